"""Rank controllers from benchmark rows: paired control error, median |error|, IQM, bootstrap intervals.

Statistics per controller, over its episodes (rows):

* the ranked score: with ``oracle`` rows, the median control error ``|e - e_oracle|``
  paired by scenario (:mod:`.paired`); else the median ``|rel_error|``. ``rel_error`` is
  the energy method as written; ``rel_error_corrected`` (the default, model-corrected
  identification) is summarised beside it;
* a failed episode (``rel_error`` null) counts as an infinite error, so failures rank
  a controller down rather than vanish from its median;
* ``median`` and its 95 % bootstrap interval: :func:`scipy.stats.bootstrap`'s percentile
  interval over ``n_boot`` resamples (fixed seed; :mod:`.statistics`);
* ``iqm``: mean of the middle 50 % of the errors (interquartile mean, as in Agarwal et al.
  2021, "Deep RL at the edge of the statistical precipice"; its stratified-bootstrap
  interval and the probability of improvement come from rliable, :mod:`.statistics`);
* ``failure_rate``, median ``energy_J`` and median ``tracking_rms_rad``.

Ranking and the tie rule: :mod:`.ranking`; the verdict: :mod:`.verdict`; rendering:
:mod:`.render`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.bench.runner import REQUIRED_FIELDS
from addedinertia_env.bench.statistics import median_ci
from addedinertia_env.bench.versions import ScoreVersionError, check_versions


class RowsError(ValueError):
    """A benchmark rows file that cannot be used."""


def load_rows(paths: list[str | Path]) -> list[dict[str, Any]]:
    """Read benchmark rows (JSON lines) from ``paths``, every file in turn.

    Raises FileNotFoundError for a missing file and :class:`RowsError` naming file and line
    for a line that is not JSON or lacks a field of :data:`REQUIRED_FIELDS`, or when no
    file holds a row, and naming the files and their versions when the rows are of several
    score versions (:func:`.versions.check_versions`).
    """
    rows = []
    by_file: dict[str, list[dict[str, Any]]] = {}
    for path in paths:
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such rows file (make it with `addedinertia bench run --out {path}`)")
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError as e:
                raise RowsError(f"{path}:{n}: not a JSON line ({e})") from None
            missing = [k for k in REQUIRED_FIELDS if k not in row]
            if missing:
                raise RowsError(f"{path}:{n}: missing field(s) {missing}; a bench row needs {list(REQUIRED_FIELDS)}")
            rows.append(row)
            by_file.setdefault(str(path), []).append(row)
    if not rows:
        raise RowsError(f"no rows in {[str(p) for p in paths]}")
    try:  # one score version per board (bench/versions.py)
        check_versions(by_file)
    except ScoreVersionError as e:
        raise RowsError(str(e)) from None
    return rows


def abs_errors(rows: list[dict]) -> np.ndarray:
    """``|rel_error|`` per row; failures are ``inf``."""
    return np.array([abs(r["rel_error"]) if r.get("rel_error") is not None else math.inf for r in rows])


def iqm(x: np.ndarray) -> float:
    """Interquartile mean: the mean of the middle 50 % (:func:`scipy.stats.trim_mean` with 25 % cut from
    each end, rliable's ``aggregate_iqm``); nan for no values."""
    from scipy.stats import trim_mean  # noqa: PLC0415

    x = np.asarray(x, float)
    if x.size == 0:
        return math.nan
    with np.errstate(invalid="ignore"):
        return float(trim_mean(x, 0.25, axis=None))


def scores(rows: list[dict]) -> tuple[str, dict[str, dict[tuple, list[float]]]]:
    """The ranked statistic's per-episode values, ``(what they are, {controller: {scenario: [value per
    run]}})``: the control error ``|e - e_oracle|`` (:mod:`.paired`) with oracle rows, else ``|rel_error|``;
    ``inf`` for a failure. :func:`.statistics.score_matrix` turns them into rliable's matrices."""
    from addedinertia_env.bench import paired  # noqa: PLC0415

    by: dict[str, list[dict]] = {}
    for r in rows:
        by.setdefault(r["controller"], []).append(r)
    oracle_rows = by.get(paired.ORACLE, [])
    out: dict[str, dict[tuple, list[float]]] = {}
    if oracle_rows:
        for name, rs in by.items():
            out[name] = {k: [v] for k, v in paired.control_errors(rs, oracle_rows).items()}
        return "control error |e_entry - e_oracle| (relative lambda66 error, paired by scenario)", out
    for name, rs in by.items():
        for r, err in zip(rs, abs_errors(rs)):
            out.setdefault(name, {}).setdefault(paired.scenario_key(r), []).append(float(err))
    return "|e| (relative lambda66 error of the energy method as written)", out


def _kind(rows: list[dict]) -> str:
    """``reference``, ``learned`` or ``classical`` (rows' ``entry_kind``; older rows: a training cost)."""
    kinds = {r.get("entry_kind") for r in rows} - {None}
    if kinds:
        return sorted(kinds)[0] if len(kinds) == 1 else "mixed"
    if rows and rows[0]["controller"] in ("oracle", "zero"):
        return "reference"
    learned = any(r.get("train_env_steps") is not None or r.get("train_cpu_minutes") is not None for r in rows)
    return "learned" if learned else "classical"


def _median_or_nan(values: list) -> float:
    vals = [v for v in values if v is not None]
    return float(np.median(vals)) if vals else math.nan


def summarise(rows: list[dict], n_boot: int = 2000, seed: int = 0) -> list[dict[str, Any]]:
    """One entry per controller, ranked (module doc of :mod:`.ranking`)."""
    from addedinertia_env.bench import paired  # noqa: PLC0415
    from addedinertia_env.bench.ranking import rank  # noqa: PLC0415

    from addedinertia_env.bench import score  # noqa: PLC0415

    score.check_versions(rows)
    by: dict[str, list[dict]] = {}
    for r in rows:
        by.setdefault(r["controller"], []).append(r)
    oracle_rows = by.get(paired.ORACLE, [])
    oracle_failed = sum(r.get("rel_error") is None for r in oracle_rows)
    out = []
    for name, rs in by.items():
        err = abs_errors(rs)
        lo, hi = median_ci(err, n_boot=n_boot, seed=seed)
        corrected = [abs(r["rel_error_corrected"]) if r.get("rel_error_corrected") is not None else math.inf
                     for r in rs if "rel_error_corrected" in r]
        e = {
            "controller": name, "kind": _kind(rs), "episodes": len(rs), "median_abs_error": float(np.median(err)),
            "ci95_median": [lo, hi], "iqm_abs_error": iqm(err), "failure_rate": float(np.mean(~np.isfinite(err))),
            "median_abs_error_corrected": float(np.median(corrected)) if corrected else math.nan,
            "median_energy_J": _median_or_nan([r.get("energy_J") for r in rs]),
            "median_tracking_rms_rad": _median_or_nan([r.get("tracking_rms_rad") for r in rs]),
            "median_wall_s": float(np.median([r["wall_s"] for r in rs])),
            # learned entries: what OnnxPolicy read from its metadata, or what a submission declared
            "train_env_steps": next((r["train_env_steps"] for r in rs if r.get("train_env_steps") is not None), None),
            "train_cpu_minutes": next((r["train_cpu_minutes"] for r in rs if r.get("train_cpu_minutes") is not None),
                                      None),
            "suites": sorted({str(r["suite"]) for r in rs}), "splits": sorted({str(r.get("split", "?")) for r in rs}),
            "version": ",".join(sorted({str(r["version"]) for r in rs})),
            "commit": ",".join(sorted({str(r.get("commit", "unknown")) for r in rs})),
            "median_abs_control_error": None, "ci95_control_error": None, "n_paired": 0,
            "oracle_failed": oracle_failed if oracle_rows else None,
        }
        e.update(score.entry_score(rs, n_boot=n_boot, seed=seed))  # the ranked score (bench/score.py)
        if oracle_rows:
            e["control_errors"] = paired.control_errors(rs, oracle_rows)
            e.update(paired.summary(e["control_errors"], n_boot=n_boot, seed=seed))
        out.append(e)
    return rank(out, n_boot=n_boot, seed=seed)


def public(entries: list[dict]) -> list[dict]:
    """Entries without their per-scenario working data (for JSON output)."""
    return [{k: v for k, v in e.items() if k not in ("control_errors", "scenario_scores")} for e in entries]
