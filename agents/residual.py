"""The residual-controller step, shared by training (``learning/envs.py``) and the exported
policy (``agents/onnx_policy.py``), so that a policy acts as it was trained."""

from __future__ import annotations

import dataclasses

import numpy as np

BASE_RATES = ("sample", "policy")  # where a residual policy's base controller runs


def residual_action(base_action, correction, scale: float, limit: float = 1.0) -> np.ndarray:
    """``clip(base + scale * clip(correction, -1, 1), -limit, limit)`` as a float32 array of shape (1,).

    ``base_action`` is the classical controller's normalised action, ``correction`` the
    policy's raw action (both fractions of the drive's limit), ``scale`` the largest
    correction (a fraction of the limit). ``limit`` (0-1, a fraction of the drive's limit)
    is the policy's own current limit: below 1 the command never reaches the drive's limit,
    where the energy method rejects the samples (a safety margin; 1: the drive's clip only)."""
    r = np.clip(np.asarray(correction, dtype=np.float32).reshape(-1)[:1], -1.0, 1.0)
    action = np.asarray(base_action, dtype=np.float32).reshape(1) + scale * r
    lim = float(limit)
    return np.clip(action, -lim, lim).astype(np.float32)


def policy_rate_context(context, action_repeat: int):
    """``context`` for a base controller that acts once every ``action_repeat`` board samples
    and whose action the board holds (residual ``base_rate`` ``"policy"``): ``dt`` the policy
    period (s, ``action_repeat`` x the board's sample period ``context.board_dt``),
    ``policy_rate_hz`` = 1 / dt, ``sample_dt`` the board's period, ``board_mode`` ``"zoh"``;
    the context a two-rate host at that rate gives it (``experiment/two_rate.py``)."""
    sample_dt = context.board_dt
    dt = sample_dt * int(action_repeat)
    return dataclasses.replace(context, dt=dt, policy_rate_hz=1.0 / dt, sample_dt=sample_dt, board_mode="zoh")
