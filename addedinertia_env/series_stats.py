"""Order statistics of sample series (numpy), shared by the plausibility check and the identification."""

from __future__ import annotations

import numpy as np


def median(x: np.ndarray) -> float:
    """``np.median`` of a non-empty 1-D float array, the same number, by sorting (numpy's vectorised
    sort beats its partition on these sizes, and a compiled selection on quantised data): nan when
    ``x`` holds a nan (they sort last)."""
    s = np.sort(x)
    if np.isnan(s[-1]):
        return float("nan")
    k = len(s) // 2
    return float(s[k]) if len(s) % 2 else float((s[k - 1] + s[k]) / 2.0)


def median_step(x: np.ndarray) -> float:
    """``np.median(np.diff(x))`` of a 1-D float array with at least two samples, the same number."""
    return median(x[1:] - x[:-1])
