"""The safety envelope: between whatever controller runs and the link to the bench.

It never trusts the controller. Every command is clamped to the current and voltage
limits before it is sent, and every sample is checked; a check that fails *trips* the
envelope: :class:`~hw_adapter.bench_rig.BenchRig` then sends the safe state (drive
passive = zero current, brake on, DISARM) and raises :class:`SafetyTrip`.

Trips (``SafetyTrip.kind``): ``angle`` (|phi - phi_neutral| beyond the limit), ``rate``
(hull rate from successive encoder samples beyond the limit), ``flywheel_rate``,
``current`` / ``voltage`` (measured beyond the limit), ``board_fault`` (fault bits in a
SAMPLE or a FAULT message), ``brake`` (sensed brake differs from the request for longer
than the board's brake response time), ``link`` (silence beyond the watchdog time, lost
or corrupted frames beyond the budget, a broken port), ``sensor`` (an impossible
reading), ``watchdog`` (the control loop itself stalled).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from addedinertia_env.sim.motor import MotorCommand


class SafetyTrip(RuntimeError):
    """The run was stopped by the safety envelope; the bench has been sent to the safe state."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind

    @property
    def reason(self) -> str:
        """``kind: message``, as the record's status and the summary give it."""
        return f"{self.kind}: {self}"


@dataclass(frozen=True)
class SafetyLimits:
    """Limits enforced outside the controller (SI units). Defaults suit the 2 m model rig."""

    i_max: float = 15.0  # A, command clamp and measured-current limit (the lower of this and the board's)
    u_max: float = 48.0  # V, voltage command clamp and measured-voltage limit
    phi_max: float = 0.35  # rad, |phi - phi_neutral|; the plan's twist must be well inside
    rate_max: float = 1.0  # rad/s, hull yaw rate
    flywheel_rate_max: float = 400.0  # rad/s, flywheel rate relative to the hull
    measured_margin: float = 1.2  # a measured |i| or |u| above margin x limit trips
    link_error_budget: int = 20  # lost + corrupted frames allowed per run
    max_missed_in_row: int = 3  # consecutive samples that may be missing

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                if not (name in ("link_error_budget",) and value == 0):
                    raise ValueError(f"SafetyLimits.{name} = {value!r}: expected a finite number > 0")
        if self.measured_margin < 1.0:
            raise ValueError(f"SafetyLimits.measured_margin = {self.measured_margin!r}: expected >= 1")


class SafetyEnvelope:
    """Clamps commands and checks samples against :class:`SafetyLimits`; see the module docstring."""

    def __init__(self, limits: SafetyLimits, phi_neutral: float):
        self.limits = limits
        self.phi_neutral = float(phi_neutral)
        self.clamped = 0  # commands the envelope had to clamp
        self.max_abs_current_sent = 0.0  # A
        self.max_abs_voltage_sent = 0.0  # V
        self._last: tuple[float, float, float] | None = None  # t, phi, psi of the previous sample

    def clamp(self, cmd: MotorCommand) -> MotorCommand:
        """The command that may be sent: within the current or voltage limit, finite."""
        if cmd.mode == "passive":
            return MotorCommand("passive", 0.0)
        limit = self.limits.i_max if cmd.mode == "current" else self.limits.u_max
        value = min(limit, max(-limit, float(cmd.value)))
        if value != cmd.value:
            self.clamped += 1
        if cmd.mode == "current":
            self.max_abs_current_sent = max(self.max_abs_current_sent, abs(value))
        else:
            self.max_abs_voltage_sent = max(self.max_abs_voltage_sent, abs(value))
        return MotorCommand(cmd.mode, value)

    def forget_motion(self) -> None:
        """After a RESET the hull was moved on purpose: no rate across it."""
        self._last = None

    def check(self, t: float, phi: float, psi: float, i: float, u: float) -> None:
        """Raise :class:`SafetyTrip` if a sample is beyond a limit (the caller makes the bench safe)."""
        lim = self.limits
        if not all(math.isfinite(x) for x in (t, phi, psi, i, u)):
            raise SafetyTrip("sensor", f"non-finite sample t={t} phi={phi} psi={psi} i={i} u={u}")
        if abs(phi - self.phi_neutral) > lim.phi_max:
            raise SafetyTrip("angle", f"hull angle {phi - self.phi_neutral:+.4f} rad from neutral at t={t:.4f} s "
                                      f"is beyond the limit {lim.phi_max} rad")
        if abs(i) > lim.measured_margin * lim.i_max:
            raise SafetyTrip("current", f"measured current {i:+.3f} A at t={t:.4f} s is beyond "
                                        f"{lim.measured_margin} x {lim.i_max} A")
        if abs(u) > lim.measured_margin * lim.u_max:
            raise SafetyTrip("voltage", f"measured voltage {u:+.3f} V at t={t:.4f} s is beyond "
                                        f"{lim.measured_margin} x {lim.u_max} V")
        if self._last is not None:
            t0, phi0, psi0 = self._last
            dt = t - t0
            if dt <= 0:
                raise SafetyTrip("sensor", f"sample time {t:.6f} s does not advance past {t0:.6f} s")
            rate = (phi - phi0) / dt
            if abs(rate) > lim.rate_max:
                raise SafetyTrip("rate", f"hull rate {rate:+.3f} rad/s at t={t:.4f} s is beyond "
                                         f"the limit {lim.rate_max} rad/s")
            fly = (psi - psi0) / dt
            if abs(fly) > lim.flywheel_rate_max:
                raise SafetyTrip("flywheel_rate", f"flywheel rate {fly:+.1f} rad/s at t={t:.4f} s is beyond "
                                                  f"the limit {lim.flywheel_rate_max} rad/s")
        self._last = (t, phi, psi)
