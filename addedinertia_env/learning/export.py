"""Export a trained model to ONNX: VecNormalize in front, the deterministic actor, the action clip.

The graph maps the task's raw observation (``task.OBSERVATION_FIELDS``, shape
``(batch, 16)``, float32) to the network's action in [-1, 1]::

    x = clip((obs - mean) / sqrt(var + eps), -clip_obs, clip_obs)    # VecNormalize, frozen
    PPO:      a = clip(action_net(mlp_extractor.forward_actor(x)), -1, 1)   # the Gaussian's mean
    SAC/TD3:  a = tanh-squashed actor(x)                                    # already in [-1, 1]

which is what ``model.predict(vecnormalize.normalize_obs(obs), deterministic=True)``
returns. How that action drives the rig (held for ``action_repeat`` samples, added to a
base controller for residual policies) is in the metadata and the card beside the file;
:class:`agents.onnx_policy.OnnxPolicy` applies it.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.sim.presets import ConfigError
from addedinertia_env.experiment.task import OBS_LIMIT, OBSERVATION_FIELDS
from addedinertia_env.learning.callbacks import write_json_atomic

OPSET = 17
META_PREFIX = "addedinertia."


def load_trained(model_path: str | Path):
    """(model, vecnormalize or None, training card or {}) from ``model.zip`` or the folder holding it."""
    from stable_baselines3.common.vec_env import VecNormalize  # noqa: PLC0415

    from addedinertia_env.learning.config import ALGOS  # noqa: PLC0415

    path = Path(model_path)
    if path.is_dir():
        path = path / "model.zip"
    if not path.exists():
        raise FileNotFoundError(f"model {path} does not exist; pass the model.zip written by `addedinertia train`")
    card_path = path.with_name("training_card.json")
    card = json.loads(card_path.read_text()) if card_path.exists() else {}
    algo = card.get("algo")
    candidates = [algo] if algo else ["ppo", "sac", "td3", "recurrent-ppo"]
    model = None
    for name in candidates:
        module, _, cls = ALGOS[name][1].partition(":")
        try:
            model = getattr(__import__(module, fromlist=[cls]), cls).load(str(path), device="cpu")
            card.setdefault("algo", name)
            break
        except (KeyError, ValueError, TypeError, RuntimeError, AttributeError):
            continue
    if model is None:
        raise ConfigError(f"{path}: not a stable-baselines3 PPO, SAC, TD3 or RecurrentPPO model")
    vn_path = path.with_name("vecnormalize.pkl")
    vecnorm = VecNormalize.load(str(vn_path), _DummyVec(model)) if vn_path.exists() else None
    if vecnorm is not None:
        vecnorm.training = False
    return model, vecnorm, card


class _DummyVec:
    """Just enough of a VecEnv for ``VecNormalize.load`` (no environment is needed to export)."""

    def __init__(self, model):
        self.observation_space, self.action_space = model.observation_space, model.action_space
        self.num_envs = 1
        self.render_mode = None

    def __getattr__(self, name):  # VecEnvWrapper may probe optional attributes
        raise AttributeError(name)


def _actor_module(model, vecnorm):
    import torch  # noqa: PLC0415
    from torch import nn  # noqa: PLC0415

    kind = type(model).__name__
    if kind == "RecurrentPPO":
        raise ConfigError("export of recurrent-ppo models is not supported yet (the LSTM state would need "
                          "to be graph inputs/outputs); export a ppo, sac or td3 model")
    policy = model.policy
    policy.set_training_mode(False)
    n_obs = model.observation_space.shape[0]
    if vecnorm is not None and vecnorm.norm_obs:
        mean = torch.as_tensor(vecnorm.obs_rms.mean, dtype=torch.float32)
        std = torch.as_tensor(np.sqrt(vecnorm.obs_rms.var + vecnorm.epsilon), dtype=torch.float32)
        clip = float(vecnorm.clip_obs)
    else:
        mean, std, clip = torch.zeros(n_obs), torch.ones(n_obs), float("inf")
    low = torch.as_tensor(model.action_space.low, dtype=torch.float32)
    high = torch.as_tensor(model.action_space.high, dtype=torch.float32)

    class Actor(nn.Module):
        def __init__(self):
            super().__init__()
            self.policy = policy
            self.register_buffer("mean", mean)
            self.register_buffer("std", std)
            self.register_buffer("low", low)
            self.register_buffer("high", high)

        def forward(self, obs):
            x = (obs - self.mean) / self.std
            if clip != float("inf"):
                x = torch.clamp(x, -clip, clip)
            if kind == "PPO":
                features = self.policy.pi_features_extractor(x)
                action = self.policy.action_net(self.policy.mlp_extractor.forward_actor(features))
                return torch.max(torch.min(action, self.high), self.low)
            squashed = self.policy.actor(x, deterministic=True) if kind == "SAC" else self.policy.actor(x)
            return self.low + 0.5 * (squashed + 1.0) * (self.high - self.low)

    if kind not in ("PPO", "SAC", "TD3"):
        raise ConfigError(f"cannot export a {kind} model; expected PPO, SAC or TD3")
    return Actor().eval()


def export_onnx(model_path: str | Path, onnx_path: str | Path, n_parity: int = 1000,
                extra_card: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write ``onnx_path`` and its card (``<stem>.json``); returns the card with parity and latency."""
    import onnx  # noqa: PLC0415
    import torch  # noqa: PLC0415

    from addedinertia_env import __version__  # noqa: PLC0415

    model, vecnorm, train_card = load_trained(model_path)
    actor = _actor_module(model, vecnorm)
    onnx_path = Path(onnx_path)
    onnx_path.parent.mkdir(parents=True, exist_ok=True)
    n_obs = model.observation_space.shape[0]
    if n_obs != len(OBSERVATION_FIELDS):
        raise ConfigError(f"{model_path}: observation size {n_obs}; the task has {len(OBSERVATION_FIELDS)} fields")
    tmp = onnx_path.with_name(onnx_path.name + ".tmp")
    with torch.no_grad():
        torch.onnx.export(actor, (torch.zeros(1, n_obs),), str(tmp), input_names=["obs"], output_names=["action"],
                          dynamic_axes={"obs": {0: "batch"}, "action": {0: "batch"}}, opset_version=OPSET,
                          dynamo=False)
    graph = onnx.load(str(tmp))
    residual = train_card.get("residual") or {}
    cost = train_card.get("cost") or {}
    repeat = int(train_card.get("action_repeat", 1))
    sample_rate = float(train_card.get("sample_rate_hz") or 1000.0)
    # A residual policy whose base runs at every sample acts at the sample rate; one whose base
    # runs once per action (base_rate "policy") acts, like a plain policy, every `repeat` samples.
    base_rate = str(residual.get("base_rate") or "sample") if residual else ""
    policy_rate = sample_rate if base_rate == "sample" else sample_rate / repeat
    meta = {
        "version": __version__,
        "algo": train_card.get("algo", ""),
        "env_id": train_card.get("env_id", ""),
        "action_repeat": str(repeat),
        "sample_rate_hz": repr(sample_rate),
        "policy_rate_hz": repr(policy_rate),
        "board_mode": str(train_card.get("board_mode") or "zoh"),
        "residual_base": residual.get("base", "") if residual else "",
        "residual_scale": str(float(residual.get("scale", 0.0))) if residual else "0",
        "residual_base_params": json.dumps(residual.get("base_params") or {}) if residual else "{}",
        "residual_base_rate": base_rate,
        "obs_fields": json.dumps(train_card.get("observation_fields") or list(OBSERVATION_FIELDS)),
        "train_env_steps": str(cost.get("env_steps", "")),
        "train_cpu_minutes": str(cost.get("cpu_minutes", "")),
    }
    save_with_metadata(graph, meta, onnx_path)

    parity = parity_max_abs_diff(onnx_path, model, vecnorm, n=n_parity)
    latency = measure_latency_us(onnx_path)
    data = onnx_path.read_bytes()
    card = {
        "kind": "addedinertia policy card",
        "onnx": onnx_path.name,
        "size_bytes": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
        "opset": OPSET,
        "metadata": meta,
        "action_repeat": int(meta["action_repeat"]),
        "policy_rate_hz": policy_rate,  # Hz: the rate the policy acts at (deploy --host-rate-hz must match)
        "board_mode": meta["board_mode"],  # what the board does between actions
        "sample_rate_hz": sample_rate,
        "residual": residual or None,
        "observation_fields": list(OBSERVATION_FIELDS),
        "parity_max_abs_diff": parity,
        "latency_us": latency,
        "training": _portable({k: train_card.get(k) for k in ("algo", "env_id", "seed", "env_seeds", "eval_seed",
                                                              "command", "cost", "machine", "final_eval", "config",
                                                              "resumed_from")}),
        **(extra_card or {}),
    }
    write_json_atomic(onnx_path.with_suffix(".json"), card)
    return card


def save_with_metadata(graph, meta: dict[str, str], onnx_path: str | Path) -> None:
    """Write the ONNX ``graph`` to ``onnx_path`` atomically (a ``.tmp`` beside it, then a
    rename), after adding every ``meta`` item as metadata ``addedinertia.<key>`` and
    checking the model with ``onnx.checker``."""
    import onnx  # noqa: PLC0415

    onnx_path = Path(onnx_path)
    for key, value in meta.items():
        entry = graph.metadata_props.add()
        entry.key, entry.value = META_PREFIX + key, value
    graph.producer_name = "addedinertia"
    onnx.checker.check_model(graph)
    tmp = onnx_path.with_name(onnx_path.name + ".tmp")
    onnx.save(graph, str(tmp))
    tmp.replace(onnx_path)


def _portable(training: dict[str, Any]) -> dict[str, Any]:
    """The training record with the config path relative to the repository (no machine's absolute path)."""
    from addedinertia_env.sim.presets import CONFIG_DIR  # noqa: PLC0415

    config = dict(training.get("config") or {})
    path = config.get("path")
    if path and Path(path).is_absolute():
        try:
            config["path"] = Path(path).resolve().relative_to(CONFIG_DIR.parent).as_posix()
        except ValueError:
            pass  # outside the repository: keep it as given
    return {**training, "config": config}


def random_observations(n: int, vecnorm=None, seed: int = 0) -> np.ndarray:
    """``n`` observations over the range a policy sees: half uniform in +-OBS_LIMIT, half near the data."""
    rng = np.random.default_rng(seed)
    size = len(OBSERVATION_FIELDS)
    uniform = rng.uniform(-OBS_LIMIT, OBS_LIMIT, (n - n // 2, size))
    if vecnorm is not None:
        near = vecnorm.obs_rms.mean + np.sqrt(vecnorm.obs_rms.var) * rng.standard_normal((n // 2, size)) * 2.0
    else:
        near = rng.standard_normal((n // 2, size))
    return np.clip(np.vstack([uniform, near]), -OBS_LIMIT, OBS_LIMIT).astype(np.float32)


def parity_max_abs_diff(onnx_path: str | Path, model, vecnorm, n: int = 1000, seed: int = 0) -> float:
    """max |onnx(obs) - model.predict(normalize(obs), deterministic=True)| over ``n`` observations."""
    import onnxruntime as ort  # noqa: PLC0415

    obs = random_observations(n, vecnorm, seed)
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    onnx_actions = session.run(None, {"obs": obs})[0]
    normed = vecnorm.normalize_obs(obs) if vecnorm is not None else obs
    sb3_actions, _ = model.predict(normed, deterministic=True)
    return float(np.max(np.abs(onnx_actions - sb3_actions)))


def measure_latency_us(onnx_path: str | Path, n: int = 2000, warmup: int = 200) -> dict[str, float]:
    """Single-observation onnxruntime inference time on one thread: p50 and p99, microseconds."""
    import onnxruntime as ort  # noqa: PLC0415

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = opts.inter_op_num_threads = 1
    session = ort.InferenceSession(str(onnx_path), opts, providers=["CPUExecutionProvider"])
    obs = random_observations(1)
    feed = {"obs": obs}
    for _ in range(warmup):
        session.run(None, feed)
    times = np.empty(n)
    for k in range(n):
        t0 = time.perf_counter()
        session.run(None, feed)
        times[k] = time.perf_counter() - t0
    return {"p50": round(float(np.percentile(times, 50)) * 1e6, 1),
            "p99": round(float(np.percentile(times, 99)) * 1e6, 1), "n": n}
