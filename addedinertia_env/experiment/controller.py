"""The ``Controller`` protocol: what the experiment runner asks of a controller.

:func:`~addedinertia_env.experiment.runner.drive` (the simulator, the environment's
baselines, the benchmark and the bench all run it) and the two-rate host
(:mod:`.two_rate`) call exactly two methods:

* ``reset(context)`` once the free stroke is recorded, with a
  :class:`~addedinertia_env.experiment.task.ControllerContext` (known rig constants, the mirrored
  reference, the inertia prior, the control period);
* ``predict(observation, state=None, episode_start=None, deterministic=True) -> (action, state)``
  at every control period: the task's flat float32 observation in, a float32 array of one
  action in [-1, 1] (a fraction of ``i_max``) out (Stable-Baselines3's ``predict`` signature).

Beside them a controller may declare (read with ``getattr``, all optional; an exported
policy's card, ``agents/onnx_policy.py``, and an outside submission's card,
``bench/submission.py``, set them): :data:`DECLARATIONS`.

The classical controllers (``agents/classical.py``), exported policies (``onnx:PATH``) and
outside ``module:factory`` controllers all satisfy :class:`Controller`
(``tests/test_controller_protocol.py``, over the registry).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from addedinertia_env.experiment.task import ControllerContext

# What a controller may declare beside the two methods: attribute -> meaning (unit).
DECLARATIONS: dict[str, str] = {
    "name": "the controller's name in messages and tables",
    "BENCH_CYCLES": "episodes per benchmark scenario, the last scored (a controller that learns across cycles, ILC)",
    "policy_rate_hz": "the rate the policy was trained to act at, Hz (exported policies; None: any rate)",
    "sample_rate_hz": "the rig's sample rate in training, Hz (exported policies)",
    "board_mode": "the two-rate board's mode between host ticks, 'zoh' or 'pd' (exported policies)",
    "board_pd": "a method obs -> (kp A/rad, kd A s/rad, correction A): the board-side PD of mode 'pd'",
    "train_env_steps": "environment samples used in training (learned controllers; the leaderboard's cost)",
    "train_cpu_minutes": "CPU minutes of training (learned controllers)",
}


@runtime_checkable
class Controller(Protocol):
    """A controller the experiment runner can drive (module doc)."""

    def reset(self, context: ControllerContext) -> None:
        """Start an episode with ``context`` (called once the free stroke is recorded)."""
        ...

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """The action (float32 array of one, a fraction of ``i_max`` in [-1, 1]) for the flat
        ``observation``, and the recurrent ``state`` (passed through by memoryless controllers)."""
        ...
