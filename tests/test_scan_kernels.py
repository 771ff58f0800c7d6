"""The compiled scans (addedinertia_env/records/scan_kernels.py) against the numpy expressions they replaced,
bit for bit, on random series with the awkward values (nan, inf, signed zeros, ties, quantised steps)."""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.records.scan_kernels import (
    abs_max,
    abs_rates,
    bitwise_constant,
    block_starts,
    first_beyond,
    first_step_beyond,
    gap_counts,
    median_abs_deviation_sorted,
    negative_step_ratios,
    reaction_work,
    relaxed_interval_means,
    second_differences,
    squared_step_sums,
    true_counts,
    value_change_starts,
)


def _series(rng, n, awkward=True):
    """A quantised random walk with, when ``awkward``, a few nan, inf and signed zeros."""
    x = np.round(np.cumsum(rng.normal(size=n)) * 50.0) / 50.0
    if awkward and n > 4:
        k = rng.integers(0, n, size=4)
        x[k] = [np.nan, np.inf, -0.0, 0.0]
    return x


def _times(rng, n):
    return np.cumsum(1e-3 * (1.0 + 0.01 * rng.integers(-2, 3, size=n)))


@pytest.mark.parametrize("labels", [["idle"] * 3 + ["free"] * 4 + ["hold", "reverse", "reverse", "idle"],
                                    ["a"], [], ["x", "y", "x", "x", "xy", "xy", "y"],
                                    ["free", "free\x00b", "free\x00b", "free\x00c"]])
def test_block_starts_equal_numpys_comparison(labels):
    for phase in (np.array(labels, dtype=str), np.array(labels, dtype=object)):
        expected = np.concatenate([[0], np.nonzero(phase[1:] != phase[:-1])[0] + 1]) if len(phase) else []
        np.testing.assert_array_equal(block_starts(phase), np.asarray(expected, dtype=np.int64))
    # a long record: every change found, a strided view too
    rng = np.random.default_rng(len(labels))
    phase = np.array(["idle", "free", "hold", "reverse"])[np.repeat(rng.integers(0, 4, size=40), 37)]
    for view in (phase, phase[::3]):
        np.testing.assert_array_equal(block_starts(view), np.concatenate([[0], np.nonzero(view[1:] != view[:-1])[0] + 1]))


def test_value_changes_and_counts_equal_numpys():
    rng = np.random.default_rng(1)
    b = rng.choice([0.0, 1.0, np.nan], size=500)
    changed = (b[1:] != b[:-1]) & ~(np.isnan(b[1:]) & np.isnan(b[:-1]))
    np.testing.assert_array_equal(value_change_starts(b), np.nonzero(changed)[0] + 1)
    mask = rng.random(500) < 0.3
    np.testing.assert_array_equal(true_counts(mask), np.concatenate([[0], np.cumsum(mask)]))
    t = _times(rng, 500)
    t[[50, 51, 300]] += [0.02, 0.03, 1.0]
    t = np.maximum.accumulate(t)
    for longest in (1.5e-3, 5e-3, 10.0):
        np.testing.assert_array_equal(gap_counts(t, longest), np.concatenate([[0], np.cumsum(np.diff(t) > longest)]))


@pytest.mark.parametrize("seed", range(6))
def test_elementwise_scans_equal_numpys(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 900))
    x, t = _series(rng, n, awkward=seed % 2 == 0), _times(rng, n)
    dt = np.diff(t)
    np.testing.assert_array_equal(second_differences(x), np.diff(x, 2))
    np.testing.assert_array_equal(abs_rates(x, dt), np.abs(np.diff(x) / dt))
    for center in (0.0, 0.37):
        np.testing.assert_array_equal(abs_max(x, center), np.max(np.abs(x - center)))
    for limit in (0.0, 1.0, 5.0, np.inf):
        bad = np.abs(x) > limit
        assert first_beyond(x, limit) == (int(np.argmax(bad)) if bad.any() else -1)
    moving = rng.random(n - 1) < 0.7
    for rate in (0.0, 500.0, 5000.0):
        for mask in (None, moving):
            bad = np.abs(np.diff(x)) > rate * dt + 0.01 + 0.003
            if mask is not None:
                bad &= mask
            got = first_step_beyond(x, dt, rate, 0.01, 0.003, np.zeros(0, dtype=bool) if mask is None else mask)
            assert got == (int(np.argmax(bad)) if bad.any() else -1)
    y = _series(rng, n, awkward=False)
    np.testing.assert_array_equal(squared_step_sums(y), np.concatenate([[0.0], np.cumsum(np.diff(y) ** 2)]))


def test_median_abs_deviation_without_a_second_sort():
    rng = np.random.default_rng(7)
    for case in range(400):
        n = int(rng.integers(1, 60))
        x = np.round(rng.normal(size=n) * rng.choice([1.0, 3.0, 50.0])) * 10.0 ** rng.uniform(-8, 2)
        if case % 5 == 0:
            x[rng.integers(0, n)] = rng.choice([np.inf, -np.inf])
        s = np.sort(x)
        m = float(np.median(x))
        if not np.isfinite(m):
            continue
        assert median_abs_deviation_sorted(s, m) == np.median(np.abs(x - m))


def test_motor_work_and_relaxed_current_equal_the_numpy_expressions():
    rng = np.random.default_rng(11)
    n = 700
    t = _times(rng, n)
    i = rng.normal(size=n)
    phi_s, psi_s = np.cumsum(rng.normal(size=n)) * 1e-3, np.cumsum(rng.normal(size=n)) * 1e-2
    psi_s[100:110] = psi_s[100]  # a resting flywheel: omega of zero, no friction
    tau = 1.3e-3
    h = np.diff(t)
    a = np.exp(-h / tau)
    decay = negative_step_ratios(t, tau)
    np.testing.assert_array_equal(decay, -h / tau)
    np.testing.assert_array_equal(np.exp(decay), a)
    i_ss = (i[1:] - a * i[:-1]) / (1.0 - a)
    i_mean = relaxed_interval_means(t, i, a, tau)
    np.testing.assert_array_equal(i_mean, i_ss + (i[:-1] - i[1:]) * tau / h)
    k_t, f_visc, f_coul, w_s = 0.05, 1e-4, 2e-3, 0.01
    for scale in (1.0, 1.013):
        omega = np.diff(psi_s) / h
        torque = k_t * (scale * i_mean) - (f_visc * omega + f_coul * np.tanh(omega / w_s))
        expected = np.concatenate([[0.0], np.cumsum(-torque * np.diff(phi_s))])
        np.testing.assert_array_equal(reaction_work(t, i_mean, scale, phi_s, psi_s, k_t, f_visc, f_coul, w_s),
                                      expected)


def test_bitwise_constant_equals_comparing_the_bits():
    rng = np.random.default_rng(5)
    cases = [np.zeros(0), np.full(1, 3.0), np.full(50, 0.25), np.full(50, np.nan), np.full(7, -0.0),
             np.array([0.0, -0.0, 0.0]), np.array([1.0, 1.0, np.nan]), np.array([np.inf, np.inf]),
             np.full(30, 2.0)[::3], _series(rng, 40), np.r_[np.full(999, 0.5), 0.5 + 1e-16]]
    for x in cases:
        bits = x.view(np.int64)
        assert bitwise_constant(x) == bool(np.all(bits == bits[0]) if len(x) else True), x
