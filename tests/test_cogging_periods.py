"""The cogging fit's one-pass search over periods (identify/cogging_periods.py) against the loop it
replaced: every period's columns built by numpy one at a time, projected, and fitted by a 2-column
``np.linalg.lstsq`` (LAPACK's SVD); the null by ``energy_cogging.drops_beside`` on those columns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from addedinertia_env.identify.cogging_periods import PeriodScan, period_columns
from addedinertia_env.identify.energy_cogging import MIN_CYCLES, MIN_SAMPLES_PER_CYCLE, PERIODS, drops_beside
from addedinertia_env.identify.series_kernels import twice_integrated

J_F = 0.02  # kg m^2, a flywheel's inertia (the columns' scale)


def _series(seed: int, gear: float, true_n: int, amplitude: float):
    """A rotor angle that speeds up, creeps and reverses (1 kHz, 5 s), a balance residual holding a cogging
    of ``true_n`` periods per motor turn plus white noise, and two loss-like columns to project out."""
    rng = np.random.default_rng(seed)
    t = np.arange(5000) * 1e-3
    psi = 0.6 * np.sin(0.7 * t) + 0.15 * t ** 2 - 0.05 * t + 0.01 * rng.standard_normal() * t
    half = 0.5 * np.diff(t)
    dpsi = np.abs(np.diff(psi, append=psi[-1]))

    def twice(x):
        return twice_integrated(np.atleast_2d(x), half).reshape(np.shape(x)) / J_F

    base = np.column_stack([np.ones_like(t), t - t[0], twice(np.tanh(np.gradient(psi, t) / 1e-2))])
    Q, _ = np.linalg.qr(base / np.linalg.norm(base, axis=0))
    m = true_n * gear
    target = amplitude * twice(np.sin(m * psi + 0.4)) + 1e-7 * rng.standard_normal(len(t)) + 1e-4 * t ** 2
    y = target - Q @ (Q.T @ target)
    return psi, dpsi, half, twice, Q, y


def _reference(psi, dpsi, twice, Q, y, gear):
    """The replaced loop (energy_cogging.cogging_fit before): numpy columns and lstsq per period."""
    pairs, drops = {}, {}
    for n in PERIODS:
        m = n * gear
        seen = 1.0 / (1.0 + (m * dpsi * MIN_SAMPLES_PER_CYCLE / (2 * math.pi)) ** 8)
        if float(np.sum(m * dpsi * seen)) / (2 * math.pi) < MIN_CYCLES:
            continue
        C = np.column_stack([twice(seen * np.sin(m * psi)), twice(seen * np.cos(m * psi))])
        C = C - Q @ (Q.T @ C)
        c, *_ = np.linalg.lstsq(C, y, rcond=None)
        f = C @ c
        pairs[n], drops[n] = C, float(f @ f)
    return pairs, drops


@pytest.mark.parametrize("seed,gear,true_n,amplitude", [(0, 5.0, 24, 2e-4), (1, 4.7, 12, 5e-5), (2, 1.0, 36, 0.0)])
def test_every_periods_drop_and_the_null_equal_the_loops_to_rounding(seed, gear, true_n, amplitude):
    psi, dpsi, half, twice, Q, y = _series(seed, gear, true_n, amplitude)
    pairs, ref = _reference(psi, dpsi, twice, Q, y, gear)
    scan = PeriodScan(psi, dpsi, half, J_F, Q, y, gear, PERIODS, MIN_CYCLES, MIN_SAMPLES_PER_CYCLE)
    assert list(scan.drops) == list(ref) and len(ref) >= 20  # the same periods judged, in order
    got = np.array(list(scan.drops.values()))
    want = np.array(list(ref.values()))
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * want.max())
    best = max(ref, key=ref.get)
    assert max(scan.drops, key=scan.drops.get) == best
    if amplitude:
        assert best == true_n  # the planted cogging stands out, so the comparison is not of noise alone
    want_null = np.array(drops_beside(pairs, y, best))
    got_null = np.array(scan.null_drops(best))
    np.testing.assert_allclose(got_null, want_null, rtol=1e-8, atol=1e-12 * want.max())


def test_the_columns_are_the_twice_integrated_tapered_sines():
    """period_columns' pairs and seen cycles against numpy (sin, cos of m psi; twice_integrated)."""
    psi, dpsi, half, twice, _, _ = _series(3, 5.4, 24, 1e-4)
    ns = np.arange(4, 40)
    X, cycles = period_columns(psi, dpsi, 5.4, ns, half, J_F, float(MIN_SAMPLES_PER_CYCLE))
    for k, n in enumerate(ns):
        m = n * 5.4
        seen = 1.0 / (1.0 + (m * dpsi * MIN_SAMPLES_PER_CYCLE / (2 * math.pi)) ** 8)
        scale = np.abs(twice(np.ones_like(psi))).max()
        np.testing.assert_allclose(X[:, k], twice(seen * np.sin(m * psi)), rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(X[:, len(ns) + k], twice(seen * np.cos(m * psi)), rtol=0, atol=1e-11 * scale)
        assert cycles[k] == pytest.approx(float(np.sum(m * dpsi * seen)) / (2 * math.pi), rel=1e-12)


def test_a_dependent_pair_falls_back_to_lstsq():
    """A pair whose columns are parallel (sine and cosine alike) is fitted as lstsq fits it: one direction."""
    from addedinertia_env.identify.cogging_periods import _drops  # noqa: PLC0415

    rng = np.random.default_rng(4)
    u = rng.standard_normal(300)
    y = rng.standard_normal(300)
    X = np.column_stack([u, u, 2 * u, rng.standard_normal(300)])  # pairs (columns k, K + k): (u, 2u), (u, noise)
    B = np.zeros((300, 0))
    d = _drops(X, B, y, np.array([0, 1]))
    assert d[0] == pytest.approx((u @ y) ** 2 / (u @ u), rel=1e-12)
    C = X[:, [1, 3]]
    f = C @ np.linalg.lstsq(C, y, rcond=None)[0]
    assert d[1] == pytest.approx(f @ f, rel=1e-10)
