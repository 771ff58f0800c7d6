"""A policy exported by ``addedinertia export``, run with onnxruntime: ``--controller onnx:PATH``.

The ONNX graph maps the raw observation to the network's action in [-1, 1] (observation
normalisation is inside). Its metadata (``addedinertia.*``) says how to drive the rig:

- ``policy_rate_hz``, ``board_mode``, ``sample_rate_hz``: the rate the policy acts at,
  what the board does between its actions (``zoh``) and the board's sample rate in
  training; ``deploy --host-rate-hz`` refuses a policy whose rate or mode the bench does
  not match (cards without them: derived from ``action_repeat``; a residual policy's
  base runs every sample, so it acts at the sample rate).
- ``action_repeat``: rig samples per network evaluation. The benchmark calls
  :meth:`predict` every sample (1 kHz); the network runs on every ``action_repeat``-th
  call and its output is held in between, as in training. The counter restarts at
  :meth:`reset`.
- ``residual_base`` / ``residual_scale``: if set, the network is a correction on top of
  a classical controller, recreated here from its name and reset with the same
  :class:`~agents.base.ControllerContext` (sensor data only); the action is
  ``clip(base(obs) + scale * network, -limit, limit)``, with the parameters the base had in
  training (``residual_base_params``, pinned) and ``limit`` the metadata's ``action_limit``
  (a fraction of i_max in (0, 1], default 1: the policy's own current limit). ``residual_base_rate`` says where the base
  runs: ``sample`` (default) every sample, so the policy acts at the sample rate;
  ``policy`` with the network, once per ``action_repeat`` samples, its context's ``dt``
  the policy period, the whole action held in between: a policy for a two-rate bench.

Training cost (``train_env_steps``, ``train_cpu_minutes``) is read from the metadata so
the benchmark can put it in the leaderboard row.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.experiment.task import OBSERVATION_FIELDS

from agents.classical import UnknownController, make_plain_controller
from agents.residual import BASE_RATES, policy_rate_context, residual_action

META_PREFIX = "addedinertia."
MAX_POLICY_BYTES = 200_000_000  # a policy network for this task is well under 1 MB
MAX_ACTION_REPEAT = 1000  # rig samples per network evaluation (1 Hz at a 1 kHz rig)
DEFAULT_SAMPLE_RATE_HZ = 1000.0  # Hz, the board sample rate of policies whose card does not say


class OnnxPolicyError(ValueError):
    """The ONNX file cannot be used as a controller; the message says why."""


class OnnxPolicy:
    """``predict(obs) -> (action, state)`` from an exported ONNX policy; see the module docstring."""

    def __init__(self, path: str | Path):
        import onnxruntime as ort  # noqa: PLC0415 - heavy, only for learned controllers

        self.path = Path(path)
        if not self.path.is_file():
            raise OnnxPolicyError(f"{self.path}: no such file; expected an ONNX policy written by `addedinertia export`")
        size = self.path.stat().st_size
        if size > MAX_POLICY_BYTES:
            raise OnnxPolicyError(f"{self.path}: {size} bytes; expected an exported policy of at most "
                                  f"{MAX_POLICY_BYTES} bytes")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = 1
        opts.log_severity_level = 3  # errors only: a refusal is one line, not onnxruntime's log
        try:
            self.session = ort.InferenceSession(str(self.path), opts, providers=["CPUExecutionProvider"])
        except Exception as e:  # noqa: BLE001 - onnxruntime raises its own exception types
            first = " ".join(str(e).split())[:200]
            raise OnnxPolicyError(f"{self.path}: not a loadable ONNX model ({first}); expected a policy written by "
                                  "`addedinertia export`") from None
        props = self.session.get_modelmeta().custom_metadata_map
        self.metadata = {k[len(META_PREFIX):]: v for k, v in props.items() if k.startswith(META_PREFIX)}
        try:
            fields = json.loads(self.metadata.get("obs_fields", "null") or "null")
        except json.JSONDecodeError:
            raise OnnxPolicyError(f"{self.path}: metadata obs_fields is not JSON; expected the list of observation "
                                  "fields it was trained on") from None
        if fields is not None and fields != list(OBSERVATION_FIELDS):
            raise OnnxPolicyError(f"{self.path}: trained on observation fields {fields}; this version observes "
                                  f"{list(OBSERVATION_FIELDS)}. Retrain or use a matching version.")
        self.input_name = self._check_signature()
        self.action_repeat = self._meta_number("action_repeat", "1", int, 1, MAX_ACTION_REPEAT)
        self.algo = self.metadata.get("algo", "")
        self.residual_base = self.metadata.get("residual_base", "") or None
        self.residual_scale = self._meta_number("residual_scale", "0", float, 0.0, 1.0)
        # the policy's own current limit (fraction of i_max): base + correction stays inside it
        self.action_limit = self._meta_number("action_limit", "1", float, 1e-3, 1.0)
        self.sample_rate_hz = (self._meta_number("sample_rate_hz", "0", float, 1.0, 1e6)
                               if self.metadata.get("sample_rate_hz") else None)
        self.residual_base_rate = (self.metadata.get("residual_base_rate", "") or "sample") if self.residual_base else ""
        if self.residual_base and self.residual_base_rate not in BASE_RATES:
            raise OnnxPolicyError(f"{self.path}: metadata residual_base_rate = {self.residual_base_rate!r}; expected "
                                  f"one of {list(BASE_RATES)}")
        # The rate the policy acts at: a residual policy whose base runs every sample acts at the sample rate.
        fs = self.sample_rate_hz or DEFAULT_SAMPLE_RATE_HZ
        derived = fs if self.residual_base_rate == "sample" else fs / self.action_repeat
        self.policy_rate_hz = _optional_float(self.metadata.get("policy_rate_hz")) or derived
        self.board_mode = self.metadata.get("board_mode", "") or "zoh"
        self.train_env_steps = _optional_int(self.metadata.get("train_env_steps"))
        self.train_cpu_minutes = _optional_float(self.metadata.get("train_cpu_minutes"))
        self.name = f"onnx:{self.path.name}"
        self.base = None
        try:
            self.residual_base_params = json.loads(self.metadata.get("residual_base_params", "{}") or "{}")
        except json.JSONDecodeError:
            raise OnnxPolicyError(f"{self.path}: metadata residual_base_params is not JSON; expected an object "
                                  "of the base controller's parameters") from None
        if self.residual_base:
            self.base = self._make_base()
        self._calls = 0
        self._held = np.zeros(1, dtype=np.float32)
        self._held_total = np.zeros(1, dtype=np.float32)

    def _meta_number(self, key: str, default: str, kind: type, low: float, high: float):
        """Metadata ``key`` as a number in [low, high], else OnnxPolicyError."""
        text = self.metadata.get(key, default) or default
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not math.isfinite(value) or not low <= value <= high:
            raise OnnxPolicyError(f"{self.path}: metadata {key} = {text!r}; expected a number in [{low:g}, {high:g}]")
        return value

    def _check_signature(self) -> str:
        """One float input ``(batch, n_obs)`` and an output ``(batch, 1)``, tried on a zero observation."""
        n_obs = len(OBSERVATION_FIELDS)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) != 1:
            raise OnnxPolicyError(f"{self.path}: {len(inputs)} inputs; expected one, the observation "
                                  f"(batch, {n_obs})")
        shape = inputs[0].shape
        if inputs[0].type != "tensor(float)" or len(shape) != 2 or (isinstance(shape[1], int) and shape[1] != n_obs):
            raise OnnxPolicyError(f"{self.path}: input {inputs[0].name!r} is {inputs[0].type} {shape}; expected "
                                  f"tensor(float) [batch, {n_obs}] (addedinertia_env.experiment.task.OBSERVATION_FIELDS)")
        if not outputs:
            raise OnnxPolicyError(f"{self.path}: no outputs; expected the action (batch, 1)")
        try:
            out = self.session.run(None, {inputs[0].name: np.zeros((2, n_obs), dtype=np.float32)})[0]
        except Exception as e:  # noqa: BLE001 - onnxruntime's own types
            first = " ".join(str(e).split())[:200]
            raise OnnxPolicyError(f"{self.path}: fails on an observation of {n_obs} fields ({first}); expected a "
                                  f"policy for this task's observation") from None
        out = np.asarray(out)
        if out.shape != (2, 1):
            raise OnnxPolicyError(f"{self.path}: action of shape {list(out.shape)} for a batch of 2 observations; "
                                  "expected [2, 1] (one drive command per observation)")
        if not np.all(np.isfinite(out)):
            raise OnnxPolicyError(f"{self.path}: non-finite action {out.ravel().tolist()} for a zero observation")
        return inputs[0].name

    def check_rate(self, dt: float) -> None:
        """Refuse a control period other than the one the policy was trained at (when its metadata says)."""
        if self.sample_rate_hz is not None and abs(1.0 / dt - self.sample_rate_hz) > 1e-6 * self.sample_rate_hz:
            raise OnnxPolicyError(f"{self.path}: trained at {self.sample_rate_hz:g} Hz; this rig samples at "
                                  f"{1.0 / dt:g} Hz. Retrain for this rate or use a matching rig.")

    def _make_base(self):
        """The base controller with the parameters it was trained with (never re-read from tuned.yaml)."""
        try:
            if not self.residual_base_params:
                return make_plain_controller(self.residual_base)
            return make_plain_controller(self.residual_base, tuned=False, **self.residual_base_params)
        except UnknownController as e:
            raise OnnxPolicyError(f"{self.path}: residual base controller: {e}") from None
        except TypeError as e:
            raise OnnxPolicyError(f"{self.path}: base controller {self.residual_base!r} no longer takes the "
                                  f"parameters it was trained with ({e}); retrain the policy") from None

    def reset(self, context: Any = None) -> None:
        """Start of an episode: restart the hold counter; reset the base controller with ``context``.

        Called at the policy's own rate (a two-rate bench: ``context.policy_rate_hz``), the
        network runs at every call: the board holds its action in between. Called every
        ``k`` samples otherwise (a drive with a slower set-point rate: ``context.dt`` is
        ``k`` samples of ``context.sample_dt``), it runs every ``max(1, action_repeat // k)``
        calls, i.e. every ``action_repeat`` samples as in training."""
        self._calls = 0
        rate = getattr(context, "policy_rate_hz", None)
        self._repeat = 1 if rate is not None and abs(rate - self.policy_rate_hz) < 1e-6 * rate else self.action_repeat
        sample_dt = getattr(context, "sample_dt", None)
        if self._repeat > 1 and sample_dt and getattr(context, "dt", None):
            self._repeat = max(1, self.action_repeat // max(1, int(round(context.dt / sample_dt))))
        self._held = np.zeros(1, dtype=np.float32)
        self._held_total = np.zeros(1, dtype=np.float32)
        if context is not None and getattr(context, "dt", None):
            self.check_rate(float(getattr(context, "sample_dt", None) or context.dt))  # the board's sample period
        if self.base is not None:
            if context is None:
                raise OnnxPolicyError(f"{self.path}: a residual policy on {self.residual_base!r} needs "
                                      "reset(context) with the ControllerContext before predict()")
            if self.residual_base_rate == "policy":  # the base acts with the network, at the policy's period
                context = policy_rate_context(context, self.action_repeat)
            self.base.reset(context)

    def network(self, observation: np.ndarray) -> np.ndarray:
        """The graph's raw action(s) in [-1, 1] for one observation or a batch."""
        obs = np.asarray(observation, dtype=np.float32)
        batch = obs.reshape(-1, len(OBSERVATION_FIELDS))
        return self.session.run(None, {self.input_name: batch})[0].reshape(obs.shape[:-1] + (-1,))

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """The action for ``observation`` (Stable-Baselines3 ``predict`` signature), a fraction of ``i_max``.

        The network is evaluated every ``action_repeat`` calls and its output held; a residual
        policy adds it to its base controller's action, the base deciding every call or, with
        ``residual_base_rate='policy'``, once per action with the sum held. Raises
        :class:`OnnxPolicyError` for an observation of the wrong size.
        """
        obs = np.asarray(observation, dtype=np.float32).reshape(-1)
        if obs.size != len(OBSERVATION_FIELDS):
            raise OnnxPolicyError(f"observation of size {obs.size}; expected {len(OBSERVATION_FIELDS)} "
                                  "(addedinertia_env.experiment.task.OBSERVATION_FIELDS)")
        new_action = self._calls % getattr(self, "_repeat", self.action_repeat) == 0
        if new_action:
            self._held = self.network(obs).reshape(-1)[:1].astype(np.float32)
        self._calls += 1
        if self.base is None:
            return self._held.copy(), state
        if self.residual_base_rate == "policy":  # base + correction decided together, then held
            if new_action:
                base_action, _ = self.base.predict(obs, deterministic=True)
                self._held_total = residual_action(base_action, self._held, self.residual_scale, self.action_limit)
            return self._held_total.copy(), state
        base_action, _ = self.base.predict(obs, deterministic=True)
        return residual_action(base_action, self._held, self.residual_scale, self.action_limit), state


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
