"""The compiled series kernels (addedinertia_env/identify/series_kernels.py) against independent references:
numpy's own routines, written out here the way the identification computed them before."""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.identify.series_kernels import (
    count_crossings,
    fit_windows,
    gradient,
    is_ascending,
    lag_ranking,
    polynomial_roots_near_zero,
    scaled_deviation,
    twice_integrated,
)
from addedinertia_env.records.series_stats import median, median_step, quantile


def _twice_by_cumsum(x, half_dt):
    out = x
    for _ in range(2):
        step = (out[..., 1:] + out[..., :-1]) * half_dt
        nxt = np.empty(x.shape)
        nxt[..., 0] = 0.0
        np.cumsum(step, axis=-1, out=nxt[..., 1:])
        out = nxt
    return out


@pytest.mark.parametrize("rows, m", [(1, 2), (1, 500), (16, 3001), (3, 7)])
def test_twice_integrated_equals_two_cumulative_trapezoids(rows, m):
    rng = np.random.default_rng(m)
    t = np.cumsum(1e-3 * (1.0 + 0.3 * rng.random(m)))
    x = rng.normal(size=(rows, m)) * 10.0 ** rng.uniform(-3, 3, size=(rows, 1))
    half_dt = 0.5 * np.diff(t)
    np.testing.assert_array_equal(twice_integrated(x, half_dt), _twice_by_cumsum(x, half_dt))
    # and it is the double integral: of a constant 1 it is t^2 / 2 (the trapezoid is exact for it)
    ones = twice_integrated(np.ones((1, m)), half_dt)[0]
    np.testing.assert_allclose(ones, 0.5 * (t - t[0]) ** 2, rtol=1e-12, atol=1e-18)


def test_fit_windows_equal_the_plain_test():
    rng = np.random.default_rng(3)
    for case in range(300):
        n = int(rng.integers(1, 400))
        t = np.cumsum(rng.choice([0.0, 1e-3, 1e-3, 1e-3, 2.5e-3, 0.05], size=n) + rng.normal(size=n) * 1e-6 * (case % 2))
        t = np.maximum.accumulate(t)
        tc = np.concatenate([t[rng.integers(0, n, size=5)], rng.uniform(t[0] - 0.2, t[-1] + 0.2, size=3)])
        h = float(rng.choice([0.0, 1e-3, 0.01, 0.1]))
        first, stop = fit_windows(t, tc, h)
        for j, c in enumerate(tc):
            sel = np.nonzero(np.abs(t - c) <= h)[0]
            if len(sel):
                assert (first[j], stop[j]) == (sel[0], sel[-1] + 1)
            else:
                assert stop[j] == first[j]


def _polyval_rows(coef, x):
    out = coef[:, -1] + x * 0
    for j in range(2, coef.shape[1] + 1):
        out = coef[:, -j] + out * x
    return out


def test_newton_roots_equal_the_vectorised_iteration_and_the_roots():
    rng = np.random.default_rng(5)
    rows = 400
    coef = rng.normal(size=(rows, 6)) * [1.0, 1.0, 0.3, 0.1, 0.05, 0.02]
    coef[:, 1] = np.where(np.abs(coef[:, 1]) < 0.3, 0.3, coef[:, 1])  # a slope that a root near 0 needs
    levels = coef[:, 0] + rng.uniform(-0.2, 0.2, size=rows) * coef[:, 1]
    dcoef = coef[:, 1:] * np.arange(1, 6)
    x = np.zeros(rows)
    for _ in range(8):  # the iteration as crossing_fits ran it on every row at once
        x_next = x - (_polyval_rows(coef, x) - levels) / _polyval_rows(dcoef, x)
        if np.array_equal(x_next, x):
            break
        x = x_next
    got = polynomial_roots_near_zero(coef, dcoef, levels, 8)
    np.testing.assert_array_equal(got, x)
    converged = np.abs(_polyval_rows(coef, got) - levels) < 1e-12
    assert converged.mean() > 0.9  # a few random polynomials send Newton away in 8 steps
    for j in np.nonzero(converged)[0]:  # a root of p(x) - level (numpy's companion-matrix roots)
        roots = np.polynomial.Polynomial(coef[j] - np.r_[levels[j], 0, 0, 0, 0, 0]).roots()
        real = roots[np.abs(roots.imag) < 1e-6].real
        assert np.min(np.abs(real - got[j])) < 1e-9


@pytest.mark.parametrize("n", [1, 2, 3, 4, 101, 1000, 5001])
def test_median_equals_numpys(n):
    rng = np.random.default_rng(n)
    for x in (rng.normal(size=n), np.round(rng.normal(size=n), 1), np.full(n, 0.25)):
        assert median(x) == np.median(x)
        if n >= 2:
            assert median_step(np.cumsum(x)) == np.median(np.diff(np.cumsum(x)))
    x = rng.normal(size=n)
    x[n // 2] = np.nan
    assert np.isnan(median(x)) and np.isnan(np.median(x))


@pytest.mark.parametrize("n", [1, 2, 3, 100, 1001, 5000])
def test_quantile_equals_numpys(n):
    rng = np.random.default_rng(n + 7)
    for q in (0.0, 0.01, 0.5, 0.9, 0.99, 0.995, 1.0):
        for x in (np.abs(rng.normal(size=n)) * 10.0 ** rng.uniform(-3, 3), np.round(rng.normal(size=n), 1),
                  np.full(n, 1.5)):
            assert quantile(x, q) == np.quantile(x, q)
    x = rng.normal(size=n)
    x[0] = np.nan
    assert np.isnan(quantile(x, 0.99)) and np.isnan(np.quantile(x, 0.99))


def test_gradient_equals_numpys():
    rng = np.random.default_rng(11)
    for n in (2, 3, 4, 50, 3001):
        f = np.cumsum(rng.normal(size=n))
        for x in (np.arange(n) * 1e-3, np.cumsum(1e-3 * (1 + 0.2 * rng.random(n))),
                  np.cumsum(np.where(rng.random(n) < 0.01, 5e-3, 1e-3))):
            np.testing.assert_array_equal(gradient(f, x), np.gradient(f, x))


def test_lag_ranking_equals_the_numpy_expressions():
    rng = np.random.default_rng(13)
    for case in range(50):
        shifts, m = 17, 200
        base = rng.normal(size=(shifts, m)) * (1.0 if case % 5 else 0.0)  # all-zero rows: z.z = 0
        y = rng.normal(size=m)
        lags = np.arange(57)
        steps = lags * (shifts - 2) / 56.0
        k = np.floor(steps + 1e-9).astype(np.int64)
        frac = np.clip(steps - k, 0.0, 1.0)
        by, gram, yy = base @ y, base @ base.T, float(y @ y)
        if case % 7 == 0:  # a tie at the smallest bound
            by[:] = by[0]
        rss, rows = lag_ranking(by, gram, k, frac, yy)
        g = 1.0 - frac
        zy = g * by[k] + frac * by[k + 1]
        zz = g * g * gram[k, k] + 2.0 * g * frac * gram[k, k + 1] + frac * frac * gram[k + 1, k + 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = yy - np.where(zz > 0, zy * zy / zz, 0.0)
        tol = 1e-9 * yy
        near = np.nonzero(bound <= np.min(bound) + tol)[0]
        expect_rows = np.unique(np.clip(np.concatenate([near - 1, near, near + 1]), 0, len(lags) - 1))
        np.testing.assert_array_equal(rows, expect_rows)
        np.testing.assert_array_equal(rss, bound + 2.0 * tol + (np.max(bound) - np.min(bound)))


def test_scaled_deviation_equals_the_array_expression():
    rng = np.random.default_rng(17)
    for case in range(100):
        n = 600
        t = np.cumsum(np.full(n, 1e-3) + (rng.normal(size=n) * 1e-9 if case % 2 else 0.0))
        m = int(rng.integers(5, 200))
        first = rng.integers(0, n - m, size=int(rng.integers(1, 20)))
        tc = t[first + m // 2]
        h = 0.1
        x = (t[first[:, None] + np.arange(m)[None, :]] - tc[:, None]) / h
        canonical = np.round(x[0] * 2.0**40) / 2.0**40
        assert scaled_deviation(t, first, tc, h, canonical) == np.max(np.abs(x - canonical))


def test_order_check_equals_numpys():
    for t in (np.arange(10.0), np.array([0.0, 1.0, 1.0, 2.0]), np.array([0.0, 2.0, 1.0]), np.array([0.0, np.nan]),
              np.array([3.0])):
        assert is_ascending(t) == bool(np.all(np.diff(t) >= 0))


def _crossings_by_numpy(t, phi, a, b, k, q):
    """The rest-angle fit's crossing instants and levels as energy_rest.crossings_fit computed them with numpy."""
    d = np.diff(phi[a:b + 1])
    steps = np.nonzero(d != 0)[0]
    n = np.maximum(1, np.round(np.abs(d[steps]) / q)).astype(np.int64)
    if int(n.sum()) < 4:
        return np.empty(0), np.empty(0)
    j = np.repeat(steps, n)
    n_j = np.repeat(n, n).astype(float)
    m = np.arange(len(j)) - np.repeat(np.cumsum(n) - n, n)
    t0, t1 = t[a + j], t[a + j + 1]
    times = t0 + (m + 0.5) / n_j * (t1 - t0)
    levels = phi[a + j] + np.sign(d[j]) * (m + 0.5) * q
    return times - t[k], levels


def test_count_crossings_equal_the_numpy_expressions():
    rng = np.random.default_rng(23)
    q = 2 * np.pi / 2**17
    for case in range(300):
        n = int(rng.integers(2, 200))
        t = np.cumsum(1e-3 + rng.normal(size=n) * 1e-7 * (case % 2))
        rate = rng.normal() * 10.0 ** rng.uniform(-4, -1)
        phi = np.round((0.1 + rate * t + rng.normal(size=n) * q * (case % 3)) / q) * q
        a = int(rng.integers(0, n - 1))
        b = int(rng.integers(a, n))
        k = a if case % 2 else b
        got, expect = count_crossings(t, phi, a, b, k, q), _crossings_by_numpy(t, phi, a, b, k, q)
        np.testing.assert_array_equal(got[0], expect[0])
        np.testing.assert_array_equal(got[1], expect[1])


def test_crossing_search_equals_the_running_maximum_search():
    from addedinertia_env.identify.series_kernels import first_at_or_past  # noqa: PLC0415

    rng = np.random.default_rng(13)
    for case in range(200):
        n = int(rng.integers(2, 300))
        phi = np.round(np.cumsum(rng.normal(size=n + 10)) * 20.0) / 20.0
        a, direction = int(rng.integers(0, 10)), float(rng.choice([-1.0, 1.0]))
        levels = rng.uniform(phi.min() - 0.5, phi.max() + 0.5, size=int(rng.integers(0, 12)))
        levels = np.concatenate([levels, phi[rng.integers(0, n + 10, size=3)]])  # levels hit exactly
        x = direction * phi[a:a + n]
        top = np.maximum.accumulate(x)
        target = direction * levels
        i = np.searchsorted(top, target, side="left")
        out, reached, ok = first_at_or_past(phi, a, a + n, a, direction, levels)
        assert ok
        np.testing.assert_array_equal(out, np.where(i < n, a + i, -1))
        np.testing.assert_array_equal(reached, x[0] >= target)
    phi[3] = np.nan
    assert not first_at_or_past(phi, 0, 10, 0, 1.0, np.zeros(2))[2]


def test_accumulated_kernels_equal_bincount():
    from addedinertia_env.identify.series_kernels import accumulated_kernels  # noqa: PLC0415

    rng = np.random.default_rng(17)
    lengths = rng.integers(1, 40, size=30)
    starts = rng.integers(0, 500, size=30)
    idx = np.concatenate([s + np.arange(m) for s, m in zip(starts, lengths)])
    kern = rng.normal(size=len(idx))
    factors = rng.normal(size=30) * 10.0 ** rng.uniform(-3, 3, size=30)
    expected = np.bincount(idx, weights=np.repeat(factors, lengths) * kern, minlength=520)
    np.testing.assert_array_equal(accumulated_kernels(idx, kern, lengths, factors, 520), expected)
    with pytest.raises(ValueError, match="negative"):
        accumulated_kernels(idx - 600, kern, lengths, factors, 520)


def test_accumulated_windows_equal_accumulated_kernels():
    from addedinertia_env.identify.series_kernels import accumulated_kernels, accumulated_windows  # noqa: PLC0415

    rng = np.random.default_rng(18)
    sizes = rng.integers(0, 40, size=30)
    first = rng.integers(0, 500, size=30)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    weights = rng.normal(size=int(sizes.sum()))
    fits = rng.permutation(30)[:24]  # a subset, in another order
    factors = rng.normal(size=24) * 10.0 ** rng.uniform(-3, 3, size=24)
    idx = np.concatenate([first[f] + np.arange(sizes[f]) for f in fits])
    kern = np.concatenate([weights[offsets[f]:offsets[f] + sizes[f]] for f in fits])
    expected = accumulated_kernels(idx, kern, sizes[fits], factors, 520)
    np.testing.assert_array_equal(accumulated_windows(first, sizes, offsets, weights, fits, factors, 520), expected)
    np.testing.assert_array_equal(expected, np.bincount(idx, weights=np.repeat(factors, sizes[fits]) * kern,
                                                        minlength=520))
    np.testing.assert_array_equal(accumulated_windows(first, sizes, offsets, weights, fits[:0], factors[:0], 520),
                                  np.zeros(520))
    with pytest.raises(ValueError, match="negative"):
        accumulated_windows(first - 600, sizes, offsets, weights, fits, factors, 520)


def test_place_rows_equals_fancy_assignment():
    from addedinertia_env.identify.series_kernels import place_rows  # noqa: PLC0415

    rng = np.random.default_rng(20)
    rows = rng.normal(size=(6, 9))
    offsets = np.array([40, 0, 9, 25, 60, 18])
    expected, got = np.full(80, np.nan), np.full(80, np.nan)
    expected[offsets[:, None] + np.arange(9)] = rows
    place_rows(got, offsets, rows)
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("even", [True, False])
def test_calibration_target_equals_the_numpy_expressions(even):
    from addedinertia_env.identify.series_kernels import calibration_target  # noqa: PLC0415

    rng = np.random.default_rng(19)
    m = 1500
    tt = 2.0 + np.arange(m) * 1e-3 if even else np.cumsum(1e-3 * (1.0 + 0.05 * rng.random(m)))
    psi = np.cumsum(rng.normal(size=m)) * 1e-3
    psi[200:260] = psi[200]  # a flywheel at rest: no friction
    th = rng.normal(size=m)
    f_visc, f_coul, J_f, w_s = 2e-4, 3e-3, 1.7e-3, 0.01
    om = gradient(psi, tt)
    friction = f_visc * om + f_coul * np.tanh(om / w_s)
    half = 0.5 * np.diff(tt)
    target, got_half = calibration_target(tt, th, psi, f_visc, f_coul, J_f, w_s)
    np.testing.assert_array_equal(got_half, half)
    # tanh: the C library's in the kernel, numpy's own (SIMD) here; they may differ in the last place
    np.testing.assert_allclose(target, th + twice_integrated(np.atleast_2d(friction), half)[0] / J_f,
                               rtol=1e-13, atol=1e-15)
