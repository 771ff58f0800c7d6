"""The base class of the classical controllers and the stroke feed-forward they share.

What a controller is given, :class:`ControllerContext`, lives beside the task
(``addedinertia_env/experiment/task.py``) and is re-exported here."""

from __future__ import annotations

from typing import Any

import numpy as np

from addedinertia_env.experiment.feedforward import stroke_feedforward_current, stroke_impulse
from addedinertia_env.experiment.task import ControllerContext

__all__ = ["Controller", "ControllerContext", "stroke_feedforward_current", "stroke_impulse"]


class Controller:
    """Base class: subclasses implement :meth:`current` in amperes, in physical units."""

    name = "controller"

    def reset(self, context: ControllerContext) -> None:
        """Start an episode (or a stroke) with ``context``: the rig's known constants, reference, sample period."""
        self.ctx = context

    def current(self, obs: dict[str, float]) -> float:  # pragma: no cover - abstract
        """The motor current command, A, for the decoded observation ``obs`` (field name -> value, SI units)."""
        raise NotImplementedError

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """The action for ``observation`` (Stable-Baselines3 ``predict`` signature): :meth:`current` as a fraction of ``i_max``,
        clipped to [-1, 1], as a float32 array of one; ``state`` is passed through.
        """
        obs = self.ctx.layout.decode(np.asarray(observation, dtype=float).reshape(-1))
        i = float(np.clip(self.current(obs) / self.ctx.i_max, -1.0, 1.0))
        return np.array([i], dtype=np.float32), state
