"""The flywheel calibration's own per-run 1-sigma (issue 26; ``energy_calibration.calibration_sigma``).

A synthetic flywheel balance ``J_f theta'' = s k_t i(t - lag)`` driven by a fast-changing current (so that the
lag is pinned), integrated finely and sampled; the logged current carries white noise and the angle a white
read-out noise, both of known size. Over many noise draws the scale's and the lag's scatter must match the
sigmas the calibration reports from one record: the current's noise enters the fit's columns (errors in
variables) and is twice integrated, so a sigma read from the residuals as if white (or with any short bandwidth)
falls several times short, and a scale read without the lag's trade falls short where the two trade; counted
in both (the residuals' HAC without its noise share taken out) it comes out about 20 % wide.
"""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.identify.energy_calibration import CALIBRATION_MODEL_ERROR, flywheel_calibration
from addedinertia_env.identify.series_kernels import twice_integrated

FS, SUB = 1000.0, 20  # samples per second; integration steps per sample
J_F, K_T, SCALE, LAG = 0.19, 0.28, 1.0 / 1.002, 1.5e-4  # kg m^2, N m / A, torque per logged ampere, s


def _current(t: np.ndarray) -> np.ndarray:
    """A feedback controller's busy current (A): slow swings with fast ripple, fixed for every draw."""
    return (1.2 * np.sin(2 * np.pi * 0.7 * t) + 0.5 * np.sin(2 * np.pi * 9.3 * t + 0.4)
            + 0.25 * np.sin(2 * np.pi * 23.0 * t + 1.1) + 0.1 * np.sign(np.sin(2 * np.pi * 4.1 * t)))


def _clean_record(seconds: float = 2.5):
    """Sample times, the flywheel's true angle and the true current at the samples."""
    fine = np.arange(int(seconds * FS * SUB) + 1) / (FS * SUB)
    torque = SCALE * K_T * _current(fine - LAG) / J_F  # the logged current is the true one, late by LAG
    theta_fine = twice_integrated(torque[None, :], np.full(len(fine) - 1, 0.5 / (FS * SUB)))[0]
    t = fine[::SUB]
    return t, theta_fine[::SUB], _current(t)


@pytest.mark.parametrize("noise_i, noise_theta", [(0.01, 2e-6), (0.003, 2e-5)])
def test_calibration_sigma_matches_the_scatter_over_noise_draws(noise_i, noise_theta):
    t, theta, i_true = _clean_record()
    rng = np.random.default_rng(11)
    a, b = 20, len(t) - 21
    scales, lags, sigmas, lag_sigmas, white = [], [], [], [], []
    for _ in range(120):
        i = i_true + noise_i * rng.standard_normal(len(t))
        th = theta + noise_theta * rng.standard_normal(len(t))
        got = flywheel_calibration(t, th, th, i, a, b, J_F, K_T, 0.0, 0.0, noise_i=noise_i)
        assert got is not None
        scales.append(got.scale)
        lags.append(got.lag)
        # the fit's own sigma (the model's error, CALIBRATION_MODEL_ERROR, is beside it in ``sigma``; this
        # record has none: the model is exact here)
        sigmas.append(np.hypot(got.sigma_current, got.sigma_residual))
        assert got.sigma == pytest.approx(np.hypot(sigmas[-1], CALIBRATION_MODEL_ERROR), rel=1e-12)
        lag_sigmas.append(got.sigma_lag)
        white.append(got.sigma_residual)
    scales, lags = np.array(scales), np.array(lags)
    spread, lag_spread = scales.std(ddof=1), lags.std(ddof=1)
    # 120 draws: the sample sd is within about +-13 % (2 sd) of the true scatter
    assert np.median(sigmas) == pytest.approx(spread, rel=0.25), (np.median(sigmas), spread)
    assert np.median(lag_sigmas) == pytest.approx(lag_spread, rel=0.3), (np.median(lag_sigmas), lag_spread)
    # the scale is unbiased to its own scatter (the fine integration against the fit's trapezoid is far below it)
    assert abs(scales.mean() - SCALE) < 4.0 * spread / np.sqrt(len(scales)) + 2e-6, (scales.mean() - SCALE, spread)
    if noise_i * K_T / J_F > 100 * noise_theta:  # the current's noise dominates: the residuals alone miss it
        assert np.median(white) < 0.5 * spread


def test_the_double_integrals_adjoint_is_its_transpose():
    """The current's share is carried through ``T^T`` (the double trapezoid's adjoint): on an uneven grid it must
    equal the transpose of ``T`` built column by column."""
    from addedinertia_env.identify.energy_calibration import _twice_adjoint

    rng = np.random.default_rng(3)
    m = 40
    half = 0.5 * rng.uniform(0.5e-3, 1.5e-3, m - 1)
    T = np.column_stack([twice_integrated(np.eye(m)[j][None, :], half)[0] for j in range(m)])
    g = rng.standard_normal(m)
    np.testing.assert_allclose(_twice_adjoint(g, half), T.T @ g, rtol=1e-12, atol=1e-18)
