"""Savitzky-Golay weights from the discrete orthogonal (Gram) polynomials, in closed form.

A Savitzky-Golay output is the least-squares polynomial of ``degree`` through a window of
``window = 2 h + 1`` equally spaced samples, differentiated ``deriv`` times and evaluated at one
position ``x`` of the window (sample offsets ``j = -h .. h`` from its centre). Written in the
window's orthogonal polynomials, the least-squares projection needs no linear algebra:

    weight(x, j) = sum_k P_k^(deriv)(x) P_k(j) / ||P_k||^2,   k = 0 .. degree,

where ``P_k`` are the monic Gram polynomials of the grid ``-h .. h`` (Gram 1883; Hildebrand,
*Introduction to Numerical Analysis*, 2nd ed., section 7.13):
``P_0 = 1``, ``P_1 = j``, ``P_{k+1}(j) = j P_k(j) - beta_k P_{k-1}(j)`` with
``beta_k = k^2 (N^2 - k^2) / (4 (4 k^2 - 1))``, ``N = 2 h + 1``, and ``||P_k||^2 = beta_k ||P_{k-1}||^2``,
``||P_0||^2 = N``. The derivatives follow from the same recurrence,
``P_{k+1}^(m) = m P_k^(m-1) + j P_k^(m) - beta_k P_{k-1}^(m)``.

Every number is made by element-wise float64 operations (no BLAS, no LAPACK), so the weights are
the same bits on every CPU and BLAS kernel, and they are accurate to a few units in the last place
for any window (``scipy.signal.savgol_coeffs`` solves a Vandermonde least-squares problem with the
machine's LAPACK: about 1e-8 relative for a quintic over 201 samples, and worse for longer windows).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


def _gram_values(points: np.ndarray, n: int, degree: int, deriv: int) -> list[np.ndarray]:
    """``P_k^(deriv)(points)`` for ``k = 0 .. degree`` on the grid of ``n`` samples (list of arrays)."""
    points = np.asarray(points, dtype=float)
    # table[m][k]: the m-th derivative of P_k at the points
    table = [[np.zeros_like(points) for _ in range(degree + 1)] for _ in range(deriv + 1)]
    table[0][0] = np.ones_like(points)
    for k in range(degree):
        beta = _beta(k, n)
        for m in range(deriv + 1):
            nxt = points * table[m][k]
            if m:
                nxt = nxt + m * table[m - 1][k]
            if k:
                nxt = nxt - beta * table[m][k - 1]
            table[m][k + 1] = nxt
    return table[deriv]


def _beta(k: int, n: int) -> float:
    """Recurrence coefficient ``beta_k`` of the monic Gram polynomials on ``n`` points (``beta_0 = 0``)."""
    return 0.0 if k == 0 else k * k * (n * n - k * k) / (4.0 * (4.0 * k * k - 1.0))


def _norms(n: int, degree: int) -> list[float]:
    """``||P_k||^2 = sum_j P_k(j)^2`` over the grid, ``k = 0 .. degree``."""
    out = [float(n)]
    for k in range(1, degree + 1):
        out.append(out[-1] * _beta(k, n))
    return out


def weights(window: int, degree: int, deriv: int, positions) -> np.ndarray:
    """Least-squares weights, one row per position (sample offset from the window's centre, a float):
    ``row @ x[window]`` is the fitted polynomial's ``deriv``-th derivative (per sample) at that position."""
    if window % 2 != 1 or window < 1 or not 0 <= degree < window or deriv < 0:
        raise ValueError(f"Savitzky-Golay weights: window {window} must be odd and > degree {degree} >= 0, "
                         f"deriv {deriv} >= 0")
    h = window // 2
    grid = np.arange(-h, h + 1, dtype=float)
    at = np.asarray(positions, dtype=float)
    p_grid = _gram_values(grid, window, degree, 0)
    p_at = _gram_values(at, window, degree, deriv)
    norms = _norms(window, degree)
    out = np.zeros((at.size, window))
    for k in range(degree + 1):
        out += (p_at[k][:, None] / norms[k]) * p_grid[k][None, :]
    return out


@lru_cache(maxsize=64)
def conv_taps(window: int, degree: int, deriv: int = 0) -> np.ndarray:
    """The centre output's weights ordered for ``np.convolve`` (``scipy.signal.savgol_coeffs``'s
    ``use='conv'`` convention, delta 1), read-only."""
    taps = weights(window, degree, deriv, [0.0])[0][::-1].copy()
    taps.flags.writeable = False
    return taps
