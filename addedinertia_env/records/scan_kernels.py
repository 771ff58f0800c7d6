"""Compiled scans of a record's sample series (numba): phase blocks and the plausibility check's passes.

Each kernel does in one pass what a few numpy calls did, with the same IEEE operations on each
element in the same order, so every number is bit for bit the numpy expression its docstring
names (``tests/test_scan_kernels.py`` holds each one to it). Compiled as the kernels of
:mod:`addedinertia_env.identify.series_kernels`: ``cache=True``, no ``fastmath``, ``error_model="numpy"``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def _run_starts(codes):
    """First row of each run of equal rows of a 2-D array (rows compared element by element)."""
    n, w = codes.shape
    out = np.empty(n, dtype=np.int64)
    c = 0
    if n:
        out[0] = 0
        c = 1
    for k in range(1, n):
        d = codes[k, 0] ^ codes[k - 1, 0]
        for j in range(1, w):
            d |= codes[k, j] ^ codes[k - 1, j]
        if d != 0:
            out[c] = k
            c += 1
    return out[:c]


def block_starts(labels) -> np.ndarray:
    """First sample of each contiguous block of equal labels (a record's ``phase``): the indices
    ``concatenate([[0], nonzero(labels[1:] != labels[:-1])[0] + 1])`` (empty for no samples).

    A fixed-width str array (numpy ``<U``) is compared as its code units, which is numpy's string
    equality; any other array by numpy's ``!=``."""
    labels = np.asarray(labels)
    if not len(labels):
        return np.zeros(0, dtype=np.int64)
    if labels.ndim == 1 and labels.dtype.kind == "U" and labels.dtype.itemsize > 0:
        codes = np.ascontiguousarray(labels).view(np.uint32).reshape(len(labels), -1)
        return _run_starts(codes)
    return np.concatenate([[0], np.nonzero(labels[1:] != labels[:-1])[0] + 1]).astype(np.int64)


@njit(cache=True, error_model="numpy")
def value_change_starts(x):
    """Samples ``k >= 1`` where a float series changes, nan to nan not counted: ``nonzero((x[1:] !=
    x[:-1]) & ~(isnan(x[1:]) & isnan(x[:-1])))[0] + 1``."""
    n = len(x)
    out = np.empty(max(n - 1, 0), dtype=np.int64)
    c = 0
    for k in range(1, n):
        if x[k] != x[k - 1] and not (np.isnan(x[k]) and np.isnan(x[k - 1])):
            out[c] = k
            c += 1
    return out[:c]


@njit(cache=True, error_model="numpy")
def _all_equal_bits(bits):
    """Whether every element of a 1-D int64 array equals the first (True for none)."""
    for k in range(1, len(bits)):
        if bits[k] != bits[0]:
            return False
    return True


def bitwise_constant(x: np.ndarray) -> bool:
    """Whether every element of a 1-D float64 array has the bits of the first (``-0.0`` differs from
    ``0.0``, a nan equals only a nan of the same bits): ``np.all(x.view(np.int64) == x.view(np.int64)[0])``,
    stopping at the first difference. True for no elements."""
    return bool(_all_equal_bits(x.view(np.int64)))


@njit(cache=True, error_model="numpy")
def first_beyond(x, limit):
    """The first ``k`` with ``abs(x[k]) > limit`` (``argmax(np.abs(x) > limit)``; nan is not beyond), or -1."""
    for k in range(len(x)):
        if abs(x[k]) > limit:
            return k
    return -1


@njit(cache=True, error_model="numpy")
def abs_max(x, center):
    """``np.max(np.abs(x - center))`` of a non-empty 1-D series (nan when any element gives nan)."""
    top = abs(x[0] - center)
    if np.isnan(top):
        return np.nan
    for k in range(1, len(x)):
        v = abs(x[k] - center)
        if np.isnan(v):
            return np.nan
        if v > top:
            top = v
    return top


@njit(cache=True, error_model="numpy")
def second_differences(x):
    """``np.diff(x, 2)`` of a 1-D series of at least two samples: ``(x[k+2] - x[k+1]) - (x[k+1] - x[k])``."""
    n = len(x)
    out = np.empty(n - 2)
    for k in range(n - 2):
        out[k] = (x[k + 2] - x[k + 1]) - (x[k + 1] - x[k])
    return out


@njit(cache=True, error_model="numpy")
def _kth_deviation(s, m, p, k):
    """The ``k``-th smallest (from 0) of ``abs(s - m)`` for an ascending ``s`` whose first ``p`` elements are
    below ``m``: the deviations of ``s[p - 1], s[p - 2], ...`` rise, as do those of ``s[p], s[p + 1], ...``;
    a binary search for how many of the ``k + 1`` smallest come from the first run."""
    lo, hi = max(0, k + 1 - (len(s) - p)), min(k + 1, p)
    while lo < hi:
        i = (lo + hi) // 2
        if abs(s[p - 1 - i] - m) < abs(s[p + k - i] - m):  # the first run's next beats the second's last
            lo = i + 1
        else:
            hi = i
    a = abs(s[p - lo] - m) if lo > 0 else -np.inf
    b = abs(s[p + k - lo] - m) if k + 1 - lo > 0 else -np.inf
    return a if a > b else b


@njit(cache=True, error_model="numpy")
def median_abs_deviation_sorted(s, m):
    """``np.median(np.abs(s - m))`` for a non-empty ascending ``s`` without nan and a finite ``m``, without a
    second sort: ``abs(s - m)`` falls towards the first ``s >= m`` and rises after it (rounding is
    monotonic), so its order statistics are found in those two sorted runs (the same elements, so the
    same number; an even count averages the middle two as ``(a + b) / 2.0``)."""
    n = len(s)
    p = np.searchsorted(s, m)
    k = n // 2
    if n % 2:
        return _kth_deviation(s, m, p, k)
    return (_kth_deviation(s, m, p, k - 1) + _kth_deviation(s, m, p, k)) / 2.0


@njit(cache=True, error_model="numpy")
def abs_rates(x, dt):
    """``np.abs(np.diff(x) / dt)``: the magnitude of each sample-to-sample rate (``dt``: the intervals)."""
    out = np.empty(len(x) - 1)
    for k in range(len(x) - 1):
        out[k] = abs((x[k + 1] - x[k]) / dt[k])
    return out


@njit(cache=True, error_model="numpy")
def first_step_beyond(x, dt, rate, quant, noise, moving):
    """The first ``k`` whose step ``abs(x[k+1] - x[k])`` exceeds ``rate * dt[k] + quant + noise`` (added in
    that order), among the ``k`` with ``moving[k]`` (every ``k`` when ``moving`` is empty), or -1:
    ``argmax((np.abs(np.diff(x)) > rate * dt + quant + noise) & moving)``."""
    use_mask = len(moving) > 0
    for k in range(len(x) - 1):
        if use_mask and not moving[k]:
            continue
        if abs(x[k + 1] - x[k]) > rate * dt[k] + quant + noise:
            return k
    return -1


@njit(cache=True, error_model="numpy")
def true_counts(mask):
    """How many of ``mask[:k]`` are true, for ``k = 0 .. len``: ``concatenate([[0], cumsum(mask)])`` (int64)."""
    out = np.empty(len(mask) + 1, dtype=np.int64)
    out[0] = 0
    for k in range(len(mask)):
        out[k + 1] = out[k] + (1 if mask[k] else 0)
    return out


@njit(cache=True, error_model="numpy")
def gap_counts(t, longest):
    """How many sample intervals before sample ``k`` exceed ``longest`` (s), for every sample:
    ``concatenate([[0], cumsum(np.diff(t) > longest)])`` (int64)."""
    out = np.empty(max(len(t), 1), dtype=np.int64)
    out[0] = 0
    for k in range(len(t) - 1):
        out[k + 1] = out[k] + (1 if t[k + 1] - t[k] > longest else 0)
    return out


@njit(cache=True, error_model="numpy")
def squared_step_sums(x):
    """Sum of the squared steps of ``x`` before each sample: ``concatenate([[0.0], cumsum(np.diff(x)**2)])``
    (a sequential sum, as ``np.cumsum``)."""
    n = len(x)
    out = np.empty(max(n, 1))
    out[0] = 0.0
    for k in range(n - 1):
        d = x[k + 1] - x[k]
        out[k + 1] = d * d if k == 0 else out[k] + d * d
    return out


@njit(cache=True, error_model="numpy")
def numpy_sign(x):
    """``np.sign`` of a float: 1, -1, 0 for either zero, nan for nan."""
    if x > 0:
        return 1.0
    if x < 0:
        return -1.0
    if x == 0:
        return 0.0
    return x


@njit(cache=True, error_model="numpy")
def reaction_work(t, i_mean, scale, phi_s, psi_s, k_t, f_visc, f_coul, w_s):
    """Cumulative work of the motor's reaction on the hull from the first sample, J (``energy``'s
    ``_cumulative_work``, form ``reaction``): per interval ``k`` with ``omega = (psi_s[k+1] - psi_s[k]) /
    (t[k+1] - t[k])``, ``-(k_t (scale i_mean[k]) - (f_visc omega + f_coul tanh(omega / w_s))) (phi_s[k+1] -
    phi_s[k])`` (the rotor's dry friction smoothed over the rate ``w_s``, rad/s: identify/rotor_friction.py), summed as ``concatenate([[0.0], cumsum(steps)])``."""
    n = len(t)
    out = np.empty(max(n, 1))
    out[0] = 0.0
    for k in range(n - 1):
        omega = (psi_s[k + 1] - psi_s[k]) / (t[k + 1] - t[k])
        torque = k_t * (scale * i_mean[k]) - (f_visc * omega + f_coul * np.tanh(omega / w_s))
        step = -torque * (phi_s[k + 1] - phi_s[k])
        out[k + 1] = step if k == 0 else out[k] + step
    return out


@njit(cache=True, error_model="numpy")
def negative_step_ratios(t, tau):
    """``-np.diff(t) / tau``: each sample interval over a time constant, negated."""
    out = np.empty(max(len(t) - 1, 0))
    for k in range(len(t) - 1):
        out[k] = -(t[k + 1] - t[k]) / tau
    return out


@njit(cache=True, error_model="numpy")
def relaxed_interval_means(t, i, decay, tau):
    """Mean of an exponentially relaxing current over each sample interval (``energy_work.interval_mean_current``,
    ``instant`` sampling): with ``h = t[k+1] - t[k]``, ``a = decay[k]`` (``exp(-h / tau)``),
    ``i_ss = (i[k+1] - a i[k]) / (1 - a)``, the mean ``i_ss + (i[k] - i[k+1]) tau / h``."""
    out = np.empty(max(len(t) - 1, 0))
    for k in range(len(t) - 1):
        a = decay[k]
        i_ss = (i[k + 1] - a * i[k]) / (1.0 - a)
        out[k] = i_ss + (i[k] - i[k + 1]) * tau / (t[k + 1] - t[k])
    return out


def warm_up() -> None:
    """Load every kernel's machine code now (from the cache, or compiled once)."""
    x = np.arange(8.0)
    block_starts(np.array(["a", "a", "b"]))
    value_change_starts(x)
    first_beyond(x, 1.0)
    bitwise_constant(x)
    abs_max(x, 0.5)
    median_abs_deviation_sorted(second_differences(x), 0.0)
    first_step_beyond(x, abs_rates(x, np.ones(7)), 1.0, 0.0, 0.0, np.zeros(0, dtype=np.bool_))
    true_counts(x > 2.0)
    gap_counts(x, 1.5)
    squared_step_sums(x)
    decay = np.exp(negative_step_ratios(x, 2.0))
    reaction_work(x, relaxed_interval_means(x, x, decay, 2.0), 1.0, x, x, 1.0, 0.1, 0.01, 0.01)
