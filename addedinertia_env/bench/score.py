"""The ranked score: failure-aware, on the error a lab would publish (issue 28).

A lab publishes its lambda66 estimate, so an entry is ranked on the estimate's own error
``e`` (the energy method as written), not on how closely it copies the oracle: where a
drive's flaws bias the method, a controller whose plan avoids the bias beats the oracle
(perfect tracking), which is then a reference, not a floor. Each episode scores::

    s = min(|e|, CAP)          s = CAP for a failed run or identification

and an entry's score is the **mean of s** over the split's scenarios: a failed tank run
costs the entry the most an episode can (a median would let 17 % failures through
unnoticed), and one wild estimate cannot outweigh more than ``CAP`` of the rest.
:data:`CAP` = 10 %: beyond it an estimate of lambda66 is not one a lab would publish.

The paired control error ``|e - e_oracle|`` stays beside it (:mod:`.paired`): how much of
the error the controller adds to what the truth allows.

Statistics (:func:`entry_score`, :func:`difference`): scenarios are the resampling unit;
95 % percentile bootstrap intervals (2000 resamples, fixed seed) of the mean and of the
paired mean difference ``s_A - s_B`` over common scenarios. Tie rule
(:mod:`.ranking`): an entry whose paired interval against the leader of the current
group includes zero joins that group.

Every row carries :data:`SCORE_VERSION` (``score_version``) and its episode score
(``score``); rows of different score versions are never ranked together
(:func:`check_versions`). Rows written before the score existed (no ``score_version``)
are scored here from their ``rel_error`` and ``failure``, which is all the score reads.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from addedinertia_env.bench.statistics import clearly as clearly  # one rule for both scores

# The version names what a row's number is: the estimate, the truth and the ranking (bench/versions.py).
# Plain rigs: v1 (truth A66(0), 2026-11-27), then v4 (2026-11-28): the energy method reads the rest
# after the brake's release from the hull's law of motion, the torque scale on smooth currents at the
# current's sampling rule, and the rotor's dry friction near rest from the flywheel's coast
# (identify/energy_rest.py, energy_calibration.py, rotor_friction.py); the estimate of every rig changed.
SCORE_VERSION = "capped-mean-v4"
# The same score on a rig with a gearbox (a row whose scenario's rig has gear_ratio > 1): v2 from the day
# the energy method booked the gearhead's loss identified on the flywheel's balance (identify/energy_gear.py,
# issue 28); v3 (2026-11-28) from the day it also books the motor's cogging identified on that balance,
# with the loss fitted beside it (identify/energy_cogging.py), and the plain rigs' v4 changes above.
GEARED_SCORE_VERSION = "capped-mean-v3"
# the same capped mean of the error of the memory-corrected estimate (a suite's ``ranked: memory-corrected``,
# memory-v1): another quantity, so another version, never ranked beside the as-written rows; v2 with v4's
# energy method and the memory families averaged by their evidence (identify/memory.py)
MEMORY_SCORE_VERSION = "capped-mean-memory-corrected-v2"
# what this code wrote before: a row's own is kept, ranked only among its own, never resumed by a new run
FORMER_VERSIONS = ("capped-mean-v1", "capped-mean-v2", "capped-mean-memory-corrected-v1")
RANKED_VERSIONS = {"as-written": SCORE_VERSION, "memory-corrected": MEMORY_SCORE_VERSION}  # ranked score -> version
VERSIONS = (SCORE_VERSION, GEARED_SCORE_VERSION, MEMORY_SCORE_VERSION)  # what this code writes
CAP = 0.10  # |relative error| at which an estimate counts as unusable; a failure scores this


class ScoreVersionError(ValueError):
    """Rows of different score versions given to one ranking."""


def episode_score(row: dict[str, Any]) -> float:
    """``min(|rel_error|, CAP)``, or ``CAP`` for a failed episode (``rel_error`` null or not finite)."""
    e = row.get("rel_error")
    if e is None or not math.isfinite(float(e)):
        return CAP
    return min(abs(float(e)), CAP)


def row_fields(row: dict[str, Any]) -> dict[str, Any]:
    """The fields a bench row carries for the score: ``score_version`` (the row's own where it is one
    this code writes: :data:`GEARED_SCORE_VERSION` for a geared rig; else the version of the suite's
    ranked estimate, :data:`RANKED_VERSIONS`) and ``score``."""
    version = row.get("score_version")
    if version not in VERSIONS + FORMER_VERSIONS:
        version = RANKED_VERSIONS.get(str(row.get("ranked_score", "as-written")), SCORE_VERSION)
    return {"score_version": version, "score": episode_score(row)}


def check_versions(rows: list[dict[str, Any]], where: str = "rows") -> str:
    """The one score version of ``rows`` (rows without one count as the current version, scored
    from their errors); :class:`ScoreVersionError` naming the versions found when they differ."""
    found = sorted({str(r.get("score_version", SCORE_VERSION)) for r in rows})
    if len(found) > 1 or found[0] not in VERSIONS + FORMER_VERSIONS:
        raise ScoreVersionError(f"{where}: rows of score version(s) {found}; this leaderboard ranks one of "
                                f"{', '.join(map(repr, VERSIONS))} at a time (rerun the old rows with "
                                "`addedinertia bench run`)")
    return found[0]


def _key(row: dict[str, Any]) -> tuple[str, str, int]:
    return (str(row["suite"]), str(row.get("split", "?")), int(row["seed"]))


def scores(rows: list[dict[str, Any]]) -> dict[tuple, float]:
    """``{scenario: s}`` of one entry's rows (the last row of a scenario wins)."""
    return {_key(r): episode_score(r) for r in rows}


def bootstrap_mean(x: np.ndarray, n_boot: int = 2000, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``x`` (its entries resampled), via
    :func:`scipy.stats.bootstrap` (method ``percentile``); ``(x, x)`` for constant ``x``."""
    x = np.asarray(x, float)
    if len(x) == 0:
        return (math.nan, math.nan)
    if np.all(x == x[0]):
        return (float(x[0]), float(x[0]))
    from scipy.stats import bootstrap  # noqa: PLC0415

    res = bootstrap((x,), np.mean, n_resamples=n_boot, confidence_level=level, method="percentile",
                    random_state=np.random.default_rng(seed), vectorized=True)
    return (float(res.confidence_interval.low), float(res.confidence_interval.high))


def entry_score(rows: list[dict[str, Any]], n_boot: int = 2000, seed: int = 0) -> dict[str, Any]:
    """An entry's ``mean_score`` (mean capped |error|), its 95 % interval, its scenario scores and
    the mean wear per episode (``mean_current_sign_changes``, ``mean_chatter_A``; None when the
    rows predate them)."""
    s = scores(rows)
    x = np.array(list(s.values()), float)
    lo, hi = bootstrap_mean(x, n_boot=n_boot, seed=seed)

    def mean_of(key: str):
        vals = [float(r[key]) for r in rows if r.get(key) is not None]
        return float(np.mean(vals)) if vals else None

    return {"mean_score": float(np.mean(x)) if len(x) else math.nan, "ci95_score": [lo, hi],
            "score_version": check_versions(rows) if rows else SCORE_VERSION, "scenario_scores": s,
            "mean_current_sign_changes": mean_of("current_sign_changes"), "mean_chatter_A": mean_of("chatter_A")}


def difference(s_a: dict[tuple, float], s_b: dict[tuple, float], n_boot: int = 2000, seed: int = 0) -> dict[str, Any]:
    """Paired ``s_A - s_B`` over the common scenarios: its mean, 95 % interval and ``n``."""
    keys = sorted(set(s_a) & set(s_b))
    d = np.array([s_a[k] - s_b[k] for k in keys], float)
    lo, hi = bootstrap_mean(d, n_boot=n_boot, seed=seed)
    return {"mean": float(np.mean(d)) if len(d) else math.nan, "ci95": [lo, hi], "n": int(len(d))}
