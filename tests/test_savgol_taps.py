"""Savitzky-Golay weights from the Gram polynomials against the exact rational least squares."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from addedinertia_env.identify.common import savgol
from addedinertia_env.identify.savgol_taps import conv_taps, weights


def exact_weights(window: int, degree: int, deriv: int, x: int) -> np.ndarray:
    """The least-squares polynomial's ``deriv``-th derivative at offset ``x``, as weights on the window's
    samples, from the normal equations solved in rational arithmetic (then rounded once)."""
    h = window // 2
    js = range(-h, h + 1)
    n = degree + 1
    gram = [[Fraction(sum(j ** (p + q) for j in js)) for q in range(n)] + [Fraction(int(r == p)) for r in range(n)]
            for p in range(n)]
    for c in range(n):  # Gauss-Jordan on [A | I]: exact
        gram[c] = [v / gram[c][c] for v in gram[c]]
        for r in range(n):
            if r != c and gram[r][c]:
                f = gram[r][c]
                gram[r] = [a - f * b for a, b in zip(gram[r], gram[c])]
    inverse = [row[n:] for row in gram]
    d = [Fraction(math.prod(range(p - deriv + 1, p + 1))) * Fraction(x) ** (p - deriv) if p >= deriv else Fraction(0)
         for p in range(n)]
    g = [sum(d[p] * inverse[p][q] for p in range(n)) for q in range(n)]
    return np.array([float(sum(g[q] * Fraction(j) ** q for q in range(n))) for j in js])


@pytest.mark.parametrize("window, degree, deriv", [(201, 5, 0), (201, 3, 1), (101, 3, 2), (21, 5, 0), (7, 3, 1),
                                                   (401, 5, 0)])
def test_taps_are_the_exact_least_squares_to_rounding(window, degree, deriv):
    exact = exact_weights(window, degree, deriv, 0)[::-1]
    scale = np.max(np.abs(exact))
    assert np.max(np.abs(conv_taps(window, degree, deriv) - exact)) < 1e-14 * scale


@pytest.mark.parametrize("x", [-10, -3, 0, 7, 10])
def test_edge_weights_are_exact_to_rounding(x):
    exact = exact_weights(21, 5, 1, x)
    assert np.max(np.abs(weights(21, 5, 1, [float(x)])[0] - exact)) < 1e-14 * np.max(np.abs(exact))


def test_a_long_window_keeps_a_polynomial():
    # 0.2 s at 10 kHz: a quintic over 2001 samples reproduces any quintic (scipy's taps do not: 100 % off)
    n, window = 5000, 2001
    s = np.linspace(-1.0, 1.0, n)
    x = 0.3 + 0.2 * s - 0.5 * s**3 + 0.1 * s**5
    np.testing.assert_allclose(savgol(x, window, 5), x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(savgol(x, window, 5, deriv=1, delta=s[1] - s[0]), 0.2 - 1.5 * s**2 + 0.5 * s**4,
                               rtol=0, atol=1e-8)
