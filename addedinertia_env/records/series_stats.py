"""Order statistics of sample series (numpy), shared by the plausibility check and the identification."""

from __future__ import annotations

import numpy as np


def median(x: np.ndarray) -> float:
    """``np.median`` of a non-empty 1-D float array, the same number, by sorting (numpy's vectorised
    sort beats its partition on these sizes, and a compiled selection on quantised data): nan when
    ``x`` holds a nan (they sort last)."""
    return sorted_median(np.sort(x))


def sorted_median(s: np.ndarray) -> float:
    """:func:`median` of a non-empty 1-D float array already sorted ascending (``np.sort``: nan last)."""
    if np.isnan(s[-1]):
        return float("nan")
    k = len(s) // 2
    return float(s[k]) if len(s) % 2 else float((s[k - 1] + s[k]) / 2.0)


def median_step(x: np.ndarray) -> float:
    """``np.median(np.diff(x))`` of a 1-D float array with at least two samples, the same number."""
    return median(x[1:] - x[:-1])


def quantile(x: np.ndarray, q: float) -> float:
    """``np.quantile(x, q)`` (method ``linear``) of a non-empty 1-D float array, the same number: the two
    order statistics around ``(n - 1) q`` (by a partial sort) blended as numpy's ``_lerp`` does (from
    below when the fraction is under 0.5, from above otherwise); nan when ``x`` holds a nan."""
    n = len(x)
    if np.isnan(x).any():
        return float("nan")
    v = (n - 1) * q
    if v >= n - 1:
        return float(np.max(x))
    if v < 0:
        return float(np.min(x))
    lo = int(np.floor(v))
    gamma = v - lo
    s = np.partition(x, [lo, lo + 1])  # s[lo], s[lo + 1]: the order statistics a full sort puts there
    a, b = float(s[lo]), float(s[lo + 1])
    d = b - a
    return b - d * (1 - gamma) if gamma >= 0.5 else a + d * gamma
