"""Interval calibration (docs/INTERVALS.md, issue 26): the report's statistics on simulated sets whose
answer is known, the error budget's parts, and (slow) the energy method's intervals on simulated hulls."""

from __future__ import annotations

import math

import numpy as np
import pytest

from addedinertia_env.reports import interval_calibration as ic


def _gaussian_runs(n: int, scale: float, seed: int = 0):
    """``n`` runs whose errors are N(0, sigma_k) (sigma_k drawn per run) with 95 % half-widths
    ``scale * 1.96 sigma_k``."""
    rng = np.random.default_rng(seed)
    sigma = rng.uniform(0.5, 2.0, n) * 1e-4
    return rng.normal(0.0, sigma), scale * ic.Z95 * sigma


def test_a_calibrated_gaussian_interval_covers_95_percent_with_ratio_2_9():
    errors, half = _gaussian_runs(20000, 1.0)
    c = ic.calibration(errors, half)
    assert c.runs == 20000
    assert c.coverage == pytest.approx(0.95, abs=0.006)
    assert c.coverage_ci[0] < 0.95 < c.coverage_ci[1]
    # one sigma per run: the ratio of medians is 2.9 for equal sigmas; spread sigmas keep it near
    errors1, half1 = np.random.default_rng(1).normal(0, 1e-4, 20000), np.full(20000, ic.Z95 * 1e-4)
    assert ic.calibration(errors1, half1).ratio == pytest.approx(ic.CALIBRATED_RATIO, rel=0.03)
    assert ic.CALIBRATED_RATIO == pytest.approx(2.906, abs=1e-3)
    assert c.median_abs_z == pytest.approx(0.674, abs=0.02)


def test_median_z_reads_per_run_calibration_where_sigmas_differ_by_orders():
    # runs whose sigmas span four decades, each interval calibrated: the ratio of the two medians is
    # not 2.9 (it depends on which runs hold the medians), the median |z| still is 0.674
    rng = np.random.default_rng(4)
    sigma = 10.0 ** rng.uniform(-6, -2, 20000)
    errors = rng.normal(0.0, sigma)
    c = ic.calibration(errors, ic.Z95 * sigma)
    assert c.median_abs_z == pytest.approx(0.674, abs=0.02)
    assert c.coverage == pytest.approx(0.95, abs=0.006)
    wide = ic.calibration(errors, 2 * ic.Z95 * sigma)
    assert wide.median_abs_z == pytest.approx(0.337, abs=0.01)


@pytest.mark.parametrize("scale", [2.0, 0.5])
def test_too_wide_and_too_narrow_intervals_are_told_apart(scale):
    coverage = math.erf(scale * ic.Z95 / math.sqrt(2))  # P(|z| <= scale * 1.96)
    errors = np.random.default_rng(2).normal(0, 1e-4, 20000)
    c = ic.calibration(errors, np.full(20000, scale * ic.Z95 * 1e-4))
    assert c.coverage == pytest.approx(coverage, abs=0.01)
    assert c.ratio == pytest.approx(scale * ic.CALIBRATED_RATIO, rel=0.04)


def test_coverage_counts_the_runs_inside_and_the_medians_are_of_absolute_values():
    c = ic.calibration([-3.0, 1.0, 2.0, -0.5], [1.0, 2.0, 2.0, 0.1])
    assert (c.covered, c.runs) == (2, 4)  # |-3| > 1 and |-0.5| > 0.1 miss; 1 <= 2 and 2 <= 2 cover
    assert c.median_abs_error == pytest.approx(1.5)
    assert c.median_half_width == pytest.approx(1.5)
    assert c.ratio == pytest.approx(1.0)
    assert c.median_abs_z == pytest.approx(ic.Z95 * np.median([3.0, 0.5, 1.0, 5.0]))  # |e| / h: 3, .5, 1, 5


@pytest.mark.parametrize("errors, half", [([], []), ([1.0], [1.0, 2.0]), ([np.nan], [1.0]), ([1.0], [-1.0])])
def test_bad_input_is_refused_by_name(errors, half):
    with pytest.raises(ValueError, match="calibration"):
        ic.calibration(errors, half)


def test_wilson_interval_brackets_the_proportion():
    lo, hi = ic.wilson(36, 36)
    assert hi == pytest.approx(1.0) and 0.88 < lo < 0.91
    lo, hi = ic.wilson(34, 36)
    assert lo < 34 / 36 < hi


def _row(label, water, value, ci, truth, cause=None):
    return {"label": label, "water": water, "result": {"lambda66": value, "ci95": ci},
            "truth": {"lambda66": truth, "cause": cause}, "cpu_s": 1.0}


def test_table_groups_by_water_and_leaves_out_causes_that_bias_the_balance_by_design():
    rows = [_row("cum-wigley-2m-lqr-s1", "memory", 10.001, [9.99, 10.012], 10.0),
            _row("con-wigley-2m-lqr-s1", "memory-free", 10.003, [10.001, 10.005], 10.0),  # misses
            _row("foreign-lab-case-03-run-03", "memory-free", 9.999, [9.99, 10.01], 10.0, "none"),
            _row("foreign-lab-case-00-run-03", "memory-free", 10.2, [10.19, 10.21], 10.0, "fluid_memory"),
            {"label": "x", "water": "memory", "result": {"error": "IdentificationError: no"}, "truth": {}, "cpu_s": 0}]
    got = ic.scored(rows)
    assert sorted(k for k in got if ":" not in k) == ["memory", "memory-free"]
    assert [lab for lab, *_ in got["memory-free"]] == ["con-wigley-2m-lqr-s1", "foreign-lab-case-03-run-03"]
    text = ic.table(rows)
    assert "| **memory-free** | 2 |" in text and "1/2" in text
    assert "5 runs, 1 refused" in text


# --- the error budget's parts ---------------------------------------------------------------------
def test_slope_weights_give_the_least_squares_slope():
    from addedinertia_env.identify.energy_pooling import _slope_weights

    rng = np.random.default_rng(3)
    phi = np.sort(rng.uniform(0.01, 0.05, 41))
    lam = 3.0 + 20.0 * phi + rng.normal(0, 0.01, 41)
    assert _slope_weights(phi) @ lam == pytest.approx(np.polyfit(phi, lam, 1)[0], rel=1e-10)


def test_trend_slope_within_its_own_noise_is_not_structure():
    from addedinertia_env.identify.energy_pooling import _trend_excess, hann_weights

    phi = np.linspace(0.01, 0.05, 41)
    g = hann_weights(np.linspace(0.25, 0.75, 41), 0.25, 0.75)
    g = g / g.sum()
    lam = 10.0 + 0.5 * (phi - 0.03)  # a pure line: no scatter about it
    s = np.zeros(41)
    full = _trend_excess(phi, lam, s, g)
    assert full == pytest.approx(0.25 * 0.5 * 0.04, rel=1e-9)  # a quarter of the end-to-end change
    assert _trend_excess(phi, lam, s, g, s_slope=0.5) == pytest.approx(0.0, abs=1e-6)  # slope within its noise
    assert 0.0 < _trend_excess(phi, lam, s, g, s_slope=0.3) < full


def test_damping_law_covariance_from_blocks_matches_independent_residuals():
    from addedinertia_env.identify.energy_dissipation import _block_covariance

    rng = np.random.default_rng(4)
    n, sigma = 40000, 0.01
    X = np.column_stack([rng.uniform(0.1, 1, n), rng.uniform(0.1, 1, n)])
    resid = rng.normal(0, sigma, n)
    cov = _block_covariance(X, resid, 25)
    ols = sigma**2 * np.linalg.inv(X.T @ X)
    assert np.sqrt(np.diag(cov)) == pytest.approx(np.sqrt(np.diag(ols)), rel=0.2)
    assert np.all(np.isnan(_block_covariance(X[:100], resid[:100], 25)))  # two blocks: no covariance


def test_energy_result_carries_its_budget_and_the_parts_add_up(realistic_record):
    from addedinertia_env.identify import identify

    record, _ = realistic_record
    res = identify([record], "energy")
    (parts,) = res.details["per_run_sigma_parts"]
    (sigma,) = res.details["per_run_sigma"]
    total = math.sqrt(sum(parts[k] ** 2 for k in ("rate", "current", "common", "trend")))
    assert total == pytest.approx(sigma, rel=1e-12)
    assert parts["rate"] > 0 and parts["slope_noise"] >= 0


# --- the big one ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_memory_and_memory_free_hulls_are_covered_by_intervals_sized_to_their_error(tmp_path):
    """One hull set per water (wigley-2m, lqr, seed 1): each interval covers A66(0), and is not wider than
    30 times the error of the run it covers nor than 0.5 % (the memory-corrected balance's own interval was
    +-2.8 % before its budget was taken on the corrected values)."""
    rows = []
    for hyd in ("cummins", "constant"):
        spec = {"preset": "wigley-2m", "hydrodynamics": hyd, "controller": "lqr", "seed": 1}
        files = ic.simulate_set(spec, tmp_path)
        rows.append(ic.identify_row(ic.label_of(spec), ic.WATERS[hyd], files, None))
    for row in rows:
        res, a0 = row["result"], row["truth"]["lambda66"]
        assert "error" not in res, res
        lo, hi = res["ci95"]
        assert lo <= a0 <= hi, row["label"]
        assert 0.5 * (hi - lo) / a0 < 5e-3
    mem = rows[0]["result"]
    half_corrected = 0.5 * (mem["lambda66_energy_corrected_ci95"][1] - mem["lambda66_energy_corrected_ci95"][0])
    assert half_corrected / rows[0]["truth"]["lambda66"] < 5e-3
    c = ic.calibration([r["result"]["lambda66"] / r["truth"]["lambda66"] - 1 for r in rows],
                       [0.5 * (r["result"]["ci95"][1] - r["result"]["ci95"][0]) / r["truth"]["lambda66"] for r in rows])
    assert c.covered == 2


def test_scatter_about_the_line_enters_the_average_as_its_own_correlation_says():
    from addedinertia_env.identify.energy_pooling import _trend_excess, hann_weights

    phi = np.linspace(0.01, 0.05, 41)
    g = hann_weights(np.linspace(0.25, 0.75, 41), 0.25, 0.75)
    g = g / g.sum()
    rng = np.random.default_rng(5)
    s = np.zeros(41)
    white = [_trend_excess(phi, 10.0 + rng.normal(0, 0.01, 41), s, g, s_slope=1e9) ** 2 for _ in range(400)]
    # white scatter: the weighted mean's variance sigma^2 sum(g^2) (the line's two parameters take a little)
    assert np.mean(white) == pytest.approx(1e-4 * float(g @ g), rel=0.25)
    alternating = 10.0 + 0.01 * (-1.0) ** np.arange(41)  # neighbours cancel in the average
    assert _trend_excess(phi, alternating, s, g, s_slope=1e9) < 0.3 * math.sqrt(1e-4 * float(g @ g))
    # scatter the modelled per-angle noise explains is not counted twice
    assert _trend_excess(phi, 10.0 + rng.normal(0, 0.01, 41), np.full(41, 0.02), g, s_slope=1e9) == 0.0
