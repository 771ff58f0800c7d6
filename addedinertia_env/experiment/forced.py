"""The forced-oscillation experiment (Chinese patent's method on our rig; source 003, physics.md s5).

The patent shakes the model harmonically on a motion platform and measures the force.
Here the motor is the shaker: a sinusoidal current ``i = I cos(Omega s)`` (current mode)
puts the reaction ``-k_t i`` on the hull, and ``k_t i`` is the measured force. Phases, as
recorded (kind ``forced-oscillation``):

1. ``idle``: rod twisted to ``phi_n - alpha``, hull braked, motor passive for
   ``calibrate_s``: the current sensor reads its own offset here (true current 0);
2. ``free``: brake released, motor passive, one half swing to the first stop, where the
   brake is set; its duration gives a natural-frequency guess ``omega_guess = pi / t_half``;
3. ``idle`` (driven; run-record.md has no ``forced`` phase): brake released, the motor
   drives at ``ratio * omega_guess`` for each ratio in turn, ``periods`` full drive
   periods each. Each sinusoid starts at a crest, with the amplitude that would keep the
   hull's swing at ``|phi_stop - phi_n|`` if the guess were right (clipped to
   ``current_fraction * i_max``), so the hull starts each segment near its steady motion.
   With ``frequencies_hz`` the drive frequencies are those (chosen by the lab, Hz) instead
   of ratios of the guess; with ``settle_s`` each segment first drives that long before its
   ``periods`` measured periods (at least ``measure_s`` long) (the water's memory settles;
   ``t_settled`` in the segment's entry marks where the measured part starts);
4. ``idle``: motor passive for ``tail_s``.

The frequencies and the time span of every driven segment are listed in the record's
``experiment.segments`` (the estimator needs them). Only the rig protocol is used.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from addedinertia_env.records.record import RunRecord
from addedinertia_env.rig.interface import Rig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.experiment.filters import RateEstimator
from addedinertia_env.experiment.sample_log import PASSIVE, SampleLog
from addedinertia_env.experiment.protocol import ExperimentError


@dataclass(frozen=True)
class ForcedPlan:
    """How one forced-oscillation experiment is run."""

    alpha: float = 0.06  # rad, twist for the initial half swing (also the target drive amplitude scale)
    calibrate_s: float = 0.5  # s, braked, passive: current-offset calibration
    ratios: tuple[float, ...] = (0.75, 0.85, 1.2, 1.35)  # drive frequency / natural-frequency guess
    periods: int = 2  # full drive periods per frequency
    current_fraction: float = 0.6  # largest drive amplitude as a share of i_max
    tail_s: float = 0.2  # s, passive idle at the end
    max_free_s: float = 30.0  # s, give up if the initial half swing never stops
    #: Hz: drive frequencies chosen by the lab (empty: ``ratios`` x the half swing's guess)
    frequencies_hz: tuple[float, ...] = ()
    settle_s: float = 0.0  # s, driven before each segment's measured periods (not counted in ``periods``)
    measure_s: float = 0.0  # s, at least this long measured per frequency (whole periods, ``periods`` at least)

    def __post_init__(self) -> None:
        checks = {"alpha": self.alpha != 0 and abs(self.alpha) < 1.0, "calibrate_s": self.calibrate_s > 0,
                  "ratios": len(self.ratios) >= 2 and all(0.1 < r < 5 and abs(r - 1) > 0.05 for r in self.ratios),
                  "periods": self.periods >= 1, "current_fraction": 0 < self.current_fraction <= 1,
                  "tail_s": self.tail_s >= 0, "max_free_s": self.max_free_s > 0,
                  "frequencies_hz": all(isinstance(f, (int, float)) and 0.005 <= f <= 20.0 for f in self.frequencies_hz)
                  and (len(self.frequencies_hz) == 0 or len(self.frequencies_hz) >= 2),
                  "settle_s": 0 <= self.settle_s <= 600, "measure_s": 0 <= self.measure_s <= 600}
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"ForcedPlan.{name} = {getattr(self, name)!r} is out of range (alpha: 0 < |alpha| < 1 rad; "
                                 "ratios: at least two, each in (0.1, 5) and not within 5 % of resonance; "
                                 "periods >= 1; 0 < current_fraction <= 1; calibrate_s > 0; frequencies_hz: none, "
                                 "or at least two, each 0.005 to 20 Hz; 0 <= settle_s, measure_s <= 600 s)")

    @classmethod
    def from_any(cls, plan: Any) -> "ForcedPlan":
        """A plan from ``None``, a :class:`ForcedPlan`, or any plan with ``alpha`` (its twist is reused)."""
        if plan is None:
            return cls()
        if isinstance(plan, cls):
            return plan
        return cls(alpha=float(getattr(plan, "alpha", cls.alpha)))


def run_forced(rig: Rig, plan: Any = None, run_id: str = "run") -> RunRecord:
    """Calibrate, swing once freely, then drive the hull at several frequencies; see the module docstring."""
    p = ForcedPlan.from_any(plan)
    known = rig.known
    phi_n, c, k_t = known.phi_neutral, known.c_torsion, known.k_t
    i_cap = p.current_fraction * (known.i_max if known.i_max is not None else 10.0)
    log = SampleLog()
    log.add(rig.reset(phi0=phi_n - p.alpha, brake=True), PASSIVE, "idle")
    for _ in range(int(round(p.calibrate_s / rig.dt))):
        log.add(rig.step(PASSIVE), PASSIVE, "idle")
    t_half, phi_stop = _half_swing(rig, log, p, phi_n)
    omega_guess = math.pi / t_half
    J_guess = c / omega_guess**2
    amplitude = abs(phi_stop - phi_n)
    rig.set_brake(False)
    segments = []
    omegas = [2.0 * math.pi * f for f in p.frequencies_hz] or [r * omega_guess for r in p.ratios]
    for omega in omegas:
        ratio = omega / omega_guess
        if abs(ratio - 1.0) <= 0.05:
            raise ExperimentError(f"forced oscillation: {omega / (2 * math.pi):.4g} Hz is within 5 % of the hull's "
                                  f"natural frequency ({omega_guess / (2 * math.pi):.4g} Hz from the half swing); "
                                  "resonance would drive it past its stops: choose frequencies away from it")
        side = 1.0 if log.last.phi >= phi_n else -1.0
        # Undamped steady state of J phi'' + c (phi - phi_n) = -k_t i: phi - phi_n = -k_t i / (c - J omega^2).
        current = -(c - J_guess * omega**2) * side * amplitude / k_t
        current = max(-i_cap, min(i_cap, current))
        t0 = log.last.t
        n_settle = int(round(p.settle_s / rig.dt))
        periods = max(p.periods, math.ceil(p.measure_s * omega / (2.0 * math.pi) - 1e-9))
        n = n_settle + int(round(periods * 2.0 * math.pi / omega / rig.dt))
        for k in range(1, n + 1):
            s = k * rig.dt - 0.5 * rig.dt  # the current is held over the coming sample: aim at its middle
            cmd = MotorCommand("current", current * math.cos(omega * s))
            log.add(rig.step(cmd), cmd, "idle")
        segments.append({"omega": omega, "frequency_hz": omega / (2.0 * math.pi), "ratio": ratio,
                         "current_amplitude": current, "t_start": t0, "t_settled": t0 + n_settle * rig.dt,
                         "t_end": log.last.t})
    for _ in range(int(round(p.tail_s / rig.dt))):
        log.add(rig.step(PASSIVE), PASSIVE, "idle")
    experiment = {"kind": "forced-oscillation", **asdict(p), "ratios": list(p.ratios),
                  "frequencies_hz_chosen": list(p.frequencies_hz),
                  "omega_guess": omega_guess, "t_half_swing": t_half, "segments": segments,
                  "frequencies_hz": [s["frequency_hz"] for s in segments]}
    return log.record(rig, experiment, run_id)


def _half_swing(rig: Rig, log: SampleLog, p: ForcedPlan, phi_n: float) -> tuple[float, float]:
    """Release, swing passively through neutral to the first stop, brake there; (duration, stop angle)."""
    rig.set_brake(False)
    t_release = log.last.t
    rate = RateEstimator(rig.dt)
    sign = 1.0 if p.alpha > 0 else -1.0
    crossed = False
    peak = 0.0
    for _ in range(int(round(p.max_free_s / rig.dt))):
        r = log.add(rig.step(PASSIVE), PASSIVE, "free")
        w = sign * rate.update(r.phi)
        peak = max(peak, w)
        crossed = crossed or sign * (r.phi - phi_n) >= 0
        if crossed and peak > 0 and w <= 0:
            rig.set_brake(True)
            return r.t - t_release, r.phi
    raise ExperimentError(f"forced oscillation: the hull did not stop within {p.max_free_s} s of release")
