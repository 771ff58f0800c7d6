"""ONNX export of a residual correction trained on the batched engine (ARS, DAgger), with its card.

The trainers (:mod:`.ars_residual`, :mod:`.dagger`) each build their network as a torch module
(observation -> correction in [-1, 1]); everything after that is shared here: the ONNX graph,
the metadata that ``agents/onnx_policy.py`` reads (a residual on a classical base acting once
per drive set-point, board mode ``zoh``, the base deciding with the correction once per action,
as trained), the parity of the ONNX graph with the numpy policy, its latency, and the card
``<stem>.json`` written atomically beside the ``.onnx`` file.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Callable

import numpy as np

from addedinertia_env.foundation.machine import machine_info
from addedinertia_env.experiment.task import OBSERVATION_FIELDS
from addedinertia_env.learning.callbacks import write_json_atomic
from addedinertia_env.learning.export import OPSET, measure_latency_us, random_observations, save_with_metadata

SAMPLE_RATE_HZ = 1000.0  # the rig's sample rate the trainers run at


def export_residual(module, numpy_policy: Callable[[np.ndarray], np.ndarray], train_card: dict[str, Any],
                    onnx_path: str | Path, *, algo: str, parity_obs: np.ndarray | None = None,
                    residual_extra: dict[str, Any] | None = None, card_extra: dict[str, Any] | None = None,
                    extra_card: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write ``module`` (a torch module, observations ``(batch, n_obs)`` float32 -> corrections
    ``(batch, 1)``) as ONNX at ``onnx_path`` with the residual metadata, and its card; returns the card.

    ``numpy_policy`` is the same policy in numpy (the parity check runs both on ``parity_obs``,
    default 1000 random observations); ``train_card`` is the run's ``training_card.json`` (``suite``,
    ``base``, ``scale``, ``base_params``, ``action_repeat``, ``cost``); ``algo`` names the trainer;
    ``residual_extra`` adds keys to the card's ``residual`` block, ``card_extra`` and ``extra_card``
    to the card itself.
    """
    import onnx  # noqa: PLC0415 - torch and onnx are heavy
    import onnxruntime as ort  # noqa: PLC0415
    import torch  # noqa: PLC0415

    from addedinertia_env import __version__  # noqa: PLC0415

    onnx_path = Path(onnx_path)
    onnx_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = onnx_path.with_name(onnx_path.name + ".tmp")
    with torch.no_grad():
        torch.onnx.export(module.eval(), (torch.zeros(1, len(OBSERVATION_FIELDS)),), str(tmp), input_names=["obs"],
                          output_names=["action"], dynamic_axes={"obs": {0: "batch"}, "action": {0: "batch"}},
                          opset_version=OPSET, dynamo=False)
    graph = onnx.load(str(tmp))
    tmp.unlink()
    repeat = int(train_card["action_repeat"])
    cost = train_card["cost"]
    meta = {
        "version": __version__, "algo": algo, "env_id": "AddedInertia/ReverseStroke-v0",
        "suite": train_card["suite"], "action_repeat": str(repeat), "sample_rate_hz": repr(SAMPLE_RATE_HZ),
        # base and correction both act once per drive set-point (the suite's 100 Hz), as trained
        "policy_rate_hz": repr(SAMPLE_RATE_HZ / repeat), "board_mode": "zoh",
        "residual_base": train_card["base"], "residual_scale": str(float(train_card["scale"])),
        "action_limit": str(float(train_card.get("action_limit", 1.0))),  # base + correction stays inside it
        "residual_base_params": json.dumps(train_card.get("base_params") or {}),
        "residual_base_rate": "policy",  # the base decides with the correction, once per action
        "obs_fields": json.dumps(list(OBSERVATION_FIELDS)),
        "train_env_steps": str(cost["env_steps"]), "train_cpu_minutes": str(cost["cpu_minutes"]),
    }
    save_with_metadata(graph, meta, onnx_path)

    obs = random_observations(1000) if parity_obs is None else np.asarray(parity_obs, dtype=np.float32)
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    parity = float(np.max(np.abs(session.run(None, {"obs": obs})[0].reshape(-1) - numpy_policy(obs))))
    blob = onnx_path.read_bytes()
    card = {
        "kind": "addedinertia policy card", "onnx": onnx_path.name, "size_bytes": len(blob),
        "sha256": hashlib.sha256(blob).hexdigest(), "opset": OPSET, "metadata": meta,
        "action_repeat": repeat, "policy_rate_hz": SAMPLE_RATE_HZ / repeat, "board_mode": "zoh",
        "sample_rate_hz": SAMPLE_RATE_HZ,
        "residual": {"enabled": True, "base": train_card["base"], "scale": float(train_card["scale"]),
                     "action_limit": float(train_card.get("action_limit", 1.0)),
                     "base_params": train_card.get("base_params") or {}, "base_rate": "policy",
                     **(residual_extra or {})},
        "observation_fields": list(OBSERVATION_FIELDS), "parity_max_abs_diff": parity,
        **(card_extra or {}),
        "latency_us": measure_latency_us(onnx_path),
        "training": {**train_card, "machine": machine_info()},
        **(extra_card or {}),
    }
    write_json_atomic(onnx_path.with_suffix(".json"), card)
    return card
