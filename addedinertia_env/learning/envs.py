"""Training and evaluation environments: one factory, vectorised, optionally residual.

Residual learning (``residual.enabled``): the policy's action ``r`` in [-1, 1] is added,
times ``scale``, to the action of a classical controller (default ``feedforward-pd``)
that runs at every sample of the rig (1 kHz) from the same observation::

    action(sample) = clip(base.predict(obs(sample)) + scale * r, -1, 1)

``r`` is held for ``action_repeat`` samples, exactly as
:class:`agents.onnx_policy.OnnxPolicy` holds it on the benchmark, so training and
deployment see one controller. The base controller gets ``reset(context)`` with the
environment's :class:`~agents.base.ControllerContext` (sensor data only) every episode.

``base_rate`` says where the base runs: ``"sample"`` (default) at every rig sample, as
above, so the whole controller acts at the sample rate (a single-rate 1 kHz host);
``"policy"`` once per policy action, with a context whose ``dt`` is the policy period
(``action_repeat`` samples), and the sum ``clip(base + scale * r, -1, 1)`` is held for
``action_repeat`` samples. Then the whole controller acts at the policy rate
(``sample rate / action_repeat``, e.g. 100 Hz) with the board holding its current in
between: what a two-rate bench runs (``deploy --host-rate-hz 100``, board mode ``zoh``).

The base controller's parameters are pinned when the wrapper is built (``base_params``,
default: its tuned values at that moment, ``configs/controllers/tuned.yaml``) and go
into the training card and the ONNX metadata: a later re-tune of the classical
controller must not change the base under a trained correction.
"""

from __future__ import annotations

import functools
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agents import make_controller
from agents.residual import BASE_RATES, policy_rate_context, residual_action

from addedinertia_env.experiment.controller import Controller
from addedinertia_env.learning.toy import TOY_ENV_ID, register_toy


class ResidualWrapper(gym.Wrapper):
    """Policy action = correction on top of a classical controller; see the module docstring.

    ``env`` must step one rig sample per call (its own ``action_repeat`` = 1) and offer
    ``controller_context()`` on ``env.unwrapped`` after ``reset``.
    """

    def __init__(self, env: gym.Env, base: str = "feedforward-pd", scale: float = 0.2, action_repeat: int = 10,
                 base_params: dict[str, Any] | None = None, base_rate: str = "sample"):
        super().__init__(env)
        if action_repeat < 1:
            raise ValueError(f"action_repeat = {action_repeat!r}; expected an integer >= 1 (samples per action)")
        if base_rate not in BASE_RATES:
            raise ValueError(f"residual base_rate = {base_rate!r}; expected one of {BASE_RATES}")
        self.base_name, self.scale, self.action_repeat = base, float(scale), int(action_repeat)
        self.base_rate = base_rate
        self.base_params = dict(base_params) if base_params is not None else pinned_base_params(base)
        self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self._obs: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Reset the environment and a fresh base controller with the episode's controller context (at the policy's period for ``base_rate='policy'``); returns ``(obs, info)``."""
        obs, info = self.env.reset(seed=seed, options=options)
        self.base = make_base(self.base_name, self.base_params)
        context = self.env.unwrapped.controller_context()
        if self.base_rate == "policy":
            context = policy_rate_context(context, self.action_repeat)
        self.base.reset(context)
        self._obs = obs
        return obs, info

    def step(self, action):
        """Apply ``action`` as a correction to the base controller's for ``action_repeat`` samples.

        The base decides every sample (``base_rate='sample'``) or once, the sum then held
        (``'policy'``). Returns ``(obs, reward, terminated, truncated, info)`` with the rewards
        summed over the samples; stops early when the episode ends.
        """
        total = 0.0
        held = None
        for _ in range(self.action_repeat):
            if held is None or self.base_rate == "sample":
                base_action, _ = self.base.predict(self._obs, deterministic=True)
                held = residual_action(base_action, action, self.scale)
            obs, reward, terminated, truncated, info = self.env.step(held)
            total += float(reward)
            self._obs = obs
            if terminated or truncated:
                break
        return obs, total, terminated, truncated, info


def pinned_base_params(base: str) -> dict[str, Any]:
    """The parameters ``base`` would run with now (tuned values included), to pin them."""
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in getattr(make_controller(base), "params", {}).items()}


def make_base(base: str, params: dict[str, Any] | None) -> Controller:
    """Controller ``base`` with exactly ``params`` (no tuned file read); ``None``: as registered."""
    if not params:
        return make_controller(base)
    try:
        return make_controller(base, tuned=False, **params)
    except TypeError as e:
        raise ValueError(f"residual base {base!r} cannot be built with pinned parameters {params} ({e})") from None


def make_env(env_id: str, env_kwargs: dict[str, Any] | None = None, residual: dict[str, Any] | None = None) -> gym.Env:
    """One environment; with ``residual`` enabled, the env steps single samples under the wrapper."""
    import addedinertia_env  # noqa: F401, PLC0415 - registers the Gymnasium ids

    if env_id == TOY_ENV_ID:
        register_toy()
    kwargs = dict(env_kwargs or {})
    if residual and residual.get("enabled"):
        repeat = int(kwargs.pop("action_repeat", 1))
        env = gym.make(env_id, action_repeat=1, **kwargs)
        return ResidualWrapper(env, base=residual["base"], scale=residual["scale"], action_repeat=repeat,
                               base_params=residual.get("base_params"),
                               base_rate=residual.get("base_rate", "sample"))
    return gym.make(env_id, **kwargs)


BATCHED_ENV_ID = "AddedInertia/ReverseStroke-v0"


def uses_batched(env_id: str, residual: dict[str, Any] | None, vec_env: str,
                 env_kwargs: dict[str, Any] | None = None) -> bool:
    """Whether ``vec_env="batched"`` applies: the reverse stroke without a residual base (the base
    controllers run per environment in Python, so residual training uses single envs); a suite's
    scenarios (``env_kwargs["suite"]``, control loop included) run batched too."""
    return vec_env == "batched" and env_id == BATCHED_ENV_ID and not (residual and residual.get("enabled"))


def make_vec(env_id: str, env_kwargs: dict[str, Any], residual: dict[str, Any] | None, n_envs: int, seed: int,
             vec_env: str = "dummy"):
    """``n_envs`` monitored environments (env ``k`` seeded with ``seed + k`` at its first reset):
    the batched engine (:class:`~addedinertia_env.vector.sb3.BatchedVecEnv` in ``VecMonitor``)
    where :func:`uses_batched`, else ``make_vec_env`` copies (``"batched"`` falls back to dummy)."""
    from stable_baselines3.common.env_util import make_vec_env  # noqa: PLC0415
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor  # noqa: PLC0415

    if uses_batched(env_id, residual, vec_env, env_kwargs):
        from addedinertia_env.vector.sb3 import BatchedVecEnv  # noqa: PLC0415

        return VecMonitor(BatchedVecEnv(n_envs, seed=seed, **dict(env_kwargs or {})))

    factory = functools.partial(make_env, env_id, env_kwargs, residual)
    cls = SubprocVecEnv if (vec_env == "subproc" and n_envs > 1) else DummyVecEnv
    return make_vec_env(factory, n_envs=n_envs, seed=seed, vec_env_cls=cls)


def effective_action_repeat(env_kwargs: dict[str, Any]) -> int:
    """Rig samples per policy action (what the exported policy must hold on the benchmark)."""
    return int(env_kwargs.get("action_repeat", 1))
