"""Gymnasium environments (registered by ``import addedinertia_env``)."""

from addedinertia_env.envs.config import EnvConfig
from addedinertia_env.envs.reverse_stroke import ReverseStrokeEnv

__all__ = ["EnvConfig", "ReverseStrokeEnv"]
