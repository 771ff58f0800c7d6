"""A policy exported by ``addedinertia export``, run with onnxruntime: ``--controller onnx:PATH``.

The ONNX graph maps the raw observation to the network's action in [-1, 1] (observation
normalisation is inside). Its metadata (``addedinertia.*``) says how to drive the rig:

- ``action_repeat``: rig samples per network evaluation. The benchmark calls
  :meth:`predict` every sample (1 kHz); the network runs on every ``action_repeat``-th
  call and its output is held in between, as in training. The counter restarts at
  :meth:`reset`.
- ``residual_base`` / ``residual_scale``: if set, the network is a correction on top of
  a classical controller, recreated here from its name and reset with the same
  :class:`~agents.base.ControllerContext` (sensor data only); the action is
  ``clip(base(obs) + scale * network, -1, 1)``, the base evaluated every sample, with
  the parameters it had in training (``residual_base_params``, pinned).

Training cost (``train_env_steps``, ``train_cpu_minutes``) is read from the metadata so
the benchmark can put it in the leaderboard row.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.task import OBSERVATION_FIELDS

META_PREFIX = "addedinertia."


class OnnxPolicyError(ValueError):
    """The ONNX file cannot be used as a controller; the message says why."""


class OnnxPolicy:
    """``predict(obs) -> (action, state)`` from an exported ONNX policy; see the module docstring."""

    def __init__(self, path: str | Path):
        import onnxruntime as ort  # noqa: PLC0415 - heavy, only for learned controllers

        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"ONNX policy {self.path} does not exist; write one with `addedinertia export`")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = 1
        try:
            self.session = ort.InferenceSession(str(self.path), opts, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types
            raise OnnxPolicyError(f"{self.path}: not a loadable ONNX model ({e})") from None
        props = self.session.get_modelmeta().custom_metadata_map
        self.metadata = {k[len(META_PREFIX):]: v for k, v in props.items() if k.startswith(META_PREFIX)}
        fields = json.loads(self.metadata.get("obs_fields", "null") or "null")
        if fields is not None and fields != list(OBSERVATION_FIELDS):
            raise OnnxPolicyError(f"{self.path}: trained on observation fields {fields}; this version observes "
                                  f"{list(OBSERVATION_FIELDS)}. Retrain or use a matching version.")
        self.input_name = self.session.get_inputs()[0].name
        self.action_repeat = int(self.metadata.get("action_repeat", "1") or 1)
        if self.action_repeat < 1:
            raise OnnxPolicyError(f"{self.path}: metadata action_repeat = {self.action_repeat}; expected >= 1")
        self.algo = self.metadata.get("algo", "")
        self.residual_base = self.metadata.get("residual_base", "") or None
        self.residual_scale = float(self.metadata.get("residual_scale", "0") or 0.0)
        self.train_env_steps = _optional_int(self.metadata.get("train_env_steps"))
        self.train_cpu_minutes = _optional_float(self.metadata.get("train_cpu_minutes"))
        self.name = f"onnx:{self.path.name}"
        self.base = None
        self.residual_base_params = json.loads(self.metadata.get("residual_base_params", "{}") or "{}")
        if self.residual_base:
            self.base = self._make_base()
        self._calls = 0
        self._held = np.zeros(1, dtype=np.float32)

    def _make_base(self):
        """The base controller with the parameters it was trained with (never re-read from tuned.yaml)."""
        from .registry import make_controller  # noqa: PLC0415

        if not self.residual_base_params:
            return make_controller(self.residual_base)
        try:
            return make_controller(self.residual_base, tuned=False, **self.residual_base_params)
        except TypeError as e:
            raise OnnxPolicyError(f"{self.path}: base controller {self.residual_base!r} no longer takes the "
                                  f"parameters it was trained with ({e}); retrain the policy") from None

    def reset(self, context: Any = None) -> None:
        """Start of an episode: restart the hold counter; reset the base controller with ``context``."""
        self._calls = 0
        self._held = np.zeros(1, dtype=np.float32)
        if self.base is not None:
            if context is None:
                raise OnnxPolicyError(f"{self.path}: a residual policy on {self.residual_base!r} needs "
                                      "reset(context) with the ControllerContext before predict()")
            self.base.reset(context)

    def network(self, observation: np.ndarray) -> np.ndarray:
        """The graph's raw action(s) in [-1, 1] for one observation or a batch."""
        obs = np.asarray(observation, dtype=np.float32)
        batch = obs.reshape(-1, len(OBSERVATION_FIELDS))
        return self.session.run(None, {self.input_name: batch})[0].reshape(obs.shape[:-1] + (-1,))

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        obs = np.asarray(observation, dtype=np.float32).reshape(-1)
        if obs.size != len(OBSERVATION_FIELDS):
            raise OnnxPolicyError(f"observation of size {obs.size}; expected {len(OBSERVATION_FIELDS)} "
                                  "(addedinertia_env.task.OBSERVATION_FIELDS)")
        if self._calls % self.action_repeat == 0:
            self._held = self.network(obs).reshape(-1)[:1].astype(np.float32)
        self._calls += 1
        if self.base is None:
            return self._held.copy(), state
        base_action, _ = self.base.predict(obs, deterministic=True)
        action = np.asarray(base_action, dtype=np.float32).reshape(1) + self.residual_scale * self._held
        return np.clip(action, -1.0, 1.0).astype(np.float32), state


def _optional_int(text: str | None) -> int | None:
    try:
        return int(float(text)) if text not in (None, "") else None
    except ValueError:
        return None


def _optional_float(text: str | None) -> float | None:
    try:
        return float(text) if text not in (None, "") else None
    except ValueError:
        return None
