"""The failure-aware ranked score (bench/score.py) and the wear counts (bench/wear.py)."""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.bench import score
from addedinertia_env.bench.leaderboard import public, summarise
from addedinertia_env.bench.wear import sign_changes


def _rows(controller, errors, kind="classical", version=None):
    rows = [{"controller": controller, "suite": "synthetic", "split": "test", "scenario": f"s{k}", "seed": k,
             "lambda66_true": 1.0, "lambda66_est": None if e is None else 1.0 + e, "rel_error": e,
             "energy_J": 1.0, "tracking_rms_rad": 1e-4, "saturated_frac": 0.0, "wall_s": 1.0,
             "version": "0.1.0", "commit": "abc1234", "entry_kind": kind} for k, e in enumerate(errors)]
    if version is not None:
        for r in rows:
            r["score_version"] = version
    return rows


def test_an_episode_scores_its_capped_error_and_a_failure_the_cap():
    assert score.episode_score({"rel_error": -0.02}) == 0.02
    assert score.episode_score({"rel_error": 0.5}) == score.CAP
    assert score.episode_score({"rel_error": None, "failure": "x"}) == score.CAP
    assert score.row_fields({"rel_error": 0.01}) == {"score_version": score.SCORE_VERSION, "score": 0.01}


def test_failures_rank_an_entry_down_that_a_median_would_have_let_through():
    """hard-v0's case: 17 % failures and slightly better errors otherwise; a median ranks it first."""
    rng = np.random.default_rng(0)
    n = 30
    steady = list(0.012 + 0.002 * rng.standard_normal(n))
    flaky = [None if k % 6 == 0 else 0.010 + 0.002 * rng.standard_normal() for k in range(n)]
    entries = {e["controller"]: e for e in summarise(_rows("steady", steady) + _rows("flaky", flaky), n_boot=500)}
    med = lambda rows: np.median([abs(e) if e is not None else np.inf for e in rows])  # noqa: E731
    assert med(flaky) < med(steady)  # the old statistic preferred the flaky entry
    assert entries["steady"]["rank"] == 1 and entries["flaky"]["rank"] == 2
    assert entries["flaky"]["mean_score"] == pytest.approx(np.mean([score.episode_score({"rel_error": e})
                                                                    for e in flaky]))
    lo, hi = entries["flaky"]["ci95_score"]
    assert lo <= entries["flaky"]["mean_score"] <= hi
    assert all(e["score_version"] == score.SCORE_VERSION for e in public(list(entries.values())))


def test_rows_of_another_score_version_are_not_ranked_together():
    rows = _rows("a", [0.01, 0.02]) + _rows("b", [0.01, 0.03], version="median-v0")
    with pytest.raises(score.ScoreVersionError, match="median-v0"):
        summarise(rows, n_boot=100)


def test_paired_difference_of_scores():
    a = {("s", "t", k): 0.01 for k in range(10)}
    b = {("s", "t", k): 0.02 + 0.001 * k for k in range(10)}
    d = score.difference(b, a, n_boot=500)
    assert d["n"] == 10 and d["mean"] == pytest.approx(0.0145) and score.clearly(d) == 1


def test_sign_changes_count_crossings_of_the_band_only():
    i = np.array([1.0, 0.5, 0.05, -0.05, 0.04, -1.0, -0.9, 0.01, 2.0, 3.0, -3.0])
    assert sign_changes(i, band=0.1) == 3  # +, (band), -, (band), +, -
    chatter = 5.0 * (-1.0) ** np.arange(100)  # +-5 A at the sample rate
    assert np.sqrt(np.mean(np.square(np.diff(chatter)))) == pytest.approx(10.0)
    assert sign_changes(chatter, band=0.3) == 99


def test_the_cli_refuses_rows_of_another_score_version(tmp_path, capsys):
    import json

    from addedinertia_env.cli import main

    path = tmp_path / "rows.jsonl"
    path.write_text("\n".join(json.dumps(r) for r in _rows("a", [0.01]) + _rows("b", [0.02], version="median-v0")))
    assert main(["bench", "leaderboard", str(path), "--format", "json"]) == 2
    err = capsys.readouterr().err
    assert "median-v0" in err and str(path) in err and len(err.strip().splitlines()) == 1
