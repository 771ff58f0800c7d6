"""The stratified delete-one-cluster jackknife (identify/cluster_jackknife.py) and A66(0)'s interval holding it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from addedinertia_env.identify.cluster_jackknife import stratified_jackknife, t95


def test_one_stratum_is_the_plain_jackknife_of_a_mean():
    # the delete-one jackknife of a sample mean is the mean's usual standard error, s / sqrt(n)
    rng = np.random.default_rng(3)
    x = rng.normal(2.0, 0.5, 7)
    leave_one_out = [(x.sum() - xi) / (len(x) - 1) for xi in x]
    sd, dof = stratified_jackknife(leave_one_out, ["a"] * len(x))
    assert sd == pytest.approx(x.std(ddof=1) / math.sqrt(len(x)), rel=1e-12)
    assert dof == len(x) - 1


def test_strata_add_their_variances_and_a_lone_cluster_adds_nothing():
    a, b = [1.0, 3.0], [10.0, 10.5, 11.5]
    sd, dof = stratified_jackknife(a + b + [100.0], ["a", "a", "b", "b", "b", "lone"])
    var_a = 0.5 * ((1 - 2) ** 2 + (3 - 2) ** 2)
    mb = np.mean(b)
    var_b = 2 / 3 * sum((v - mb) ** 2 for v in b)
    assert sd == pytest.approx(math.sqrt(var_a + var_b), rel=1e-12)
    assert dof == 1 + 2  # the lone cluster (a decay beside reverse runs) gives no degree of freedom
    # the spread *between* strata is not sampling error: shifting a whole stratum changes nothing
    sd2, _ = stratified_jackknife([v + 50 for v in a] + b + [0.0], ["a", "a", "b", "b", "b", "lone"])
    assert sd2 == pytest.approx(sd, rel=1e-12)


def test_no_stratum_of_two_gives_no_estimate_and_bad_input_is_refused():
    sd, dof = stratified_jackknife([1.0, 2.0], ["x", "y"])
    assert math.isnan(sd) and dof == 0
    with pytest.raises(ValueError, match="one stratum per value"):
        stratified_jackknife([1.0, 2.0], ["x"])
    with pytest.raises(ValueError, match="finite"):
        stratified_jackknife([1.0, float("nan")], ["x", "x"])
    with pytest.raises(ValueError, match="dof"):
        t95(0)
    assert t95(2) == pytest.approx(4.302653, rel=1e-6)


def test_the_corrected_balance_is_a_check_not_a_floor():
    # the reported A66(0) keeps the memory fit's own interval however far the corrected balance reads; their
    # difference is reported over the two half-widths together (1.96: the intervals just agree at 95 %)
    from addedinertia_env.identify.memory_energy import balance_check, combine

    value, ci = combine(10.00, (9.99, 10.02))  # the balance (10.30 +- 0.02, below) does not enter it
    assert value == 10.00 and ci == (9.99, 10.02)
    check = balance_check(10.30, (10.28, 10.32), 10.00, (9.99, 10.02))
    assert check["difference"] == pytest.approx(0.30)
    assert check["z"] == pytest.approx(0.30 / (math.hypot(0.02, 0.02) / 1.959963984540054))
    assert balance_check(10.0, (9.9, 10.1), 10.0, (9.9, 10.1))["z"] == 0.0
