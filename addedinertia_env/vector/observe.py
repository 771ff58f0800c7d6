"""The task's observation for many environments at once (:meth:`ReverseStrokeTask.observe` on arrays).

Same fields, order, scales, clipping and float32 cast as the single task; the values are
computed with the same operations on per-slot arrays of an
:class:`~addedinertia_env.vector.pool.ExperimentPool`.
"""

from __future__ import annotations

import numpy as np

from ..task import LOOKAHEAD_S, OBS_LIMIT, OBSERVATION_FIELDS
from .pool import ENDED, HOLD, ExperimentPool

_SCALES = np.array([scale for _, scale in OBSERVATION_FIELDS.values()])[:, None]


def observe(pool: ExperimentPool, slots: np.ndarray) -> np.ndarray:
    """Observations (len(slots), 22) float32 of the slots' newest samples."""
    pool.refresh_rates(slots)
    t = pool.t[slots]
    refs = pool.refs
    phi_ref, rate_ref, acc_ref = refs.phi_rate_accel(t, slots)
    ahead = [refs.phi(t + h, slots) for h in LOOKAHEAD_S]
    stage = pool.stage[slots]
    hold = stage == HOLD
    t_begin, t_end, duration = refs.t_begin[slots], refs.t_end[slots], refs.duration[slots]
    rate_ref = np.where(hold, 0.0, rate_ref)
    acc_ref = np.where(hold, 0.0, acc_ref)
    to_end = np.where(hold, np.maximum(0.0, t_begin - t), np.maximum(0.0, t_end - t))
    progress = np.where(hold, 1.0 - to_end / np.maximum(pool.hold_s[slots], 1e-9), (t - t_begin) / duration)
    phi, phi_n = pool.phi[slots], pool.phi_n[slots]
    hull_rate = pool.hull_rate[slots]
    values = np.stack([
        phi_ref - phi,
        rate_ref - hull_rate,
        phi_ref - phi_n,
        rate_ref,
        acc_ref,
        ahead[0] - phi_ref,
        ahead[1] - phi_ref,
        ahead[2] - phi_ref,
        phi - phi_n,
        hull_rate,
        pool.fly_rate[slots],
        pool.i[slots],
        hold.astype(float),
        ((stage != HOLD) & (stage != ENDED)).astype(float),
        np.minimum(np.maximum(progress, 0.0), 1.0),
        pool.energy[slots],
        to_end,
        pool.inertia_prior[slots],
        duration,
        pool.c_known[slots],
        pool.k_t_known[slots],
        pool.J_f_known[slots],
    ])
    obs = values / _SCALES
    return np.clip(obs, -OBS_LIMIT, OBS_LIMIT).astype(np.float32).T
