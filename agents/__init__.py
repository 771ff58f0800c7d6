"""Controllers for the reverse stroke: classical ones here, learned ones loaded by name.

Every controller has ``predict(observation, state=None, episode_start=None,
deterministic=True) -> (action, state)`` like a stable-baselines3 policy, so one
evaluation path serves PID, LQR and a trained network. Classical controllers also take
``reset(context)`` at the start of each reverse stroke (see :mod:`agents.base`).
"""

from agents.registry import CLASSICAL, make_controller

__all__ = ["CLASSICAL", "make_controller"]
