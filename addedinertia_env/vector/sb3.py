"""The batched reverse-stroke task as a stable-baselines3 ``VecEnv``.

:class:`BatchedVecEnv` wraps :class:`~addedinertia_env.vector.env.ReverseStrokeVectorEnv`
in same-step autoreset mode, which is SB3's convention: when an episode ends, ``step``
returns the next episode's first observation, ``dones[k]`` is True and ``infos[k]``
carries ``terminal_observation``, ``TimeLimit.truncated`` (False: episodes end by
themselves) and the episode's benchmark numbers (``rel_error``, ``lambda66_est``,
``lambda66_true``, ``energy_J``, ``tracking_rms_rad``, ``saturated_frac``, ``failed``)
and reward terms (``episode_reward_terms``: tracking, energy, limits, accuracy summed over the
episode). Wrap it in ``VecMonitor`` for SB3's episode statistics.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from addedinertia_env.vector.env import METRIC_KEYS, ReverseStrokeVectorEnv


class BatchedVecEnv(VecEnv):
    """``num_envs`` batched reverse-stroke environments behind SB3's ``VecEnv`` API."""

    def __init__(self, num_envs: int, seed: int | None = None, **env_kwargs: Any):
        self.venv = ReverseStrokeVectorEnv(num_envs, autoreset_mode="same_step", **env_kwargs)
        super().__init__(num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._seed = seed
        self._actions: np.ndarray | None = None
        self._episode_terms = np.zeros((num_envs, 4))
        self.render_mode = None

    # --- VecEnv API -----------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        """Reset every environment (with the seed and options set for the next reset, if any); returns the observations."""
        seed = self._seeds[0] if self._seeds[0] is not None else self._seed
        obs, _ = self.venv.reset(seed=seed, options=self._options[0] or None)
        self._seed = None  # later resets go on with the same streams
        self._episode_terms[:] = 0.0
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Keep ``actions`` (one row per environment) for :meth:`step_wait`."""
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self):
        """Step every environment; returns ``(obs, rewards, dones, infos)`` in SB3's form.

        An ended episode's info carries ``terminal_observation``, ``TimeLimit.truncated``, its summed
        reward terms and, for scored episodes, its metrics (rel_error, energy J, ...).
        """
        obs, rewards, terminated, truncated, info = self.venv.step(self._actions)
        dones = terminated | truncated
        terms = info["reward_terms"]
        names = list(terms)
        self._episode_terms += np.stack([terms[k] for k in names], axis=1)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            final = info["final_info"]
            for k in np.nonzero(dones)[0]:
                d = infos[k]
                d["terminal_observation"] = info["final_obs"][k]
                d["TimeLimit.truncated"] = bool(truncated[k] and not terminated[k])
                if "rel_error" in final:  # scored episodes (score_episodes=True)
                    for key in METRIC_KEYS:
                        d[key] = float(final[key][k])
                    d["failed"] = bool(final["failed"][k])
                    d["scenario_seed"] = int(final["scenario_seed"][k])
                d["episode_reward_terms"] = dict(zip(names, (float(x) for x in self._episode_terms[k])))
                self._episode_terms[k] = 0.0
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        """Close the batched environment."""
        self.venv.close()


    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        """The batched environment's attribute ``attr_name``, once per requested index (all share it)."""
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        """Set ``attr_name`` on the batched environment (shared by every index)."""
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        """Call ``method_name`` once on the batched environment; its result repeated per requested index."""
        return [getattr(self.venv, method_name)(*method_args, **method_kwargs)] * len(self._get_indices(indices))

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        """False for every index: the slots are not Gymnasium environments and carry no wrapper."""
        return [False] * len(self._get_indices(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        """No images (None per environment): the batched engine does not render."""
        return [None] * self.num_envs
