"""PID on the hull's tracking error (observer state), with flywheel pre-spin, no model feedforward.

The classic loop: ``i = -(J / k_t) (Kp e + Ki integral(e) + Kd e')`` with
``Kp = omega_c^2``, ``Kd = 2 zeta omega_c``, ``Ki = integral_ratio * omega_c^3``
(``J`` the inertia prior, ``e = phi_ref - phi``). Without the recorded-law feedforward
the loop must supply the whole ``2 x damping`` torque from the error, so it lags: the
integral term removes the slowly varying part of that lag. Knobs and ranges:
:attr:`PID.KNOBS` (tuning: addedinertia_env/bench/tuning.py, docs/CONTROLLERS.md).
"""

from __future__ import annotations

from agents.feedforward_pd import StrokeController


class PID(StrokeController):
    """PID on the observer's tracking error, with pre-spin and no model feed-forward.

    Loop at ``omega_c`` rad/s with damping ``zeta``; the integral gain is
    ``integral_ratio * omega_c^3``.
    """

    name = "pid"
    DEFAULTS = {**StrokeController.DEFAULTS, "feedforward": False, "omega_c": 15.0, "zeta": 1.0,
                "integral_ratio": 0.3}
    KNOBS = {"omega_c": (5.0, 60.0, "log"), "zeta": (0.5, 2.0, "lin"), "integral_ratio": (0.02, 1.0, "log"),
             "observer_bandwidth": (2.0, 80.0, "log")}

    def reset(self, context) -> None:
        """Start a stroke as :class:`StrokeController` does, with the error integral at 0."""
        super().reset(context)
        self.integral = 0.0  # rad s

    def feedback(self, obs: dict[str, float], e: float, e_rate: float) -> float:
        """PID current, A: ``-J (kp e + kd e_rate + ki integral(e)) / k_t``; the integral stops while the current is at its limit (anti-windup)."""
        w = self.omega_c
        self.integral += e * self.ctx.dt
        kp, kd, ki = w * w, 2.0 * self.zeta * w, self.integral_ratio * w**3
        i = -self.J * (kp * e + kd * e_rate + ki * self.integral) / self.ctx.k_t
        if abs(i) >= self.ctx.i_max:  # anti-windup: do not integrate into saturation
            self.integral -= e * self.ctx.dt
        return i
