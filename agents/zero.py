"""The ``zero`` reference: the motor commanded to 0 A throughout (no control at all).

Benchmarks run it beside every entry (``bench run --controller zero``, simulated suites
only) so that a leaderboard shows what doing nothing scores: a controller that cannot beat
it clearly does not measure anything the rig's free swing would not.
"""

from __future__ import annotations

import numpy as np


class ZeroCurrent:
    """``predict(obs) -> 0`` (normalised current), whatever the observation."""

    name = "zero"

    def reset(self, context) -> None:
        """Keep the episode's context (nothing else to prepare)."""
        self.ctx = context

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """Always 0 A (action 0) (Stable-Baselines3 ``predict`` signature)."""
        return np.zeros(1, dtype=np.float32), state
