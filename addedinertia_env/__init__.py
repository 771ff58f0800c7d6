"""addedinertia: the reverse-symmetric yaw rig of patent RU 2627023, simulated and real.

Importing this package registers the Gymnasium environments (``AddedInertia/ReverseStroke-v0``).
"""

from __future__ import annotations

__version__ = "0.1.0"

from gymnasium.envs.registration import register as _register

_register(
    id="AddedInertia/ReverseStroke-v0",
    entry_point="addedinertia_env.envs.reverse_stroke:ReverseStrokeEnv",
    vector_entry_point="addedinertia_env.vector.entry:make_vector_env",
    max_episode_steps=20000,
)
