"""Averaging over model families (identify/model_average.py): Akaike weights and the mixture's interval."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from addedinertia_env.identify.model_average import akaike_weights, mixture_interval, unconditional_sigma


def test_akaike_weights_count_the_evidence_and_the_parameters():
    # equal fits, equal sizes: equal weights; one parameter more at the same residual costs a factor e
    assert akaike_weights([2.0, 2.0], [3, 3], 30) == pytest.approx([0.5, 0.5])
    w = akaike_weights([2.0, 2.0], [3, 4], 30)
    assert w[0] / w[1] == pytest.approx(math.e)
    # the same residual ratio weighs more with more independent evidence
    few, many = akaike_weights([1.0, 1.05], [3, 3], 10), akaike_weights([1.0, 1.05], [3, 3], 300)
    assert few[1] / few[0] == pytest.approx(1.05 ** -5)
    assert many[1] < few[1] and many[1] / many[0] == pytest.approx(1.05 ** -150)


def test_akaike_weights_refuse_bad_input():
    with pytest.raises(ValueError, match="rss must be finite and positive"):
        akaike_weights([1.0, 0.0], [1, 2], 10)
    with pytest.raises(ValueError, match="same|one non-zero length"):
        akaike_weights([1.0], [1, 2], 10)


def test_one_family_gives_its_own_normal_interval():
    lo, hi = mixture_interval([10.0], [0.2], [1.0])
    assert lo == pytest.approx(10.0 - stats.norm.ppf(0.975) * 0.2, rel=1e-9)
    assert hi == pytest.approx(10.0 + stats.norm.ppf(0.975) * 0.2, rel=1e-9)


def test_mixture_interval_is_its_distributions_central_95_percent():
    # drawn from the mixture, 95 % of the draws fall inside (Monte Carlo, 200 000 draws)
    x, s, w = np.array([1.0, 1.3, 0.7]), np.array([0.05, 0.1, 0.02]), np.array([0.6, 0.3, 0.1])
    lo, hi = mixture_interval(x, s, w)
    rng = np.random.default_rng(1)
    k = rng.choice(3, size=200_000, p=w)
    draws = rng.normal(x[k], s[k])
    assert np.mean((draws >= lo) & (draws <= hi)) == pytest.approx(0.95, abs=0.003)
    assert np.mean(draws < lo) == pytest.approx(0.025, abs=0.002)


def test_a_far_family_of_small_weight_widens_less_than_the_union():
    # the union takes the far family whole; the mixture by its weight's worth
    x, s = np.array([1.0, 1.5]), np.array([0.01, 0.01])
    lo, hi = mixture_interval(x, s, np.array([0.99, 0.01]))
    assert hi < 1.5 - 1.96 * 0.01 and lo == pytest.approx(1.0 - 1.96 * 0.01, abs=2e-3)
    lo2, hi2 = mixture_interval(x, s, np.array([0.5, 0.5]))
    assert hi2 > 1.5  # with half the weight it is held
    assert unconditional_sigma(x, s, [0.5, 0.5]) == pytest.approx(math.sqrt(0.01**2 + 0.25**2))
