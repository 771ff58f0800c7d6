"""The leaderboard's statistics, from the libraries that define them: SciPy's bootstrap and rliable.

* intervals of a median and of a paired median difference: :func:`scipy.stats.bootstrap`
  (percentile method; ``paired=True`` resamples scenarios, keeping each scenario's pair
  together), ``n_boot`` resamples with a fixed seed;
* the score matrix: per controller, ``runs x scenarios`` of its score (the ranked statistic's
  per-episode error, lower is better; a failure is ``inf``), scenarios in one order for every
  controller (:func:`score_matrix`); ``bench leaderboard --format scores`` writes it
  (:func:`write_scores`) as an ``.npz`` that ``dict(np.load(path))`` turns into rliable's
  ``score_dict``, with a JSON sidecar naming the scenarios and the score;
* rliable (Agarwal et al. 2021, "Deep RL at the edge of the statistical precipice") on that
  matrix: the interquartile mean with its stratified-bootstrap interval, the probability of
  improvement of each entry over the best classical entry (with its interval), and
  performance profiles (the fraction of runs whose error exceeds each tau) as a figure.
  rliable assumes higher is better; its functions are given ``-error`` where the direction
  matters (probability of improvement), and the profile is drawn of the error itself.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable

import numpy as np

LEVEL = 0.95
RLIABLE_REPS = 2000  # stratified-bootstrap resamples for rliable's intervals (its default is 50,000)


def clearly(diff: dict[str, Any]) -> int:
    """Which side of zero a paired difference ``diff`` (``{"ci95": [lo, hi], ...}``) clearly lies:
    +1 when its interval lies above zero (the first entry clearly worse), -1 below, 0 when it
    includes zero. The rule of both :mod:`.paired` and :mod:`.score`."""
    lo, hi = diff["ci95"]
    if lo > 0:
        return 1
    if hi < 0:
        return -1
    return 0


def _median_axis(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Median along ``axis`` that tolerates +-inf (no inf - inf): the mean of the two middle order
    statistics, or the one value where they are equal."""
    s = np.sort(x, axis=axis)
    n = s.shape[axis]
    a = np.take(s, (n - 1) // 2, axis=axis)
    b = np.take(s, n // 2, axis=axis)
    with np.errstate(invalid="ignore"):
        return np.where(a == b, a, 0.5 * a + 0.5 * b)


def median(x) -> float:
    """:func:`_median_axis` of a 1-D sample (nan when empty)."""
    x = np.asarray(x, float)
    return float(_median_axis(x)) if x.size else math.nan


def median_ci(x, n_boot: int = 2000, seed: int = 0, level: float = LEVEL) -> tuple[float, float]:
    """Percentile bootstrap interval of the median of ``x`` (``inf`` entries allowed), by
    :func:`scipy.stats.bootstrap`; ``(nan, nan)`` when ``x`` is empty, the value itself when it has one entry."""
    from scipy.stats import bootstrap  # noqa: PLC0415

    x = np.asarray(x, float)
    if x.size == 0:
        return (math.nan, math.nan)
    if x.size == 1 or np.all(x == x[0]):
        return (float(x[0]), float(x[0]))
    with np.errstate(invalid="ignore"):  # the standard error of resamples holding inf (not used here)
        res = bootstrap((x,), _median_axis, n_resamples=n_boot, confidence_level=level, method="percentile",
                        rng=np.random.default_rng(seed), vectorized=True)
    ci = res.confidence_interval
    return (float(ci.low), float(ci.high))


def _difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` per scenario with two failures (inf, inf) counting as no difference."""
    both = ~np.isfinite(a) & ~np.isfinite(b) & (a == b)
    with np.errstate(invalid="ignore"):
        return np.where(both, 0.0, a - b)


def paired_median_difference(a, b, n_boot: int = 2000, seed: int = 0,
                             level: float = LEVEL) -> tuple[float, tuple[float, float]]:
    """Median of ``a - b`` over paired scenarios and its percentile interval by :func:`scipy.stats.bootstrap`
    with ``paired=True`` (each resample draws scenarios, both entries' values together)."""
    from scipy.stats import bootstrap  # noqa: PLC0415

    a, b = np.asarray(a, float), np.asarray(b, float)
    d = _difference(a, b)
    if d.size == 0:
        return math.nan, (math.nan, math.nan)
    if d.size == 1 or np.all(d == d[0]):
        return float(d[0]), (float(d[0]), float(d[0]))

    def statistic(x, y, axis=-1):
        return _median_axis(_difference(x, y), axis=axis)

    with np.errstate(invalid="ignore"):
        res = bootstrap((a, b), statistic, paired=True, n_resamples=n_boot, confidence_level=level,
                        method="percentile", rng=np.random.default_rng(seed), vectorized=True)
    ci = res.confidence_interval
    return median(d), (float(ci.low), float(ci.high))


# --- the score matrix and rliable ----------------------------------------------------------

def score_matrix(scores: dict[str, dict[Any, list[float]]]) -> tuple[list, dict[str, np.ndarray]]:
    """``(scenarios, {controller: runs x scenarios})`` from ``{controller: {scenario: [score per run]}}``:
    the scenarios every controller ran (sorted), and as many runs as every controller has on each of
    them (a controller's runs on a scenario in the order given). Scenarios not shared by all are left
    out (they cannot be compared)."""
    if not scores:
        return [], {}
    common = sorted(set.intersection(*(set(s) for s in scores.values())), key=_order)
    if not common:
        return [], {}
    runs = min(len(v[k]) for v in scores.values() for k in common)
    return common, {name: np.array([[float(v[k][r]) for k in common] for r in range(runs)], dtype=float)
                    for name, v in scores.items()}


def _order(key) -> tuple:
    """Sort key of a scenario key: its parts in turn, numbers by value before text."""
    parts = key if isinstance(key, tuple) else (key,)
    return tuple((0, float(x), "") if isinstance(x, (int, float)) else (1, 0.0, str(x)) for x in parts)


def write_scores(path: str | Path, scenarios: list, matrices: dict[str, np.ndarray], score: str) -> tuple[Path, Path]:
    """Write the score matrices as ``path`` (``.npz``: one ``runs x scenarios`` float array per controller,
    rliable's ``score_dict`` by ``dict(np.load(path))``) and ``path`` + ``.json`` (the scenarios in column
    order, what the score is, that lower is better and that ``inf`` is a failure). Atomic writes."""
    from addedinertia_env.foundation.atomic import atomic_target, atomic_write_text  # noqa: PLC0415

    path = Path(path)
    with atomic_target(path, suffix=".npz") as tmp:
        np.savez(tmp, **matrices)
    side = path.with_name(path.name + ".json")
    meta = {"format": "addedinertia-scores/1", "score": score, "lower_is_better": True,
            "failure": "inf (a failed run or identification)", "shape": "runs x scenarios",
            "scenarios": ["/".join(str(x) for x in s) if isinstance(s, tuple) else str(s) for s in scenarios],
            "controllers": {k: list(v.shape) for k, v in matrices.items()},
            "read_with": "score_dict = dict(numpy.load(path)); rliable.library.get_interval_estimates(score_dict, ...)"}
    atomic_write_text(side, json.dumps(meta, indent=1) + "\n")
    return path, side


def iqm_with_ci(matrices: dict[str, np.ndarray], reps: int = RLIABLE_REPS,
                seed: int = 0) -> dict[str, tuple[float, float, float]]:
    """rliable's interquartile mean of each matrix with its stratified-bootstrap interval
    (``{controller: (iqm, lo, hi)}``): runs resampled within each scenario and the scenarios resampled
    too (rliable's ``task_bootstrap``; with one run per scenario, as a bench has, the scenarios are
    the only unit to resample)."""
    from rliable import library as rly  # noqa: PLC0415
    from rliable import metrics  # noqa: PLC0415

    if not matrices:
        return {}
    finite = {k: v for k, v in matrices.items() if v.size}
    point, ci = _quiet(lambda: rly.get_interval_estimates(
        finite, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=reps, confidence_interval_size=LEVEL,
        task_bootstrap=True), seed)
    return {k: (float(point[k][0]), *(_unbounded(float(c), finite[k]) for c in ci[k][:, 0])) for k in finite}


def _unbounded(end: float, matrix: np.ndarray) -> float:
    """An interval end of a matrix holding failures (infinite errors): where enough resamples hold more
    failures than the IQM trims, their IQMs are infinite, and the percentile interpolated between two of
    them is nan (inf - inf); the end is then infinite (the interval unbounded above)."""
    return float("inf") if math.isnan(end) and np.isinf(matrix).any() else end


def improvement_over(matrices: dict[str, np.ndarray], reference: str, reps: int = RLIABLE_REPS,
                     seed: int = 0) -> dict[str, tuple[float, float, float]]:
    """rliable's probability of improvement ``P(error_entry < error_reference)`` of every other
    controller over ``reference`` (Mann-Whitney per scenario, averaged over scenarios), with its 95 %
    interval: ``{controller: (p, lo, hi)}``. With several runs per scenario the interval is rliable's
    (runs resampled within each scenario); with one run per scenario (a bench: one episode per
    scenario) there are no runs to resample, and the scenarios are resampled in pairs by
    :func:`scipy.stats.bootstrap` (``paired=True``) with rliable's statistic, which for one run per
    scenario is the mean over scenarios of ``1[x < y] + 0.5 1[x = y]`` (:func:`_one_run_improvement`,
    held equal to rliable's in tests)."""
    from rliable import library as rly  # noqa: PLC0415
    from rliable import metrics  # noqa: PLC0415
    from scipy.stats import bootstrap  # noqa: PLC0415

    if reference not in matrices:
        return {}
    ref = -_finite_order(matrices[reference], matrices)
    others = {k: -_finite_order(v, matrices) for k, v in matrices.items() if k != reference}
    if not others:
        return {}
    out = {}
    if ref.shape[0] == 1:
        for k, x in others.items():
            p = float(_quiet(lambda: metrics.probability_of_improvement(x, ref)))
            if np.all(x[0] == x[0, 0]) and np.all(ref[0] == ref[0, 0]) or x.shape[1] < 2:
                out[k] = (p, p, p)
                continue
            res = _quiet(lambda: bootstrap((x[0], ref[0]), _one_run_improvement, paired=True, n_resamples=reps,
                                           confidence_level=LEVEL, method="percentile",
                                           rng=np.random.default_rng(seed), vectorized=True))
            out[k] = (p, float(res.confidence_interval.low), float(res.confidence_interval.high))
        return out
    point, ci = _quiet(lambda: rly.get_interval_estimates(
        {k: [x, ref] for k, x in others.items()}, metrics.probability_of_improvement, reps=reps,
        confidence_interval_size=LEVEL), seed)
    return {k: (float(np.ravel(point[k])[0]), float(np.ravel(ci[k])[0]), float(np.ravel(ci[k])[1])) for k in others}


def _one_run_improvement(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    """rliable's ``probability_of_improvement`` for one run per scenario (higher is better), along ``axis``:
    per scenario the Mann-Whitney ``U / (1 x 1)`` is 1, 0.5 or 0; their mean."""
    return np.mean((x > y) + 0.5 * (x == y), axis=axis)


def _finite_order(x: np.ndarray, matrices: dict[str, np.ndarray]) -> np.ndarray:
    """``x`` with ``inf`` replaced by a finite value above every finite score of ``matrices`` (ties
    among failures kept): the Mann-Whitney statistic compares order only, and scipy's test wants finite input."""
    finite = np.concatenate([v[np.isfinite(v)] for v in matrices.values()] + [np.zeros(1)])
    big = 2.0 * float(np.max(np.abs(finite))) + 1.0
    return np.where(np.isfinite(x), x, big)


def plot_performance_profiles(matrices: dict[str, np.ndarray], path: str | Path, label: str,
                              reps: int = RLIABLE_REPS, seed: int = 0) -> Path:
    """rliable's performance profiles of the error (fraction of runs with error > tau, log tau, with
    stratified-bootstrap bands) as a PNG at ``path``: lower curves are better."""
    from rliable import library as rly  # noqa: PLC0415
    from rliable import plot_utils  # noqa: PLC0415

    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from addedinertia_env.foundation.atomic import save_figure  # noqa: PLC0415

    finite = np.concatenate([v[np.isfinite(v)] for v in matrices.values()] + [np.array([1e-6, 1.0])])
    lo = max(float(np.min(finite[finite > 0])) if np.any(finite > 0) else 1e-6, 1e-7)
    hi = max(float(np.max(finite)), lo * 10)
    taus = np.geomspace(lo, hi, 60)
    profiles, cis = _quiet(lambda: rly.create_performance_profile(matrices, taus, reps=reps, task_bootstrap=True), seed)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    plot_utils.plot_performance_profiles(profiles, np.log10(taus), performance_profile_cis=cis, ax=ax,
                                         xlabel=f"log10 tau ({label})",
                                         ylabel="fraction of runs with error > tau")
    ax.legend(list(profiles), fontsize=8)
    return save_figure(fig, Path(path))


def _quiet(call: Callable, seed: int = 0):
    """Run a rliable call without its numpy warnings on inf scores (each interval is still computed), with
    numpy's global generator seeded by ``seed`` and restored after: rliable's resampling draws from
    ``np.random.choice`` whatever ``random_state`` it is given, so this is what makes its intervals
    the same from run to run."""
    import warnings  # noqa: PLC0415

    state = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            warnings.simplefilter("ignore", FutureWarning)  # arch, under rliable: its random_state argument
            return call()
    finally:
        np.random.set_state(state)
