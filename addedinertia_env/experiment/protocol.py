"""The reverse-symmetric experiment as a state machine over any rig (patent RU 2627023).

Phases, as recorded in the run record:

1. ``idle``: the rod is twisted to ``phi_n - alpha`` and the hull held on the brake;
2. ``free``: brake released, motor passive (open circuit: no electric work); the hull
   swings through neutral and slows to a stop; the brake is set at the predicted stop;
3. ``hold``: hull braked for ``hold_s``; the controller may spin the flywheel;
4. ``reverse``: brake released; the controller drives the hull along the time mirror of
   the free stroke's fitted law (sensor data only);
5. ``idle``: motor passive again for ``tail_s``.

The controller acts only in ``hold`` and ``reverse`` through :meth:`Experiment.step`; the
rest runs by itself. The same object drives the MuJoCo rig, the batched rig's single
view, or the real bench through ``hw_adapter``: it only uses the rig protocol
(``reset``, ``set_brake``, ``step``, ``dt``, ``known``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from addedinertia_env.foundation.config_io import ConfigError, check_keys
from addedinertia_env.records.record import RunRecord
from addedinertia_env.rig.interface import Rig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.sensors import Reading
from addedinertia_env.experiment.filters import RateEstimator
from addedinertia_env.experiment.reference import MirroredReference, StrokeLaw, fit_stroke
from addedinertia_env.experiment.sample_log import PASSIVE, SampleLog



@dataclass(frozen=True)
class ExperimentPlan:
    """How one reverse-symmetric experiment is run."""

    alpha: float = 0.1  # rad, twist of the rod before release
    #: s, brake hold at the reversal: 0.1 s, the study's recommendation (docs/RADIATION_MEMORY.md,
    #: "The protocol's part": in water that remembers, the shortest hold a brake makes leaves the
    #: smallest memory bias; memory-free accuracy unchanged)
    hold_s: float = 0.1
    settle_s: float = 0.1  # s, braked idle before release
    tail_s: float = 0.1  # s, passive idle after the reverse stroke
    lead_s: float = 0.05  # s, the fitted stroke starts this long before the neutral crossing
    stop_window_s: float = 0.05  # s, quadratic fit window that predicts the stop
    max_free_s: float = 30.0  # s, give up if the hull never stops
    #: kg m^2: when given, the controller's inertia prior is ``J_hull + lambda66_prior`` (e.g. the
    #: BEM's A66 at the swing frequency, addedinertia_env.hydro) instead of the free stroke's
    #: stop estimate ``-c (phi2 - phi_n) / f''(t2)``
    lambda66_prior: float | None = None

    def __post_init__(self) -> None:
        checks = {"alpha": self.alpha != 0 and abs(self.alpha) < 1.0, "hold_s": self.hold_s >= 0,
                  "settle_s": self.settle_s >= 0, "tail_s": self.tail_s >= 0, "lead_s": self.lead_s > 0,
                  "stop_window_s": self.stop_window_s > 0, "max_free_s": self.max_free_s > 0}
        if self.lambda66_prior is not None:
            checks["lambda66_prior"] = self.lambda66_prior > 0
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (ok and math.isfinite(value)):
                raise ValueError(f"ExperimentPlan.{name} = {value!r} is out of range "
                                 "(alpha: 0 < |alpha| < 1 rad; times: >= 0 s; lambda66_prior > 0 kg m^2)")
        for name, limit in MAX_DURATION_S.items():
            if getattr(self, name) > limit:
                raise ValueError(f"ExperimentPlan.{name} = {getattr(self, name)!r} s: expected at most {limit:g} s "
                                 "(docs/RELIABILITY.md)")


# Documented limits of one experiment's durations, s (docs/RELIABILITY.md): longer is refused up front.
MAX_DURATION_S = {"hold_s": 600.0, "settle_s": 60.0, "tail_s": 60.0, "lead_s": 10.0, "stop_window_s": 10.0,
                  "max_free_s": 600.0}


def plan_from_preset(data: dict[str, Any], **overrides: Any) -> ExperimentPlan:
    """A rig preset's (or lab file's) ``experiment`` block as an :class:`ExperimentPlan`, with
    ``overrides`` (``None`` values ignored); ``ConfigError`` naming the file and the key."""
    where = data.get("_path", "rig")
    allowed = {f.name for f in dataclasses.fields(ExperimentPlan)}
    exp = dict(check_keys(data.get("experiment") or {}, allowed, f"{where}: experiment"))
    exp.update({k: v for k, v in overrides.items() if v is not None})
    numeric = {f.name for f in dataclasses.fields(ExperimentPlan) if f.type in ("float", float)}
    for key, value in exp.items():
        if key in numeric and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ConfigError(f"{where}: experiment.{key} = {value!r}: expected a number (SI units)")
    try:
        return ExperimentPlan(**exp)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: experiment: {e}") from None


class ExperimentError(RuntimeError):
    """The experiment could not proceed (the hull never stopped, never crossed neutral)."""


class Experiment:
    """One reverse-symmetric experiment on ``rig``; see the module docstring."""

    def __init__(self, rig: Rig, plan: ExperimentPlan | None = None):
        self.rig = rig
        self.plan = plan or ExperimentPlan()
        self.known = rig.known
        self.phase = "idle"
        self.done = False
        self.log = SampleLog()
        self.law: StrokeLaw | None = None
        self.reference: MirroredReference | None = None
        self.inertia_prior = float("nan")
        self.last: Reading | None = None
        self.hull_rate = RateEstimator(rig.dt)
        self.flywheel_rate = RateEstimator(rig.dt)
        self.electric_energy = 0.0  # J, integral of measured u*i over hold and reverse
        self.controlled_steps = 0
        self.t_brake = self.t_release = float("nan")
        self.log_command = PASSIVE  # the command applied over the last sample period

    # --- phases that run by themselves -------------------------------------------------
    def start(self) -> None:
        """Twist, release and run the free stroke; ends braked, in ``hold``."""
        p, phi_n = self.plan, self.known.phi_neutral
        sign = 1.0 if p.alpha > 0 else -1.0  # direction of the free stroke
        self._log_reading(self.rig.reset(phi0=phi_n - p.alpha), None)
        for _ in range(int(round(p.settle_s / self.rig.dt))):
            self._advance(PASSIVE, "idle")
        self.rig.set_brake(False)
        self.t_release = self.last.t
        self.phase = "free"
        t_cross = None
        peak = 0.0
        window = max(5, int(round(p.stop_window_s / self.rig.dt)))
        n_max = int(round(p.max_free_s / self.rig.dt))
        for _ in range(n_max):
            r = self._advance(PASSIVE, "free")
            w = sign * self.hull_rate.value
            peak = max(peak, w)
            if t_cross is None and sign * (r.phi - phi_n) >= 0:
                t_cross = r.t
            if t_cross is not None and w < 0.3 * peak and self._stop_due(window):
                break
        else:
            raise ExperimentError(f"the hull did not stop within {p.max_free_s} s of release")
        self.rig.set_brake(True)
        self.t_brake = self.last.t
        t = np.asarray(self.log.columns["t"])
        phi = np.asarray(self.log.columns["phi"])
        self.law = fit_stroke(t, phi, t_cross - p.lead_s, self.t_brake)
        self.inertia_prior = self.law.inertia_prior(self.known.c_torsion, phi_n)
        if p.lambda66_prior is not None:  # a prior from the hull's geometry (BEM) instead
            self.inertia_prior = self.known.J_hull + float(p.lambda66_prior)
        self.reference = MirroredReference(self.law, t_begin=self.t_brake + p.hold_s)
        self.phase = "hold" if p.hold_s > 0 else "reverse"
        if self.phase == "reverse":
            self.rig.set_brake(False)

    def _stop_due(self, window: int) -> bool:
        """Predict the stop from a quadratic over the last ``window`` samples; true when due."""
        t = self.log.tail("t", window)
        phi = self.log.tail("phi", window)
        tt = t - t[-1]
        c2, c1, _ = np.polyfit(tt, phi, 2)
        if c2 == 0.0:
            return False
        t_stop = -c1 / (2.0 * c2)  # relative to the newest sample
        return t_stop <= 0.5 * self.rig.dt

    # --- the controlled part -----------------------------------------------------------
    @property
    def needs_control(self) -> bool:
        """Whether the controller acts now: during the hold and the reverse stroke, until the experiment is done."""
        return not self.done and self.phase in ("hold", "reverse")

    def step(self, cmd: MotorCommand | None) -> Reading:
        """One sample under the controller's command (hold or reverse phase). ``None``: a
        two-rate rig's board applies the segment it has (``rig.send_segment``)."""
        if not self.needs_control:
            raise ExperimentError(f"step() called in phase {self.phase!r}; call start() first, and stop when done")
        p = self.plan
        self.controlled_steps += 1
        r = self._advance(cmd, self.phase)
        if self.phase == "hold" and r.t >= self.reference.t_begin - 0.5 * self.rig.dt:
            self.rig.set_brake(False)
            self.phase = "reverse"
        elif self.phase == "reverse" and r.t >= self.reference.t_end - 0.5 * self.rig.dt:
            self.phase = "idle"
            for _ in range(int(round(p.tail_s / self.rig.dt))):
                self._advance(PASSIVE, "idle")
            self.done = True
        return r

    # --- bookkeeping -----------------------------------------------------------------
    def _advance(self, cmd: MotorCommand | None, phase: str) -> Reading:
        r = self.rig.step(cmd)
        # A two-rate rig's board decides the command itself: log what it applied.
        applied = getattr(self.rig, "applied_command", None)
        self.log_command = applied if applied is not None else (cmd if cmd is not None else PASSIVE)
        self._log_reading(r, self.log_command, phase)
        return r

    def _log_reading(self, r: Reading, cmd: MotorCommand | None, phase: str = "idle") -> None:
        if self.last is not None and phase in ("hold", "reverse"):
            self.electric_energy += abs(r.u * r.i) * (r.t - self.last.t)
        self.last = self.log.add(r, cmd, phase)
        self.hull_rate.update(r.phi)
        self.flywheel_rate.update(r.psi)

    def record(self, run_id: str = "run", extra_experiment: dict | None = None) -> RunRecord:
        """The run record so far (complete once ``done``)."""
        experiment = {"kind": "reverse-symmetric", **asdict(self.plan),
                      "t_release": self.t_release, "t_brake": self.t_brake}
        if self.law is not None:
            experiment["stroke_fit_rms_rad"] = self.law.fit_rms
        experiment.update(extra_experiment or {})
        return self.log.record(self.rig, experiment, run_id)
