"""Compiled per-angle columns of the energy balance (numba): lambda66, the rejection tests and the
uncertainty parts of every boundary angle in one pass each.

They are :meth:`~addedinertia_env.identify.energy_balance.RunBalance.interval_columns`' numpy expressions
element by element, the same IEEE operations in the same order (``x**2`` of an array is ``x * x``;
``hypot`` and ``sqrt`` are the C library's, as numpy's), so every number is bit for bit numpy's
(``tests/test_energy_vectorised.py`` holds them to it). Compiled as the other kernels: ``cache=True``,
no ``fastmath``, ``error_model="numpy"``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def _at_least(x, floor):
    """``np.maximum(x, floor)`` of a float: nan stays nan."""
    return x if (x >= floor or np.isnan(x)) else floor


@njit(cache=True, error_model="numpy")
def angle_values(spring, A_f, A_r, B_f, B_r, K1, K2, K3, K4, hull_rest, dW, w1f, w1r, J_h,
                 sat_count, n_saturated, k3, k4s):
    """Per angle: ``lambda66`` (``energy_balance.inertia_from_terms``), the fraction of samples ``k3..k4`` with the
    current at its limit (from the cumulative count ``sat_count`` of ``n_saturated`` samples; zeros when
    ``sat_count`` is empty) and the reverse-forward speed mismatch ``||w1r| - |w1f|| / max(|w1f|, 1e-12)``.
    Returns ``(lam, sat, mismatch)``."""
    n = len(w1f)
    lam, sat, mismatch = np.empty(n), np.empty(n), np.empty(n)
    last = len(sat_count) - 1
    for j in range(n):
        numerator = (spring[j] + (A_r[j] + B_r[j]) - (A_f[j] + B_f[j]) + K2[j] + K3[j] - K1[j] - K4[j]
                     + hull_rest[j] - dW[j])
        lam[j] = numerator / (0.5 * (w1f[j] * w1f[j] + w1r[j] * w1r[j])) - J_h
        if last >= 0:
            hi = k4s[j] + 1
            sat[j] = (sat_count[min(hi, last)] - sat_count[k3]) / (min(hi, n_saturated) - k3)
        else:
            sat[j] = 0.0
        mismatch[j] = abs(abs(w1r[j]) - abs(w1f[j])) / _at_least(abs(w1f[j]), 1e-12)
    return lam, sat, mismatch


@njit(cache=True, error_model="numpy")
def angle_uncertainties(lam, A_f, A_r, w1f, w1r, sigma_f, sigma_r, s_dW, k1s, k4s, k2, k3, dsq_cum, work_noise,
                        gain_u, J_h):
    """Per angle, kg m^2: ``s_independent``, ``s_common``, ``sigma`` and ``s_current`` of
    ``interval_columns``: the motor work's noise ``work_noise sqrt(max(dsq(k1..k2), 0) / 2)`` and
    ``... (k3..k4)`` (``dsq_cum``: the cumulative squared angle steps), the rates' sigmas ``sigma_f``,
    ``sigma_r``, the gain part ``gain_u hypot(A_f, A_r)`` and the dissipation model's ``s_dW``, each over the
    kinetic denominator. Returns ``(s_independent, s_common, sigma, s_current)``."""
    n = len(w1f)
    s_independent, s_common, sigma, s_current = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    last = len(dsq_cum) - 1
    for j in range(n):
        denom = 0.5 * (w1f[j] * w1f[j] + w1r[j] * w1r[j])
        J_total = lam[j] + J_h
        s_f = work_noise * np.sqrt(_at_least(dsq_cum[min(k2, last)] - dsq_cum[min(k1s[j], last)], 0.0) / 2.0)
        s_r = work_noise * np.sqrt(_at_least(dsq_cum[min(k4s[j], last)] - dsq_cum[min(k3, last)], 0.0) / 2.0)
        s_den = np.hypot(w1f[j] * sigma_f[j], w1r[j] * sigma_r[j])
        s_current[j] = np.hypot(s_f, s_r) / denom
        s_independent[j] = np.hypot(s_current[j], J_total * s_den / denom)
        s_common[j] = np.hypot(gain_u * np.hypot(A_f[j], A_r[j]), s_dW[j]) / denom
        sigma[j] = np.hypot(s_independent[j], s_common[j])
    return s_independent, s_common, sigma, s_current


def warm_up() -> None:
    """Load both kernels' machine code now (from the cache, or compiled once)."""
    x, k = np.ones(3), np.arange(3, dtype=np.int64)
    lam, _, _ = angle_values(x, x, x, x, x, x, x, x, x, x, x, x, x, 1.0, k, 3, 0, k)
    angle_values(x, x, x, x, x, x, x, x, x, x, x, x, x, 1.0, np.zeros(0, dtype=np.int64), 0, 0, k)
    angle_uncertainties(lam, x, x, x, x, x, x, x, k, k, 2, 0, x, 1.0, 0.005, 1.0)
