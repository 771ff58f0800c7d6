"""PID with anti-windup under the supply's voltage limit (issue 28).

On a fixed supply the drive cannot push more current than the voltage left after the
back-EMF allows: over one sample the current can reach at most
``(u_max - k_t Omega) / R`` and at least ``(-u_max - k_t Omega) / R`` (the winding's
resistance ``R``, the flywheel's rate ``Omega``; sim/motor.py). :class:`~agents.pid.PID`
stops integrating only at the current limit ``i_max``; this entry also clamps its command
to what the supply can drive now (with ``headroom``) and stops integrating whenever it
clamps (conditional integration), so the integral never winds up while the back-EMF eats
the voltage late in a fast pre-spun stroke. Known constants only (``u_max``, ``R``, ``k_t``).
Its loop gains are :class:`~agents.pid.PID`'s tuned ones (``tuned_as = "pid"``), so where
the supply's reach stays above the current limit it is that PID, sample for sample.
"""

from __future__ import annotations

from typing import Any

from agents.pid import PID


class VoltageAntiWindupPID(PID):
    """:class:`~agents.pid.PID` that clamps to the supply's reach and integrates only inside it (module doc)."""

    name = "pid-antiwindup"
    tuned_as = "pid"  # the same loop: PID's tuned gains (configs/controllers/tuned.yaml)
    DEFAULTS: dict[str, Any] = {**PID.DEFAULTS, "headroom": 0.95}
    KNOBS = dict(PID.KNOBS)

    def feedback(self, obs: dict[str, float], e: float, e_rate: float) -> float:
        """PID current, A, clamped (with the feed-forward-free command) to the supply's reach; no
        integration while clamped."""
        rig, ctx = self.ctx.rig, self.ctx
        w = self.omega_c
        integral = self.integral + e * ctx.dt
        kp, kd, ki = w * w, 2.0 * self.zeta * w, self.integral_ratio * w**3
        i = -self.J * (kp * e + kd * e_rate + ki * integral) / ctx.k_t
        hi, lo = ctx.i_max, -ctx.i_max
        if rig.u_max is not None and rig.R:
            emf = ctx.k_t * obs["flywheel_rate"]
            u = float(self.headroom) * rig.u_max
            hi, lo = min(hi, (u - emf) / rig.R), max(lo, (-u - emf) / rig.R)
        clamped = min(max(i, lo), hi)
        if clamped == i:  # integrate only while the command is within reach
            self.integral = integral
        return clamped
