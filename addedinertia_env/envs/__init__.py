"""Gymnasium environments (registered by ``import addedinertia_env``)."""

from .config import EnvConfig
from .reverse_stroke import ReverseStrokeEnv

__all__ = ["EnvConfig", "ReverseStrokeEnv"]
