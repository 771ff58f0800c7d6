"""The reverse-stroke task: observations, actions and reward, apart from any rig.

The task talks to an :class:`~addedinertia_env.experiment.protocol.Experiment` only, so
the same task drives the MuJoCo rig, the batched rig or the real bench. Observations
are built from sensor readings, the sensor-derived reference and the rig's *known*
constants (the run record's ``rig`` block), never from the true state. Every entry is
named in :data:`OBSERVATION_FIELDS`; controllers look entries up by name through
:class:`ObservationLayout`, never by magic index. New fields are only ever appended.

Reward (per rig sample, summed by the environment over its action repeat)::

    tracking = -w_tracking * (e / 1 mrad)^2 * dt / 1 s      e = phi_ref - phi (encoder), reverse stroke only
    energy   = -w_energy   * (electric energy drawn in the sample) / 1 J
    limits   = -w_limits   * dt / 1 s                       while the drive is at a limit
    accuracy = -w_accuracy * min(|rel_error| / 1 %, 10)     once, at the episode's end

so an episode's return does not depend on the sample rate or the action repeat.
``accuracy`` needs the true lambda66, which only a simulator knows; on a real bench it
is 0. See docs/ENVIRONMENT.md for the reasoning behind the weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from addedinertia_env.experiment.protocol import Experiment
from addedinertia_env.experiment.reference import MirroredReference
from addedinertia_env.experiment.metrics import current_at_limit, voltage_at_limit
from addedinertia_env.rig.known import KnownRig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.sensors import Reading

# name: physical unit, normalising scale (physical value / scale is the observation).
# Scales are fixed constants so that one policy sees one meaning across episodes.
LOOKAHEAD_S = (0.01, 0.05, 0.1)
OBSERVATION_FIELDS: dict[str, tuple[str, float]] = {
    "tracking_error": ("rad", 0.005),  # phi_ref - phi
    "rate_error": ("rad/s", 0.05),  # rate_ref - estimated rate
    "phi_ref": ("rad", 0.2),  # relative to the calibrated neutral
    "rate_ref": ("rad/s", 0.3),
    "accel_ref": ("rad/s^2", 0.5),
    "ahead_10ms": ("rad", 0.005),  # phi_ref(t + 10 ms) - phi_ref(t)
    "ahead_50ms": ("rad", 0.02),
    "ahead_100ms": ("rad", 0.04),
    "phi": ("rad", 0.2),  # hull encoder, relative to the calibrated neutral
    "hull_rate": ("rad/s", 0.3),  # estimated from the hull encoder
    "flywheel_rate": ("rad/s", 50.0),  # estimated from the motor encoder (relative to the hull)
    "current": ("A", 15.0),  # current sensor
    "is_hold": ("-", 1.0),
    "is_reverse": ("-", 1.0),
    "phase_progress": ("-", 1.0),  # 0 at the phase start, 1 at its end
    "electric_energy": ("J", 20.0),  # integral of |u i| so far (hold and reverse)
    # Appended for learned controllers: time, and the episode's constants that the
    # classical controllers get through their ControllerContext.
    "time_to_phase_end": ("s", 5.0),  # to the end of the hold, or of the reverse stroke
    "inertia_prior": ("kg m^2", 20.0),  # J_hull + lambda66 seen at the free stroke's stop
    "stroke_duration": ("s", 2.0),  # duration of the reverse stroke
    "c_torsion": ("N m/rad", 50.0),  # known (calibrated) rod stiffness
    "k_t": ("N m/A", 0.25),  # known torque constant
    "J_flywheel": ("kg m^2", 0.1),  # known flywheel inertia
}
OBS_LIMIT = 10.0  # observations are clipped to +-OBS_LIMIT after normalising
_SCALES = np.array([scale for _, scale in OBSERVATION_FIELDS.values()])
TRACKING_UNIT = 0.001  # rad: a tracking error of 1 mrad held for 1 s costs w_tracking
ACCURACY_UNIT = 0.01  # relative lambda66 error that costs w_accuracy
ACCURACY_CAP = 10.0  # the accuracy term saturates at 10 units (10 %), also for a failed estimate
CONTROL_MODES = ("current", "voltage")


@dataclass(frozen=True)
class ObservationLayout:
    """Named access to the flat observation vector."""

    names: tuple[str, ...] = tuple(OBSERVATION_FIELDS)

    def index(self, name: str) -> int:
        """Position of observation field ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no observation field {name!r}; fields are {self.names}") from None

    def scale(self, name: str) -> float:
        """Normalising scale of field ``name`` (physical value / scale = observation)."""
        return OBSERVATION_FIELDS[name][1]

    def get(self, obs: np.ndarray, name: str) -> float:
        """Physical value of field ``name`` in observation ``obs``."""
        return float(obs[..., self.index(name)] * self.scale(name))

    def decode(self, obs: np.ndarray) -> dict[str, float]:
        """Physical values (SI) of a flat observation, by field name."""
        return {n: float(obs[k]) * self.scale(n) for k, n in enumerate(self.names)}

    @property
    def size(self) -> int:
        """Number of observation entries."""
        return len(self.names)


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the named reward terms (module docstring); each must be finite and >= 0."""

    tracking: float = 1.0  # per second at a tracking error of 1 mrad (quadratic)
    energy: float = 0.1  # per joule of |u i| drawn
    limits: float = 1.0  # per second at the current (or voltage) limit
    accuracy: float = 1.0  # per percent of lambda66 error, once at the end (simulator only)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"reward weight {f.name} = {value!r}: expected a finite number >= 0")

    @classmethod
    def from_mapping(cls, mapping: dict) -> "RewardWeights":
        """Weights from a mapping of term name to weight; unknown names refused."""
        allowed = [f.name for f in fields(cls)]
        unknown = sorted(set(mapping) - set(allowed))
        if unknown:
            raise ValueError(f"reward weights: unknown term(s) {unknown}; expected some of {allowed}")
        return cls(**mapping)


TERM_NAMES = tuple(f.name for f in fields(RewardWeights))
# The default weights on a benchmark suite's scenarios (issue 28): the terminal accuracy term
# alone, so that an episode's return is minus its ranked score in percent (bench/score.py:
# min(|e|, 10 %), a failure at the cap); no shaping (docs/ENVIRONMENT.md measures why).
SCORE_ONLY = RewardWeights(tracking=0.0, energy=0.0, limits=0.0, accuracy=1.0)


@dataclass(frozen=True)
class ControllerContext:
    """Known before the controlled part of an episode begins (sensor data and rig constants only)."""

    rig: KnownRig  # the known rig constants (the run record's ``rig`` block, SI)
    layout: ObservationLayout  # named access to observation entries
    reference: MirroredReference  # the mirrored free-stroke law, from the encoder
    inertia_prior: float  # kg m^2, J_hull + lambda66 seen at the free stroke's stop
    dt: float  # s, control period: the policy's (host's) period, 1 / policy_rate_hz
    hold_s: float  # s, duration of the brake hold before the reverse stroke
    policy_rate_hz: float | None = None  # Hz, how often the controller acts (None: every board sample)
    board_mode: str = "zoh"  # what the board does between actions: "zoh" (hold) or "pd" (board-side PD)
    sample_dt: float | None = None  # s, the board's sample period (None: = dt)
    link_round_trip_s: float | None = None  # s, the link's round trip as the lab states it (a loopback ping; None: not stated)

    @property
    def board_dt(self) -> float:
        """s, the period at which the board's inner loop runs."""
        return self.sample_dt if self.sample_dt is not None else self.dt

    @property
    def i_max(self) -> float:
        """Drive current limit, A (the rig must state it: a controller's action is a fraction of it)."""
        if self.rig.i_max is None:
            raise ValueError("rig.i_max (drive current limit, A) is not given; a controller needs it")
        return self.rig.i_max

    @property
    def k_t(self) -> float:
        """Motor torque constant, N m/A."""
        return self.rig.k_t


class ReverseStrokeTask:
    """Observation, action mapping and reward of the reverse-stroke task.

    ``control_mode`` ``"current"``: action 1 is ``i_max`` amperes; ``"voltage"``: action 1
    is ``u_max`` volts at the terminals (then ``u_max`` is required).
    """

    layout = ObservationLayout()
    term_names = TERM_NAMES

    def __init__(self, i_max: float, weights: RewardWeights | None = None, control_mode: str = "current",
                 u_max: float | None = None):
        if control_mode not in CONTROL_MODES:
            raise ValueError(f"control_mode = {control_mode!r}: expected one of {CONTROL_MODES}")
        if control_mode == "voltage" and u_max is None:
            raise ValueError("control_mode = 'voltage' needs u_max (V), the supply voltage")
        self.i_max = float(i_max)
        self.u_max = float(u_max) if u_max is not None else math.nan
        self.control_mode = control_mode
        self.command_scale = self.i_max if control_mode == "current" else self.u_max
        self.weights = weights or RewardWeights()

    @classmethod
    def for_rig(cls, known: KnownRig, weights: RewardWeights | None = None,
                control_mode: str = "current") -> "ReverseStrokeTask":
        """The task for a rig whose known constants are ``known`` (``i_max`` must be given)."""
        if known.i_max is None:
            raise ValueError("rig.i_max (drive current limit, A) is not given; the task scales actions by it")
        return cls(i_max=known.i_max, weights=weights, control_mode=control_mode, u_max=known.u_max)

    # Actions ------------------------------------------------------------------------
    def command(self, action: np.ndarray | float) -> MotorCommand:
        """Normalised command in [-1, 1] -> motor command (A or V); clipped to [-1, 1]."""
        a = min(max(float(np.asarray(action, dtype=float).reshape(-1)[0]), -1.0), 1.0)
        return MotorCommand(self.control_mode, a * self.command_scale)

    # Observations -------------------------------------------------------------------
    def observe(self, exp: Experiment) -> np.ndarray:
        """The normalised observation (float32, clipped to +-OBS_LIMIT) of the experiment now."""
        r, ref, known = exp.last, exp.reference, exp.known
        t = r.t
        phi_n = known.phi_neutral
        hull_rate, fly_rate = exp.hull_rate.value, exp.flywheel_rate.value
        phi_ref, rate_ref, acc_ref = float(ref.phi(t)), float(ref.rate(t)), float(ref.accel(t))
        # Scalar calls: faster than one vectorised call for four points.
        ahead_1, ahead_2, ahead_3 = (float(ref.phi(t + h)) for h in LOOKAHEAD_S)
        duration = ref.law.duration
        if exp.phase == "hold":
            # The hull is braked: the reference is the stroke's start, and nothing moves yet.
            rate_ref = acc_ref = 0.0
            to_end = max(0.0, ref.t_begin - t)
            progress = 1.0 - to_end / max(exp.plan.hold_s, 1e-9)
        else:
            to_end = max(0.0, ref.t_end - t)
            progress = (t - ref.t_begin) / duration
        values = (
            phi_ref - r.phi,  # tracking_error
            rate_ref - hull_rate,  # rate_error
            phi_ref - phi_n,  # phi_ref
            rate_ref,
            acc_ref,
            ahead_1 - phi_ref,  # ahead_10ms
            ahead_2 - phi_ref,
            ahead_3 - phi_ref,
            r.phi - phi_n,  # phi
            hull_rate,
            fly_rate,
            r.i,  # current
            1.0 if exp.phase == "hold" else 0.0,
            1.0 if exp.phase == "reverse" else 0.0,
            min(max(progress, 0.0), 1.0),
            exp.electric_energy,
            to_end,  # time_to_phase_end
            exp.inertia_prior,
            duration,  # stroke_duration
            known.c_torsion,
            known.k_t,
            known.J_flywheel,
        )
        obs = np.array(values) / _SCALES
        return np.clip(obs, -OBS_LIMIT, OBS_LIMIT).astype(np.float32)

    # Reward -------------------------------------------------------------------------
    def tracking_error(self, exp: Experiment, reading: Reading) -> float | None:
        """``phi_ref - phi`` (rad) at ``reading`` if it lies in the reverse stroke, else None."""
        ref = exp.reference
        if ref.t_begin < reading.t <= ref.t_end + 0.5 * exp.rig.dt:
            return float(ref.phi(reading.t)) - reading.phi
        return None

    def at_limit(self, cmd: MotorCommand, reading: Reading) -> bool:
        """Current mode: the command at the current limit; voltage mode: at the supply
        voltage, or the measured current at or over the current limit."""
        if cmd.mode == "current":
            return bool(current_at_limit(cmd.value, self.i_max))
        if cmd.mode == "voltage":
            return bool(voltage_at_limit(cmd.value, reading.i, self.u_max, self.i_max))
        return False

    def reward_terms(self, exp: Experiment, energy_before: float, cmd: MotorCommand,
                     reading: Reading | None = None) -> dict[str, float]:
        """Named reward terms of the sample just taken (``reading``, default ``exp.last``);
        the reward is their sum. ``accuracy`` is 0 here (see :meth:`accuracy_term`)."""
        r = reading if reading is not None else exp.last
        e = self.tracking_error(exp, r)
        return self.terms(tracking_sq=0.0 if e is None else e * e, energy=exp.electric_energy - energy_before,
                          limit_samples=int(self.at_limit(cmd, r)), dt=exp.rig.dt)

    def terms(self, tracking_sq: float, energy: float, limit_samples: int, dt: float) -> dict[str, float]:
        """The terms over a run of samples (of period ``dt`` s) from its totals: the sum of
        squared tracking errors (rad^2), the electric energy drawn (J) and the number of
        samples at a limit. The one place where the reward's formula lives."""
        w = self.weights
        return {
            "tracking": -w.tracking * tracking_sq / TRACKING_UNIT**2 * dt,
            "energy": -w.energy * energy,
            "limits": -w.limits * limit_samples * dt,
            "accuracy": 0.0,
        }

    def accuracy_term(self, rel_error: float, failed: bool = False) -> float:
        """Terminal term from the episode's relative lambda66 error. A failed estimate
        costs the cap; an unknown error (nan: no true lambda66, a real bench) costs 0."""
        if failed:
            units = ACCURACY_CAP
        elif not math.isfinite(rel_error):
            return 0.0
        else:
            units = min(abs(rel_error) / ACCURACY_UNIT, ACCURACY_CAP)
        return -self.weights.accuracy * units
