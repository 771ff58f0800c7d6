"""Paired scoring against the oracle: the control error, its interval, tests between entries.

Every controller meets the same scenarios and, scenario by scenario, the same sensor noise
(``runner.cycle_seed``). The oracle (truth-based tracking) on that scenario sets the floor:
what the estimator returns when the stroke is retraced as well as the truth allows. So per
scenario ``s``::

    c_s = e_entry,s - e_oracle,s          (e: relative lambda66 error, the method as written)

is the part of the error that the controller adds. Errors common to both (the current
sensor's gain error, an off data-sheet ``k_t`` acting on the same work, a hidden effect
that biases every estimate) cancel. A failed episode has ``c = inf``; a scenario where the
oracle failed has no pair and is counted (``oracle_failed``), never silently dropped.

Statistics (scenarios are the resampling unit, fixed seed, percentile intervals of
:func:`scipy.stats.bootstrap`, paired resampling for differences; :mod:`.statistics`):

* ``median |c|`` with a 95 % paired bootstrap interval;
* between two entries A and B on their common scenarios: ``d_s = |c_A,s| - |c_B,s|``
  (both failed: 0), the median of ``d`` with its bootstrap interval and the two-sided
  Wilcoxon signed-rank p-value. "Clearly" different means the interval excludes zero.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from addedinertia_env.bench.statistics import clearly as clearly  # one rule for both scores
from addedinertia_env.bench.statistics import median, median_ci, paired_median_difference

ORACLE = "oracle"


def scenario_key(row: dict[str, Any]) -> tuple[str, str, int]:
    """What makes two rows the same scenario: ``(suite, split, seed)``."""
    return (str(row["suite"]), str(row.get("split", "?")), int(row["seed"]))


def signed_error(row: dict[str, Any]) -> float:
    """The row's relative error; ``inf`` for a failure."""
    return float(row["rel_error"]) if row.get("rel_error") is not None else math.inf


def control_errors(rows: list[dict], oracle_rows: list[dict]) -> dict[tuple, float]:
    """``{scenario: |e_entry - e_oracle|}`` over the scenarios both ran and the oracle solved
    (``inf`` where the entry failed)."""
    oracle = {scenario_key(r): signed_error(r) for r in oracle_rows}
    out: dict[tuple, float] = {}
    for r in rows:
        k = scenario_key(r)
        if k in oracle and math.isfinite(oracle[k]):
            e = signed_error(r)
            out[k] = abs(e - oracle[k]) if math.isfinite(e) else math.inf
    return out


def summary(c: dict[tuple, float], n_boot: int = 2000, seed: int = 0) -> dict[str, Any]:
    """Median ``|c|``, its paired bootstrap interval and the number of pairs."""
    x = np.array(list(c.values()), float)
    lo, hi = median_ci(x, n_boot=n_boot, seed=seed)
    return {"median_abs_control_error": median(x), "ci95_control_error": [lo, hi], "n_paired": int(len(x))}


def difference(c_a: dict[tuple, float], c_b: dict[tuple, float], n_boot: int = 2000,
               seed: int = 0) -> dict[str, Any]:
    """Paired comparison of A and B on their common scenarios (module doc): ``d = |c_A| - |c_B|``."""
    keys = sorted(set(c_a) & set(c_b))
    a = np.array([c_a[k] for k in keys], float)
    b = np.array([c_b[k] for k in keys], float)
    both = ~np.isfinite(a) & ~np.isfinite(b)
    with np.errstate(invalid="ignore"):
        d = np.where(both, 0.0, a - b)
    mid, (lo, hi) = paired_median_difference(a, b, n_boot=n_boot, seed=seed)
    return {"median": mid, "ci95": [lo, hi], "n": int(len(d)), "p_wilcoxon": wilcoxon_p(d)}


def wilcoxon_p(d: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p-value of paired differences ``d`` (``inf`` allowed:
    ranked above every finite value); 1.0 when every difference is zero, nan with < 2 pairs."""
    d = np.asarray(d, float)
    if len(d) < 2:
        return math.nan
    finite = d[np.isfinite(d)]
    big = (np.max(np.abs(finite)) if len(finite) else 1.0) * 10.0 + 1.0
    d = np.where(np.isfinite(d), d, np.sign(d) * big)
    if not np.any(d != 0):
        return 1.0
    from scipy.stats import wilcoxon  # noqa: PLC0415

    return float(wilcoxon(d, zero_method="zsplit").pvalue)
