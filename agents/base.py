"""What a controller is given, and the base class of the classical controllers."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from addedinertia_env.experiment.reference import MirroredReference
from addedinertia_env.rig.known import KnownRig
from addedinertia_env.task import ObservationLayout


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


class Controller:
    """Base class: subclasses implement :meth:`current` in amperes, in physical units."""

    name = "controller"

    def reset(self, context: ControllerContext) -> None:
        self.ctx = context

    def current(self, obs: dict[str, float]) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        obs = self.ctx.layout.decode(np.asarray(observation, dtype=float).reshape(-1))
        i = float(np.clip(self.current(obs) / self.ctx.i_max, -1.0, 1.0))
        return np.array([i], dtype=np.float32), state


def stroke_feedforward_current(ctx: ControllerContext, phi_ref_rel: float, accel_ref: float, J: float) -> float:
    """Current that makes the hull retrace the mirrored stroke, from the recorded law, A.

    On the free stroke ``J f'' + c (f - phi_n) = Q_w(f')`` (the damping torque). On the
    mirror the rate changes sign, so the motor must supply ``-2 Q_w``; its reaction on
    the hull is ``-k_t i``, hence ``i = -2 (J f'' + c (f - phi_n)) / k_t``.
    """
    c = ctx.rig.c_torsion
    return -2.0 * (J * accel_ref + c * phi_ref_rel) / ctx.k_t


def stroke_impulse(ctx: ControllerContext, J: float, n: int = 400) -> float:
    """Angular impulse (N m s) the feedforward puts on the flywheel over the reverse stroke."""
    law = ctx.reference.law
    s = np.linspace(law.t_start, law.t_stop, n)
    phi_n = ctx.rig.phi_neutral
    torque = -2.0 * (J * law.accel(s) + ctx.rig.c_torsion * (law.phi(s) - phi_n))
    return float(np.trapezoid(torque, s))
