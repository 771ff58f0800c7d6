"""The free stroke's law (experiment/reference.py) against numpy's least-squares Chebyshev fits."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import chebyshev as C

from addedinertia_env.experiment.reference import chebyshev_derivative, fit_stroke


def _decaying_stroke(seed: int):
    """A damped half swing sampled at 1 kHz from its fastest point to just past its stop, quantised (17 bits)."""
    rng = np.random.default_rng(seed)
    period, amp, decay = rng.uniform(2.5, 5.0), rng.uniform(0.05, 0.15), rng.uniform(0.02, 0.2)
    w = 2 * np.pi / period
    t = np.arange(0.0, period / 2 + 0.05, 1e-3)
    phi = amp * np.exp(-decay * t) * np.sin(w * t)
    q = 2 * np.pi / 2**17
    return t, np.round(phi / q) * q, period


@pytest.mark.parametrize("seed", range(6))
def test_law_is_the_least_squares_fit_re_expressed_on_its_own_span(seed):
    t, phi, period = _decaying_stroke(seed)
    t_brake = period / 4 + 0.01  # just past the stop
    law = fit_stroke(t, phi, 0.0, t_brake)
    sel = t <= t_brake
    ts, ps = t[sel], phi[sel]
    a, b = ts[0], ts[-1]
    coef = C.chebfit((2 * ts - (a + b)) / (b - a), ps, 11)  # numpy's fit on the whole span
    rate = C.chebval((2 * law.t_stop - (a + b)) / (b - a), C.chebder(coef)) * 2 / (b - a)
    assert abs(rate) < 1e-6 * np.max(np.abs(np.diff(ps))) / 1e-3  # the stop is where the fitted rate vanishes
    assert a + 0.8 * (b - a) <= law.t_stop <= b
    # the law on [a, t_stop] is that polynomial (numpy's least-squares re-fit of it, as the law was made before)
    keep = ts <= law.t_stop
    refit = C.chebfit((2 * ts[keep] - (a + law.t_stop)) / (law.t_stop - a),
                      C.chebval((2 * ts[keep] - (a + b)) / (b - a), coef), 11)
    np.testing.assert_allclose(law.coef, refit, rtol=0, atol=1e-12 * np.max(np.abs(refit)))
    np.testing.assert_allclose(law.phi(ts[keep]), C.chebval((2 * ts[keep] - (a + b)) / (b - a), coef),
                               rtol=0, atol=1e-13)


def test_chebyshev_derivative_equals_numpys():
    rng = np.random.default_rng(0)
    for n in range(1, 16):
        for _ in range(50):
            c = rng.normal(size=n) * 10.0 ** rng.uniform(-6, 3, size=n)
            np.testing.assert_array_equal(chebyshev_derivative(c), C.chebder(c))
            np.testing.assert_array_equal(chebyshev_derivative(chebyshev_derivative(c)), C.chebder(c, 2))


def _numpy_fit_stroke(t, phi, t_start, t_stop_guess, degree=11):
    """fit_stroke written with numpy's Chebyshev functions only (what the compiled pieces must equal)."""
    sel = (t >= t_start) & (t <= t_stop_guess)
    ts, ps = t[sel], phi[sel]
    a, b = ts[0], ts[-1]
    x = (2.0 * ts - (a + b)) / (b - a)
    coef = C.chebfit(x, ps, degree)
    rms = float(np.sqrt(np.mean((C.chebval(x, coef) - ps) ** 2)))
    tt = np.linspace(a + 0.8 * (b - a), b, 2001)
    rr = C.chebval((2.0 * tt - (a + b)) / (b - a), C.chebder(coef)) * (2.0 / (b - a))
    change = np.nonzero(np.signbit(rr[:-1]) != np.signbit(rr[1:]))[0]
    if len(change):
        k = change[-1]
        t_stop = float(tt[k] - rr[k] * (tt[k + 1] - tt[k]) / (rr[k + 1] - rr[k]))
    else:
        t_stop = float(tt[np.argmin(np.abs(rr))])
    coef_new = C.chebinterpolate(
        lambda xn: C.chebval((2.0 * (a + 0.5 * (xn + 1.0) * (t_stop - a)) - (a + b)) / (b - a), coef), degree)
    return coef_new, a, t_stop, rms


@pytest.mark.parametrize("seed", range(40))
def test_fit_stroke_equals_numpys_chebyshev_functions_bit_for_bit(seed):
    t, phi, period = _decaying_stroke(seed)
    rng = np.random.default_rng(100 + seed)
    phi = phi + rng.normal(0.0, 1e-5, len(phi)) * (seed % 2)  # half of them noisy
    t_start, t_brake = rng.uniform(0.0, 0.05), period / 4 + rng.uniform(-0.05, 0.05)  # some stop past the window
    law = fit_stroke(t, phi, t_start, t_brake)
    coef, a, t_stop, rms = _numpy_fit_stroke(t, phi, t_start, t_brake)
    np.testing.assert_array_equal(law.coef, coef)
    assert (law.t_start, law.t_stop, law.fit_rms) == (a, t_stop, rms)
