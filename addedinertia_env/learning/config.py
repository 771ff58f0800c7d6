"""Algorithm configs: ``configs/algos/<algo>.yaml``, laid out like rl-baselines3-zoo.

Each file maps a Gymnasium id to one block::

    AddedInertia/ReverseStroke-v0:
      policy: MlpPolicy
      n_timesteps: 200000          # environment (agent) steps
      n_envs: 2                    # parallel environments
      vec_env: batched             # batched (the reverse stroke on the batched engine, one process;
                                   # residual runs fall back to dummy) | dummy (one process) | subproc
      normalize: {norm_obs: true, norm_reward: false, clip_obs: 10.0}   # VecNormalize
      env_kwargs: {action_repeat: 10, randomize: true}
      residual: {enabled: false, base: feedforward-pd, scale: 0.2}   # + base_rate: sample | policy
      eval: {seed: 10000, n_episodes: 5, freq: 20000}   # freq in agent steps, all envs together
      checkpoint_freq: 50000       # agent steps, all envs together
      hyperparams: {...}           # keyword arguments of the stable-baselines3 class

Unlike the zoo, ``policy_kwargs`` is a plain mapping (never ``eval``-ed):
``{net_arch: [64, 64], activation_fn: tanh}``. Unknown keys are refused by name.
"""

from __future__ import annotations

import copy
import inspect
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from addedinertia_env.foundation.config_io import read_yaml

from addedinertia_env.sim.presets import CONFIG_DIR, ConfigError

ALGO_DIR = CONFIG_DIR / "algos"
DEFAULT_ENV_ID = "AddedInertia/ReverseStroke-v0"
# command-line name -> (config file stem, "module:class")
ALGOS: dict[str, tuple[str, str]] = {
    "ppo": ("ppo", "stable_baselines3:PPO"),
    "sac": ("sac", "stable_baselines3:SAC"),
    "td3": ("td3", "stable_baselines3:TD3"),
    "recurrent-ppo": ("recurrent_ppo", "sb3_contrib:RecurrentPPO"),
}
VEC_ENVS = ("batched", "dummy", "subproc")
BLOCK_KEYS = {"policy", "n_timesteps", "n_envs", "vec_env", "normalize", "env_kwargs", "residual", "eval",
              "checkpoint_freq", "hyperparams"}
NORMALIZE_KEYS = {"norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma"}
RESIDUAL_KEYS = {"enabled", "base", "scale", "base_params", "base_rate"}
EVAL_KEYS = {"seed", "n_episodes", "freq"}
ACTIVATIONS = {"tanh": "Tanh", "relu": "ReLU", "elu": "ELU", "leaky_relu": "LeakyReLU"}


@dataclass
class TrainConfig:
    """One validated training block (see the module docstring for the meaning of each key)."""

    algo: str
    env_id: str
    path: str
    policy: str = "MlpPolicy"
    n_timesteps: int = 100_000
    n_envs: int = 2
    vec_env: str = "dummy"
    normalize: dict[str, Any] = field(default_factory=lambda: {"norm_obs": True, "norm_reward": False,
                                                               "clip_obs": 10.0})
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    residual: dict[str, Any] = field(default_factory=lambda: {"enabled": False, "base": "feedforward-pd",
                                                              "scale": 0.2})
    eval: dict[str, Any] = field(default_factory=lambda: {"seed": 10_000, "n_episodes": 5, "freq": 20_000})
    checkpoint_freq: int = 50_000
    hyperparams: dict[str, Any] = field(default_factory=dict)

    @property
    def algo_class(self):
        """The algorithm's class (``stable_baselines3.PPO``, ``sb3_contrib.RecurrentPPO``, ...), imported on demand."""
        module, _, name = ALGOS[self.algo][1].partition(":")
        return getattr(__import__(module, fromlist=[name]), name)

    def as_dict(self) -> dict[str, Any]:
        """The config as a plain dict (deep copies), as written into the training card."""
        return {k: copy.deepcopy(getattr(self, k)) for k in ("algo", "env_id", "path", "policy", "n_timesteps",
                                                             "n_envs", "vec_env", "normalize", "env_kwargs",
                                                             "residual", "eval", "checkpoint_freq", "hyperparams")}

    def model_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for the stable-baselines3 class, with names turned into objects."""
        kwargs = copy.deepcopy(self.hyperparams)
        pk = kwargs.get("policy_kwargs")
        if pk and "activation_fn" in pk:
            import torch.nn as nn  # noqa: PLC0415

            pk["activation_fn"] = getattr(nn, ACTIVATIONS[pk["activation_fn"]])
        noise = kwargs.pop("action_noise", None)
        if noise:
            import numpy as np  # noqa: PLC0415
            from stable_baselines3.common.noise import NormalActionNoise  # noqa: PLC0415

            kwargs["action_noise"] = NormalActionNoise(np.zeros(1), np.full(1, float(noise["sigma"])))
        return kwargs


def config_path(algo: str) -> Path:
    """The YAML file of algorithm ``algo`` in ``configs/algos/``; ConfigError naming the known algorithms otherwise."""
    if algo not in ALGOS:
        raise ConfigError(f"unknown algorithm {algo!r}; expected one of {', '.join(ALGOS)}")
    return ALGO_DIR / f"{ALGOS[algo][0]}.yaml"


def load_config(algo: str, path: str | Path | None = None, env_id: str = DEFAULT_ENV_ID) -> TrainConfig:
    """The block for ``env_id`` in ``path`` (default ``configs/algos/<algo>.yaml``), validated."""
    path = Path(path) if path else config_path(algo)
    if algo not in ALGOS:
        raise ConfigError(f"unknown algorithm {algo!r}; expected one of {', '.join(ALGOS)}")
    if not path.exists():
        raise ConfigError(f"config file {path} does not exist; see configs/algos/ for examples")
    data = read_yaml(path, "training config")
    if not isinstance(data, dict) or env_id not in data:
        found = list(data) if isinstance(data, dict) else type(data).__name__
        raise ConfigError(f"{path}: expected a block for environment {env_id!r} at the top level, found {found}")
    block = data[env_id]
    where = f"{path}: {env_id}"
    if not isinstance(block, dict):
        raise ConfigError(f"{where}: expected a mapping of settings")
    _only(block, BLOCK_KEYS, where)
    cfg = TrainConfig(algo=algo, env_id=env_id, path=str(path))
    for key in ("policy", "vec_env"):
        if key in block:
            setattr(cfg, key, str(block[key]))
    for key in ("n_timesteps", "n_envs", "checkpoint_freq"):
        if key in block:
            setattr(cfg, key, _positive_int(block[key], f"{where}: {key}"))
    if cfg.vec_env not in VEC_ENVS:
        raise ConfigError(f"{where}: vec_env = {cfg.vec_env!r}; expected one of {', '.join(VEC_ENVS)}")
    for key, allowed in (("normalize", NORMALIZE_KEYS), ("residual", RESIDUAL_KEYS), ("eval", EVAL_KEYS)):
        if key in block:
            sub = block[key] or {}
            if not isinstance(sub, dict):
                raise ConfigError(f"{where}: {key} must be a mapping, got {sub!r}")
            _only(sub, allowed, f"{where}: {key}")
            getattr(cfg, key).update(sub)
    if "env_kwargs" in block:
        if not isinstance(block["env_kwargs"], dict):
            raise ConfigError(f"{where}: env_kwargs must be a mapping")
        cfg.env_kwargs = dict(block["env_kwargs"])
    scale = cfg.residual["scale"]
    if not (isinstance(scale, (int, float)) and 0 < scale <= 2):
        raise ConfigError(f"{where}: residual.scale = {scale!r}; expected a number in (0, 2] (fraction of i_max)")
    base_rate = cfg.residual.get("base_rate", "sample")
    if base_rate not in ("sample", "policy"):
        raise ConfigError(f"{where}: residual.base_rate = {base_rate!r}; expected 'sample' (the base at every rig "
                          "sample) or 'policy' (once per action, held with it: a policy for a two-rate bench)")
    for key in ("n_episodes", "freq", "seed"):
        cfg.eval[key] = _positive_int(cfg.eval[key], f"{where}: eval.{key}", allow_zero=key == "seed")
    hyper = block.get("hyperparams") or {}
    if not isinstance(hyper, dict):
        raise ConfigError(f"{where}: hyperparams must be a mapping")
    _check_hyperparams(cfg, hyper, f"{where}: hyperparams")
    cfg.hyperparams = dict(hyper)
    return cfg


def _check_hyperparams(cfg: TrainConfig, hyper: dict[str, Any], where: str) -> None:
    accepted = set(inspect.signature(cfg.algo_class.__init__).parameters) - {"self", "policy", "env"}
    reserved = {"seed", "tensorboard_log", "verbose", "device", "_init_setup_model"}
    _only(hyper, accepted - reserved, where)
    pk = hyper.get("policy_kwargs") or {}
    if not isinstance(pk, dict):
        raise ConfigError(f"{where}: policy_kwargs must be a mapping such as {{net_arch: [64, 64]}}")
    if "activation_fn" in pk and pk["activation_fn"] not in ACTIVATIONS:
        raise ConfigError(f"{where}: policy_kwargs.activation_fn = {pk['activation_fn']!r}; "
                          f"expected one of {', '.join(ACTIVATIONS)}")
    noise = hyper.get("action_noise")
    if noise is not None:
        if not (isinstance(noise, dict) and set(noise) == {"type", "sigma"} and noise["type"] == "normal"):
            raise ConfigError(f"{where}: action_noise = {noise!r}; expected {{type: normal, sigma: 0.1}}")


def _only(mapping: dict[str, Any], allowed: set[str], where: str) -> None:
    unknown = sorted(set(mapping) - allowed)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed keys are {sorted(allowed)}")


def _positive_int(value: Any, where: str, allow_zero: bool = False) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool) or value < (0 if allow_zero else 1):
        raise ConfigError(f"{where} = {value!r}; expected an integer {'>= 0' if allow_zero else '> 0'}")
    return value
