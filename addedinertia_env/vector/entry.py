"""The registered vector entry point of ``AddedInertia/ReverseStroke-v0``: one process or several."""

from __future__ import annotations

from typing import Any

from gymnasium.vector import VectorEnv

from addedinertia_env.vector.env import ReverseStrokeVectorEnv
from addedinertia_env.vector.shards import ShardedVectorEnv


def make_vector_env(num_envs: int = 1, workers: int = 1, **kwargs: Any) -> VectorEnv:
    """:class:`~.env.ReverseStrokeVectorEnv` in this process (``workers`` 1, the default), or
    ``workers`` processes of it (:class:`~.shards.ShardedVectorEnv`)."""
    if workers == 1:
        return ReverseStrokeVectorEnv(num_envs, **kwargs)
    ReverseStrokeVectorEnv.spaces(num_envs, **kwargs)  # the option errors here, not in a worker
    return ShardedVectorEnv(num_envs, workers=workers, **kwargs)
