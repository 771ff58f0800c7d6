"""The reverse-stroke task: observations, actions and reward, apart from any rig.

The task talks to an :class:`~addedinertia_env.experiment.protocol.Experiment` only, so
the same task drives the MuJoCo rig, the batched rig or the real bench. Observations
are built from sensor readings and the sensor-derived reference, never from the true
state. Every entry is named in :data:`OBSERVATION_FIELDS`; controllers look entries up
by name through :class:`ObservationLayout`, never by magic index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .experiment.protocol import Experiment
from .rig.motor import MotorCommand

# name: physical unit, normalising scale (physical value / scale is the observation).
# Scales are fixed constants so that one policy sees one meaning across episodes.
LOOKAHEAD_S = (0.01, 0.05, 0.1)
OBSERVATION_FIELDS: dict[str, tuple[str, float]] = {
    "tracking_error": ("rad", 0.005),  # phi_ref - phi
    "rate_error": ("rad/s", 0.05),  # rate_ref - estimated rate
    "phi_ref": ("rad", 0.2),
    "rate_ref": ("rad/s", 0.3),
    "accel_ref": ("rad/s^2", 0.5),
    "ahead_10ms": ("rad", 0.005),  # phi_ref(t + 10 ms) - phi_ref(t)
    "ahead_50ms": ("rad", 0.02),
    "ahead_100ms": ("rad", 0.04),
    "phi": ("rad", 0.2),
    "hull_rate": ("rad/s", 0.3),  # estimated from the hull encoder
    "flywheel_rate": ("rad/s", 50.0),  # estimated from the motor encoder
    "current": ("A", 15.0),
    "is_hold": ("-", 1.0),
    "is_reverse": ("-", 1.0),
    "phase_progress": ("-", 1.0),  # 0 at the phase start, 1 at its end
    "electric_energy": ("J", 20.0),  # integral of |u i| so far
}
OBS_LIMIT = 10.0  # observations are clipped to +-OBS_LIMIT after normalising
_SCALES = np.array([scale for _, scale in OBSERVATION_FIELDS.values()])


@dataclass(frozen=True)
class ObservationLayout:
    """Named access to the flat observation vector."""

    names: tuple[str, ...] = tuple(OBSERVATION_FIELDS)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no observation field {name!r}; fields are {self.names}") from None

    def scale(self, name: str) -> float:
        return OBSERVATION_FIELDS[name][1]

    def get(self, obs: np.ndarray, name: str) -> float:
        """Physical value of field ``name`` in observation ``obs``."""
        return float(obs[..., self.index(name)] * self.scale(name))

    def decode(self, obs: np.ndarray) -> dict[str, float]:
        return {n: float(obs[k]) * self.scale(n) for k, n in enumerate(self.names)}

    @property
    def size(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class RewardWeights:
    """Reward = -(tracking + energy + limits) per step; each term is in ``info``."""

    tracking: float = 1.0  # per (tracking error / 5 mrad)^2 during the reverse stroke
    energy: float = 0.05  # per joule of |u i| drawn
    limits: float = 1.0  # per step at the current limit


class ReverseStrokeTask:
    """Observation, action mapping and reward of the reverse-stroke task."""

    layout = ObservationLayout()

    def __init__(self, i_max: float, weights: RewardWeights | None = None):
        self.i_max = float(i_max)
        self.weights = weights or RewardWeights()

    # Actions ------------------------------------------------------------------------
    def command(self, action: np.ndarray | float) -> MotorCommand:
        """Normalised current command in [-1, 1] -> motor current command, A."""
        a = float(np.clip(np.asarray(action, dtype=float).reshape(-1)[0], -1.0, 1.0))
        return MotorCommand("current", a * self.i_max)

    # Observations -------------------------------------------------------------------
    def observe(self, exp: Experiment) -> np.ndarray:
        r, ref = exp.last, exp.reference
        t = r.t
        hull_rate, fly_rate = exp.hull_rate.value, exp.flywheel_rate.value
        phi_ref, rate_ref, acc_ref = float(ref.phi(t)), float(ref.rate(t)), float(ref.accel(t))
        if exp.phase == "hold":
            # The hull is braked: the reference is the stroke's start, and nothing moves yet.
            rate_ref = acc_ref = 0.0
            progress = 1.0 - max(0.0, ref.t_begin - t) / max(exp.plan.hold_s, 1e-9)
        else:
            progress = (t - ref.t_begin) / ref.law.duration
        values = {
            "tracking_error": phi_ref - r.phi,
            "rate_error": rate_ref - hull_rate,
            "phi_ref": phi_ref - float(exp.known["phi_neutral"]),
            "rate_ref": rate_ref,
            "accel_ref": acc_ref,
            "ahead_10ms": float(ref.phi(t + LOOKAHEAD_S[0])) - phi_ref,
            "ahead_50ms": float(ref.phi(t + LOOKAHEAD_S[1])) - phi_ref,
            "ahead_100ms": float(ref.phi(t + LOOKAHEAD_S[2])) - phi_ref,
            "phi": r.phi - float(exp.known["phi_neutral"]),
            "hull_rate": hull_rate,
            "flywheel_rate": fly_rate,
            "current": r.i,
            "is_hold": 1.0 if exp.phase == "hold" else 0.0,
            "is_reverse": 1.0 if exp.phase == "reverse" else 0.0,
            "phase_progress": float(np.clip(progress, 0.0, 1.0)),
            "electric_energy": exp.electric_energy,
        }
        obs = np.fromiter((values[n] for n in self.layout.names), float, self.layout.size) / _SCALES
        return np.clip(obs, -OBS_LIMIT, OBS_LIMIT).astype(np.float32)

    # Reward -------------------------------------------------------------------------
    def reward_terms(self, exp: Experiment, energy_before: float, cmd: MotorCommand) -> dict[str, float]:
        """Named reward terms for the step just taken; the reward is their sum."""
        w = self.weights
        r, ref = exp.last, exp.reference
        in_reverse = exp.phase == "reverse" or (exp.phase == "idle" and r.t <= ref.t_end + exp.rig.dt)
        err = (float(ref.phi(r.t)) - r.phi) / OBSERVATION_FIELDS["tracking_error"][1] if in_reverse else 0.0
        saturated = cmd.mode == "current" and abs(cmd.value) >= self.i_max * 0.999
        return {
            "tracking": -w.tracking * err**2,
            "energy": -w.energy * (exp.electric_energy - energy_before),
            "limits": -w.limits * float(saturated),
        }

