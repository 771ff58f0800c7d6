"""The residual-controller step, shared by training (``learning/envs.py``) and the exported
policy (``agents/onnx_policy.py``), so that a policy acts as it was trained."""

from __future__ import annotations

import numpy as np


def residual_action(base_action, correction, scale: float) -> np.ndarray:
    """``clip(base + scale * clip(correction, -1, 1), -1, 1)`` as a float32 array of shape (1,).

    ``base_action`` is the classical controller's normalised action, ``correction`` the
    policy's raw action (both fractions of the drive's limit), ``scale`` the largest
    correction (a fraction of the limit)."""
    r = np.clip(np.asarray(correction, dtype=np.float32).reshape(-1)[:1], -1.0, 1.0)
    action = np.asarray(base_action, dtype=np.float32).reshape(1) + scale * r
    return np.clip(action, -1.0, 1.0).astype(np.float32)
