"""The re-quantisation report's pieces: an encoder read again, a smoothed stroke, the calibration summary."""

import numpy as np

from addedinertia_env.reports.lab_requantise import requantise, smooth_angle, summary

Q = 2 * np.pi / 131072


def test_requantise_reads_a_shifted_grid_within_half_a_count():
    angle = np.linspace(-0.08, 0.08, 20001)
    for offset in (0.0, 0.3, 0.77):
        read = requantise(angle, Q, offset)
        counts = read / Q + offset
        assert np.allclose(counts, np.round(counts), atol=1e-6)
        err = (read - angle) / Q
        assert np.abs(err).max() <= 0.5 + 1e-9
        assert abs(err.mean()) < 0.02 and abs(err.std() - 1 / np.sqrt(12)) < 0.02  # uniform over a count


def test_smoothed_stroke_follows_the_true_angle_and_braked_phases_continue_it():
    t = np.arange(0, 3.0, 1e-3)
    truth = 0.08 * np.cos(2.4 * t)
    phase = np.where(t < 0.5, "idle", "free")
    truth[t < 0.5] = truth[t >= 0.5][0]  # braked before the release
    smooth = smooth_angle(requantise(truth, Q, 0.0), phase, Q)
    moving = phase == "free"
    assert np.sqrt(np.mean(((smooth - truth)[moving] / Q) ** 2)) < 0.15  # well under the reading's 0.29 count
    assert np.all(smooth[~moving] == smooth[np.argmax(moving)])


def test_summary_of_gaussian_errors_is_calibrated():
    rng = np.random.default_rng(3)
    sigma = rng.uniform(0.5, 2.0, 20000)
    s = summary(sigma * rng.standard_normal(sigma.size), sigma)
    assert abs(s["covered"] - 0.95) < 0.01
    assert abs(s["median_abs_z"] - 0.674) < 0.02 and abs(s["rms_z"] - 1.0) < 0.02
    wide = summary(0.5 * sigma * rng.standard_normal(sigma.size), sigma)  # a budget twice the error
    assert wide["rms_z"] < 0.55 and wide["covered"] > 0.99


def test_small_sample_ratio_spreads_around_the_pooled_one():
    from addedinertia_env.reports.lab_requantise import small_sample_ratios

    rng = np.random.default_rng(5)
    sigma = np.ones(4000)
    r = small_sample_ratios(sigma * rng.standard_normal(sigma.size), sigma, 8, 4, draws=4000)
    assert 2.6 < np.median(r) < 3.3  # 1.96 / 0.674 for Gaussian errors
    assert np.percentile(r, 95) > 1.5 * np.percentile(r, 5)  # a dozen runs pin a median ratio loosely
