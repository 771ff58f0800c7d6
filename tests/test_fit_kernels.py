"""identify/fit_kernels.py against the numpy code each kernel replaced (to float rounding)."""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.identify import crossings
from addedinertia_env.identify.fit_kernels import line_basis, lstsq, project_out_line


def test_lstsq_equals_numpys_and_falls_back_on_rank_deficient_designs():
    rng = np.random.default_rng(3)
    for _ in range(200):
        m, n = int(rng.integers(3, 300)), int(rng.integers(1, 4))
        if m < n:
            continue
        A = rng.normal(size=(m, n)) * 10.0 ** rng.uniform(-3, 3, size=n)
        b = rng.normal(size=m)
        want = np.linalg.lstsq(A, b, rcond=None)[0]
        got, _, rank, _ = lstsq(A, b, rcond=None)
        assert rank == n
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-13 * np.max(np.abs(want)))
    A = np.column_stack([np.ones(6), np.ones(6)])  # rank 1: numpy's answer, rank and all
    b = np.arange(6.0)
    got, want = lstsq(A, b, rcond=None), np.linalg.lstsq(A, b, rcond=None)
    assert got[2] == want[2] == 1
    np.testing.assert_array_equal(got[0], want[0])


def test_projection_equals_the_qr_projection():
    rng = np.random.default_rng(5)
    tt = np.cumsum(rng.uniform(0.9e-3, 1.1e-3, 700))
    x = rng.normal(size=(5, 700)) + 3.0 + 40.0 * (tt - tt[0])[None, :]
    Q, _ = np.linalg.qr(np.column_stack([np.ones_like(tt), tt - tt[0]]))
    want = x.copy()
    for _ in range(2):
        want = want - (want @ Q) @ Q.T
    basis = line_basis(tt)
    np.testing.assert_allclose(basis.T @ basis, np.eye(2), atol=1e-13)  # orthonormal
    np.testing.assert_allclose(basis @ (basis.T @ Q), Q, atol=1e-12)  # the span of (1, tt - tt[0])
    got = project_out_line(x, basis)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(x)))
    np.testing.assert_allclose(got @ Q, 0.0, atol=1e-10)  # nothing of the line is left


@pytest.mark.parametrize("degree", [2, 5])
def test_compiled_crossing_fits_equal_the_numpy_path(monkeypatch, degree):
    """crossing_fits on an evenly sampled stroke (one compiled pass per group) against its numpy path
    (taken when the compiled one is refused): times, rates, sigmas and kernels to float rounding."""
    t = np.arange(4000) * 1e-3
    rng = np.random.default_rng(7)
    q = 2 * np.pi / 2**17
    phi = np.round((0.3 * np.sin(1.3 * t) + 1e-6 * rng.normal(size=t.size)) / q) * q
    levels = np.linspace(0.03, 0.28, 41)
    ks = crossings.first_crossings(phi, 0, 1200, levels, 1.0)
    assert np.all(ks > 0)
    original, used = crossings._fused_fits, []
    monkeypatch.setattr(crossings, "_fused_fits", lambda *args: used.append(original(*args)) or used[-1])
    fast = crossings.crossing_fits(t, phi, ks, levels, 0.0505, degree)
    assert used and used[0] is not None, "an evenly sampled stroke takes the compiled pass"
    monkeypatch.setattr(crossings, "_fused_fits", lambda *args: None)
    slow = crossings.crossing_fits(t, phi, ks, levels, 0.0505, degree)
    for key in ("t", "rate", "sigma_rate"):
        np.testing.assert_allclose(fast[key], slow[key], rtol=1e-10, err_msg=key)
    for (i1, w1), (i2, w2) in zip(fast["kernel"], slow["kernel"]):
        np.testing.assert_array_equal(i1, i2)
        np.testing.assert_allclose(w1, w2, rtol=1e-9, atol=1e-9 * np.max(np.abs(w2)))
