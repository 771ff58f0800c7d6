"""The leaderboard's statistics through SciPy's bootstrap and rliable (issue 30, item 1).

The intervals are held to what an interval must do (cover the population's median, pair
scenarios so that what they share cancels), and the score matrix that ``bench leaderboard
--format scores`` writes is read back by rliable itself.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from addedinertia_env.bench.leaderboard import summarise
from addedinertia_env.bench.statistics import (_one_run_improvement, improvement_over, iqm_with_ci, median_ci,
                                               paired_median_difference)
from addedinertia_env.cli import main

from test_bench import _rows


def test_the_median_interval_covers_the_population_median():
    rng = np.random.default_rng(3)
    true_median = math.log(2.0)  # exponential(1)
    hits = [lo <= true_median <= hi for lo, hi in (median_ci(rng.exponential(size=41), n_boot=400, seed=k)
                                                    for k in range(200))]
    assert 0.88 <= np.mean(hits) <= 0.995, np.mean(hits)


def test_failures_count_as_infinite_errors():
    lo, hi = median_ci(np.array([1.0, math.inf, 2.0]), n_boot=200)
    assert lo >= 1.0 and math.isinf(hi)
    assert all(math.isnan(v) for v in median_ci(np.array([]), n_boot=10))


def test_pairing_cancels_what_two_entries_share():
    rng = np.random.default_rng(8)
    shared = rng.normal(0.0, 0.05, 60)  # per-scenario difficulty, common to both entries
    a = np.abs(shared + rng.normal(0.0, 0.001, 60))
    b = a + 0.004 + rng.normal(0.0, 0.001, 60)  # b adds 0.4 % on every scenario
    mid, (lo, hi) = paired_median_difference(b, a, n_boot=1000)
    assert 0.0 < lo < 0.004 < hi < 0.008 and lo <= mid <= hi
    # unpaired, the shared spread hides the difference: the two medians' intervals overlap
    (alo, ahi), (blo, bhi) = median_ci(a, n_boot=1000), median_ci(b, n_boot=1000)
    assert not (ahi < blo) and hi - lo < (bhi - blo) / 3
    # two failures on a scenario are no difference; one failure is an infinite one
    mid, _ = paired_median_difference(np.array([math.inf, 1.0, 2.0]), np.array([math.inf, 1.0, 2.0]), n_boot=50)
    assert mid == 0.0


def _rows_file(tmp_path):
    rng = np.random.default_rng(0)
    rows = (_rows("a", rng.normal(0, 0.002, 30)) + _rows("b", rng.normal(0, 0.004, 30), energy=5.0)
            + _rows("c", list(rng.normal(0, 0.003, 28)) + [None, None]))
    for r in rows:
        r["entry_kind"] = "classical"
    f = tmp_path / "rows.jsonl"
    f.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    return f, rows


def test_the_score_matrix_is_read_by_rliable(tmp_path):
    from rliable import library as rly
    from rliable import metrics

    f, rows = _rows_file(tmp_path)
    out = tmp_path / "scores.npz"
    assert main(["bench", "leaderboard", str(f), "--format", "scores", "--out", str(out)]) == 0
    score_dict = dict(np.load(out))
    side = json.loads((tmp_path / "scores.npz.json").read_text())
    assert sorted(score_dict) == ["a", "b", "c"] and side["lower_is_better"] and side["shape"] == "runs x scenarios"
    assert all(v.shape == (1, 30) for v in score_dict.values()) and len(side["scenarios"]) == 30
    assert np.isinf(score_dict["c"]).sum() == 2  # the two failures
    entries = {e["controller"]: e for e in summarise(rows, n_boot=200)}
    point, ci = rly.get_interval_estimates(score_dict, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=200)
    for name, matrix in score_dict.items():
        # the same numbers as the leaderboard's, scenario by scenario
        by_seed = {r["seed"]: abs(r["rel_error"]) if r["rel_error"] is not None else math.inf
                   for r in rows if r["controller"] == name}
        np.testing.assert_array_equal(matrix[0], [by_seed[int(s.rsplit("/", 1)[1])] for s in side["scenarios"]])
        assert point[name][0] == pytest.approx(entries[name]["iqm_abs_error"])
        assert ci[name][0, 0] <= point[name][0] <= ci[name][1, 0]
    assert main(["bench", "leaderboard", str(f), "--format", "scores"]) == 2  # a binary file needs --out


def test_iqm_interval_and_probability_of_improvement():
    from rliable import metrics

    rng = np.random.default_rng(4)
    m = {"good": np.abs(rng.normal(0, 0.001, (1, 40))), "bad": np.abs(rng.normal(0, 0.01, (1, 40)))}
    iqms = iqm_with_ci(m, reps=500)
    assert iqms["good"][2] < iqms["bad"][1]  # clearly apart
    assert iqm_with_ci(m, reps=500) == iqms  # seeded: the same intervals every run
    poi = improvement_over(m, "bad", reps=500)["good"]
    assert poi[1] <= poi[0] <= poi[2] and poi[1] > 0.7  # good's error is below bad's on most scenarios
    same = improvement_over({"x": m["good"], "y": m["good"].copy()}, "y", reps=100)["x"]
    assert same[0] == 0.5
    # the one-run statistic the paired scenario bootstrap uses is rliable's own
    x, y = rng.integers(0, 3, (1, 50)).astype(float), rng.integers(0, 3, (1, 50)).astype(float)
    assert _one_run_improvement(x[0], y[0]) == pytest.approx(metrics.probability_of_improvement(x, y))


def test_an_iqm_interval_over_failures_is_unbounded_not_nan():
    # 7 failures of 30 (as many as the IQM trims; more in many resamples): rliable's percentile between two
    # infinite resampled IQMs is nan; the interval is then open above, and reads so
    m = {"fails": np.concatenate([np.linspace(0.001, 0.01, 23), np.full(7, np.inf)])[None, :]}
    v, lo, hi = iqm_with_ci(m, reps=500)["fails"]
    assert np.isfinite(v) and np.isfinite(lo) and lo <= v
    assert hi == math.inf
    m = {"ok": np.linspace(0.001, 0.01, 30)[None, :]}
    assert all(np.isfinite(iqm_with_ci(m, reps=200)["ok"]))  # no failure, a bounded interval


def test_the_markdown_leaderboard_has_rliables_aggregates_and_profiles(tmp_path):
    f, _ = _rows_file(tmp_path)
    md = tmp_path / "lb.md"
    assert main(["bench", "leaderboard", str(f), "--format", "md", "--out", str(md)]) == 0
    text = md.read_text()
    assert "## Aggregate statistics (rliable)" in text and "| a |" in text.split("Aggregate statistics")[1]
    assert (tmp_path / "figures" / "lb-profiles.png").stat().st_size > 5000
