"""A classical controller acting at a slower policy rate on a faster-sampled loop.

``HeldController("lqr", every=10)`` decides once every ``every`` board samples (100 Hz on a
1 kHz rig), with a context whose ``dt`` is that period (``agents.residual.policy_rate_context``),
and holds its action in between: what a two-rate bench does with ``--controller lqr
--host-rate-hz 100`` (board mode ``zoh``), and the base of ``reverse_stroke_100hz.onnx``
with a zero correction. For the simulated benchmark, which calls a controller at every
sample::

    addedinertia bench run --suite standard-v0 --controller agents.held:lqr_100hz
"""

from __future__ import annotations

from typing import Any

import numpy as np

from addedinertia_env.experiment.task import ControllerContext

from agents.classical import make_plain_controller
from agents.residual import policy_rate_context


class HeldController:
    """``name`` deciding every ``every`` samples, its action held (see the module docstring)."""

    def __init__(self, name: str, every: int = 10, **params: Any):
        if int(every) < 1:
            raise ValueError(f"every = {every!r}; expected an integer >= 1 (board samples per decision)")
        self.inner = make_plain_controller(name, **params)
        self.every = int(every)
        self.name = f"{name}@{self.every}samples"
        self._calls, self._repeat = 0, self.every
        self._held = np.zeros(1, dtype=np.float32)

    def reset(self, context: ControllerContext) -> None:
        """Episode start: the inner controller gets the policy-rate context; called already at
        the policy rate (``context.policy_rate_hz`` equal to it) it decides at every call."""
        ctx = policy_rate_context(context, self.every)
        rate = getattr(context, "policy_rate_hz", None)
        self._repeat = 1 if rate is not None and abs(rate - ctx.policy_rate_hz) < 1e-6 * rate else self.every
        self._calls = 0
        self.inner.reset(ctx)

    def predict(self, observation, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """The action for ``observation`` (Stable-Baselines3 ``predict`` signature): the inner controller's, decided on every ``every``-th call and held in between."""
        if self._calls % self._repeat == 0:
            action, _ = self.inner.predict(observation, deterministic=True)
            self._held = np.asarray(action, dtype=np.float32).reshape(1)
        self._calls += 1
        return self._held.copy(), state


def lqr_100hz() -> HeldController:
    """lqr (tuned) deciding at 100 Hz on a 1 kHz rig."""
    return HeldController("lqr", every=10)
