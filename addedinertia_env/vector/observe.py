"""The task's observation for many environments at once (:meth:`ReverseStrokeTask.observe` on arrays).

Same fields, order, scales, clipping and float32 cast as the single task; the values are
computed with the same operations on per-slot arrays of an
:class:`~addedinertia_env.vector.pool.ExperimentPool`, one slot after another in one
compiled loop (:func:`observation_rows`; numpy's ``maximum``/``minimum``/``clip`` rules
for NaN and for equal arguments, so the numbers are those of the numpy expressions it
replaced, bit for bit).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from addedinertia_env.experiment.task import LOOKAHEAD_S, OBS_LIMIT, OBSERVATION_FIELDS
from addedinertia_env.vector.pool import ENDED, HOLD, ExperimentPool
from addedinertia_env.vector.reference import reference_one

_SCALES = np.array([scale for _, scale in OBSERVATION_FIELDS.values()])
_LOOKAHEAD = np.array(LOOKAHEAD_S)
if len(_LOOKAHEAD) != 3 or len(_SCALES) != 22:
    raise ImportError("vector/observe.py writes 22 fields with three look-ahead times; task.py's layout changed")


@njit(cache=True, inline="always")
def _maximum(a, b):  # pragma: no cover - compiled
    """``np.maximum(a, b)`` of two floats: NaN if either is, else ``a if a > b else b``."""
    if a != a:
        return a
    return a if a > b else b


@njit(cache=True, inline="always")
def _minimum(a, b):  # pragma: no cover - compiled
    """``np.minimum(a, b)`` of two floats: NaN if either is, else ``a if a < b else b``."""
    if a != a:
        return a
    return a if a < b else b


@njit(cache=True)
def observation_rows(slots, t_now, stage, coef, d1, d2, t_start, t_stop, t_begin, t_end, duration, hold_s,
                     phi, phi_n, hull_rate, fly_rate, current, energy, inertia_prior, c_known, k_t_known,
                     J_f_known, lookahead, scales, limit, out):  # pragma: no cover - compiled
    """The observation (the 22 fields of ``task.OBSERVATION_FIELDS``, divided by ``scales``, clipped
    to +-``limit``, float32) of slot ``slots[j]`` into ``out[j]``, from the pool's per-slot arrays
    (s, rad, rad/s, A, J, kg m^2, N m/A) and the slots' references (:func:`~.reference.reference_one`)."""
    for j in range(len(slots)):
        k = slots[j]
        t = t_now[k]
        phi_ref, rate_ref, acc_ref = reference_one(t, k, coef, d1, d2, t_start, t_stop, t_begin, t_end, True)
        a1 = reference_one(t + lookahead[0], k, coef, d1, d2, t_start, t_stop, t_begin, t_end, False)[0]
        a2 = reference_one(t + lookahead[1], k, coef, d1, d2, t_start, t_stop, t_begin, t_end, False)[0]
        a3 = reference_one(t + lookahead[2], k, coef, d1, d2, t_start, t_stop, t_begin, t_end, False)[0]
        hold = stage[k] == HOLD
        if hold:  # the hull is braked: the reference is the stroke's start, and nothing moves yet
            rate_ref = 0.0
            acc_ref = 0.0
            to_end = _maximum(0.0, t_begin[k] - t)
            progress = 1.0 - to_end / _maximum(hold_s[k], 1e-9)
        else:
            to_end = _maximum(0.0, t_end[k] - t)
            progress = (t - t_begin[k]) / duration[k]
        moving = 1.0 if stage[k] != HOLD and stage[k] != ENDED else 0.0
        values = (phi_ref - phi[k], rate_ref - hull_rate[k], phi_ref - phi_n[k], rate_ref, acc_ref,
                  a1 - phi_ref, a2 - phi_ref, a3 - phi_ref, phi[k] - phi_n[k], hull_rate[k], fly_rate[k],
                  current[k], 1.0 if hold else 0.0, moving, _minimum(_maximum(progress, 0.0), 1.0), energy[k],
                  to_end, inertia_prior[k], duration[k], c_known[k], k_t_known[k], J_f_known[k])
        f = 0
        for v in values:
            out[j, f] = np.float32(_minimum(_maximum(v / scales[f], -limit), limit))
            f += 1


def observe(pool: ExperimentPool, slots: np.ndarray) -> np.ndarray:
    """Observations (len(slots), 22) float32 of the slots' newest samples."""
    pool.refresh_rates(slots)
    refs = pool.refs
    slots = np.asarray(slots, dtype=np.int64)
    out = np.empty((len(slots), len(_SCALES)), dtype=np.float32)
    observation_rows(slots, pool.t, pool.stage, refs.coef, refs.d1, refs.d2, refs.t_start, refs.t_stop, refs.t_begin,
                     refs.t_end, refs.duration, pool.hold_s, pool.phi, pool.phi_n, pool.hull_rate, pool.fly_rate,
                     pool.i, pool.energy, pool.inertia_prior, pool.c_known, pool.k_t_known, pool.J_f_known,
                     _LOOKAHEAD, _SCALES, OBS_LIMIT, out)
    return out
