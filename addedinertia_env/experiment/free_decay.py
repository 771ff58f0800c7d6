"""The free-decay experiment (textbook method, physics.md section 5; source 004).

Phases, as recorded in the run record (kind ``free-decay``):

1. ``idle``: the rod is twisted to ``phi_n - alpha`` and the hull held on the brake, motor
   passive (open circuit);
2. ``free``: brake released, motor passive, the flywheel spins freely on its bearing; the
   hull swings and decays. Recording stops once the hull has made ``periods`` full swings
   past the neutral angle (plus a quarter period, so that the last extremum is whole), or
   after ``max_s`` seconds.

Only the rig protocol is used (``reset``, ``set_brake``, ``step``, ``dt``, ``known``,
``truth``), so the same code runs on the MuJoCo rig and on the real bench.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any


from addedinertia_env.records.record import RunRecord
from addedinertia_env.rig.interface import Rig
from addedinertia_env.experiment.protocol import ExperimentError
from addedinertia_env.experiment.sample_log import PASSIVE, SampleLog



@dataclass(frozen=True)
class FreeDecayPlan:
    """How one free-decay experiment is run."""

    alpha: float = 0.1  # rad, twist of the rod before release
    settle_s: float = 0.2  # s, braked idle before release (motor passive)
    periods: int = 7  # full swings to record (the textbook uses several; 6 to 8 here)
    max_s: float = 90.0  # s, stop recording after this long in any case
    hysteresis_counts: int = 20  # hull-encoder counts around neutral that a crossing must clear

    def __post_init__(self) -> None:
        checks = {"alpha": self.alpha != 0 and abs(self.alpha) < 1.0, "settle_s": self.settle_s >= 0,
                  "periods": self.periods >= 2, "max_s": self.max_s > 0, "hysteresis_counts": self.hysteresis_counts >= 0}
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ValueError(f"FreeDecayPlan.{name} = {value!r} is out of range "
                                 "(0 < |alpha| < 1 rad, periods >= 2, times >= 0 s)")

    @classmethod
    def from_any(cls, plan: Any) -> "FreeDecayPlan":
        """A plan from ``None``, a :class:`FreeDecayPlan`, or any plan with ``alpha`` (e.g. a preset's
        :class:`~addedinertia_env.experiment.protocol.ExperimentPlan`: its twist is reused)."""
        if plan is None:
            return cls()
        if isinstance(plan, cls):
            return plan
        return cls(alpha=float(getattr(plan, "alpha", cls.alpha)))


def run_free_decay(rig: Rig, plan: Any = None, run_id: str = "run") -> RunRecord:
    """Twist to ``phi_n - alpha``, release with the motor passive, record the decay.

    ``plan`` is a :class:`FreeDecayPlan` or anything with an ``alpha`` (rad); ``None``
    takes the defaults. Returns a run record of kind ``free-decay``.
    """
    p = FreeDecayPlan.from_any(plan)
    known = rig.known
    phi_n = known.phi_neutral
    counts = known.phi_counts
    band = p.hysteresis_counts * (2.0 * math.pi / counts) if counts > 0 else 1e-5
    log = SampleLog()
    log.add(rig.reset(phi0=phi_n - p.alpha, brake=True), PASSIVE, "idle")
    for _ in range(int(round(p.settle_s / rig.dt))):
        log.add(rig.step(PASSIVE), PASSIVE, "idle")
    rig.set_brake(False)
    t_release = log.last.t
    side = -1.0 if p.alpha > 0 else 1.0  # side of neutral the hull starts on
    crossings: list[float] = []
    t_stop = math.inf
    for _ in range(int(round(p.max_s / rig.dt))):
        r = log.add(rig.step(PASSIVE), PASSIVE, "free")
        if -side * (r.phi - phi_n) > band:  # cleared the band on the other side: a crossing
            side = -side
            crossings.append(r.t)
            if len(crossings) == 2 * p.periods + 1:
                # A quarter period after this crossing the hull is at its last extremum;
                # record a little beyond it so that a local fit around it is whole.
                half = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
                t_stop = r.t + 0.75 * half
        if r.t >= t_stop:
            break
    if len(crossings) < 4:
        raise ExperimentError(f"free decay: the hull crossed neutral only {len(crossings)} time(s) in "
                              f"{p.max_s} s; raise alpha ({p.alpha} rad) or max_s")
    experiment = {"kind": "free-decay", **asdict(p), "t_release": t_release, "flywheel": "free",
                  "neutral_crossings": len(crossings)}
    return log.record(rig, experiment, run_id)
