"""Compiled pieces of the stroke fit (:func:`~.reference.fit_stroke`): numpy's Chebyshev code, element by element.

Each function does the same floating-point operations, in the same order, as the numpy
code its docstring names, so its numbers are those of numpy bit for bit (numba without
``fastmath``: no reassociation, no fused multiply-add); tests/test_stroke_law.py holds
them equal. The sums, the least-squares solve and the products of matrices stay in numpy
(their order of operations belongs to numpy and BLAS/LAPACK).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def clenshaw_one(c, k, x):  # pragma: no cover - compiled
    """The Chebyshev series of column ``k`` of ``c`` (terms x columns) at one ``x``: the Clenshaw
    recursion of ``numpy.polynomial.chebyshev.chebval`` for one point."""
    m = c.shape[0]
    if m == 1:
        return c[0, k] + 0 * x
    if m == 2:
        return c[0, k] + c[1, k] * x
    x2 = 2 * x
    c0 = c[m - 2, k]
    c1 = c[m - 1, k]
    for i in range(3, m + 1):
        tmp = c0
        c0 = c[m - i, k] - c1
        c1 = tmp + c1 * x2
    return c0 + c1 * x


@njit(cache=True)
def chebyshev_rows(x, degree):  # pragma: no cover - compiled
    """The Chebyshev polynomials ``T_0 .. T_degree`` at ``x`` (1-D), rows x points, C-contiguous:
    the array ``v`` that ``numpy.polynomial.chebyshev.chebvander(x, degree)`` builds (and returns
    as the view ``moveaxis(v, 0, -1)``), the same numbers."""
    n = len(x)
    v = np.empty((degree + 1, n))
    for j in range(n):
        xj = x[j] + 0.0
        v[0, j] = xj * 0 + 1
        if degree > 0:
            x2 = 2 * xj
            v[1, j] = xj
            for i in range(2, degree + 1):
                v[i, j] = v[i - 1, j] * x2 - v[i - 2, j]
    return v


@njit(cache=True)
def chebyshev_series(coef, x):  # pragma: no cover - compiled
    """``numpy.polynomial.chebyshev.chebval(x, coef)`` for 1-D ``x`` and contiguous 1-D ``coef``."""
    c = coef.reshape(-1, 1)
    out = np.empty(len(x))
    for j in range(len(x)):
        out[j] = clenshaw_one(c, 0, x[j])
    return out


@njit(cache=True)
def squared_residuals(coef, x, y):  # pragma: no cover - compiled
    """``(chebval(x, coef) - y) ** 2`` element by element (``coef`` 1-D)."""
    c = coef.reshape(-1, 1)
    out = np.empty(len(x))
    for j in range(len(x)):
        d = clenshaw_one(c, 0, x[j]) - y[j]
        out[j] = d * d
    return out


@njit(cache=True)
def mapped_series(coef, x_new, a, b, t_stop):  # pragma: no cover - compiled
    """``chebval((2.0 * (a + 0.5 * (x_new + 1.0) * (t_stop - a)) - (a + b)) / (b - a), coef)``:
    a series on ``[a, b]`` (s) at the points ``x_new`` of ``[-1, 1]`` mapped onto ``[a, t_stop]``."""
    c = coef.reshape(-1, 1)
    span, mid, width = t_stop - a, a + b, b - a
    out = np.empty(len(x_new))
    for j in range(len(x_new)):
        x = (2.0 * (a + 0.5 * (x_new[j] + 1.0) * span) - mid) / width
        out[j] = clenshaw_one(c, 0, x)
    return out


@njit(cache=True, inline="always")
def _rate_at(c, t, a, b):  # pragma: no cover - compiled
    """``chebval((2.0 * t - (a + b)) / (b - a), d1) * (2.0 / (b - a))`` for one ``t`` (s), ``c`` the
    derivative series ``d1`` as one column: the rate (rad/s) of the law on ``[a, b]``."""
    return clenshaw_one(c, 0, (2.0 * t - (a + b)) / (b - a)) * (2.0 / (b - a))


@njit(cache=True)
def last_rate_zero(d1, tt, a, b):  # pragma: no cover - compiled
    """The last sign change of the rate on the grid ``tt`` (s): ``(k, rate[k], rate[k + 1])`` with
    ``k`` the largest index where ``signbit(rate[k]) != signbit(rate[k + 1])`` (the rate of the law
    on ``[a, b]`` whose derivative series is ``d1``, as :func:`rates_on_grid`), computed from the
    end backwards; ``k = -1`` when the sign never changes."""
    c = d1.reshape(-1, 1)
    n = len(tt)
    later = _rate_at(c, tt[n - 1], a, b)
    for k in range(n - 2, -1, -1):
        r = _rate_at(c, tt[k], a, b)
        if np.signbit(r) != np.signbit(later):
            return k, r, later
        later = r
    return -1, 0.0, 0.0


@njit(cache=True)
def rates_on_grid(d1, tt, a, b):  # pragma: no cover - compiled
    """``chebval((2.0 * tt - (a + b)) / (b - a), d1) * (2.0 / (b - a))``, rad/s: the rate at the
    times ``tt`` (s) of the law on ``[a, b]`` whose derivative series is ``d1``."""
    c = d1.reshape(-1, 1)
    out = np.empty(len(tt))
    for j in range(len(tt)):
        out[j] = _rate_at(c, tt[j], a, b)
    return out
