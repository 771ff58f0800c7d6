"""The record's compiled loops (record_kernels.py, and the series behind StrokeLaw) against the numpy
expressions they stand for, value for value."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev as C

from addedinertia_env.experiment.reference import fit_stroke, series
from addedinertia_env.metrics import electric_energy
from addedinertia_env.record import RunRecord
from addedinertia_env.record_kernels import phase_mask

NAMES = ("idle", "free", "hold", "reverse")


def test_phase_mask_equals_numpys_comparisons():
    rng = np.random.default_rng(0)
    words = ["hold", "reverse", "free", "idle", "tail", "", "hol", "holdx", "reverse", "Hold", "h\u00f6ld"]
    for width in (1, 3, 4, 7, 9):
        phase = np.array(rng.choice(words, 500).tolist(), dtype=f"<U{width}")  # truncated to the width
        for names in (("hold", "reverse"), ("reverse",), ("free", "idle", "hold"), ("",), ("holdx", "tail")):
            expected = phase == names[0]
            for name in names[1:]:
                expected = expected | (phase == name)
            assert np.array_equal(phase_mask(phase, names), expected)
            assert np.array_equal(phase_mask(phase[::3], names), expected[::3])  # a strided view
    text = np.array(rng.choice(words, 50).tolist(), dtype=object)  # other dtypes: numpy's own comparison
    assert np.array_equal(phase_mask(text, ("hold", "reverse")), (text == "hold") | (text == "reverse"))


def test_electric_energy_equals_the_numpy_integral():
    rng = np.random.default_rng(1)
    n = 3001
    t = np.cumsum(rng.uniform(0.9e-3, 1.1e-3, n))
    u, i = rng.normal(size=n) * 5, rng.normal(size=n)
    phase = np.array(rng.choice(NAMES, n).tolist(), dtype="<U7")
    rec = RunRecord(samples={"t": t, "u": u, "i": i, "phase": phase}, meta={})
    mask = (phase == "hold") | (phase == "reverse")
    mask[0] = True  # the first sample's step is 0
    expected = float(np.sum(np.abs(u * i)[mask] * np.diff(t, prepend=t[0])[mask]))
    assert electric_energy(rec, mask) == expected
    assert electric_energy(rec, np.zeros(n, dtype=bool)) == 0.0


def test_series_equals_chebval():
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 0.5, 1e-3)
    law = fit_stroke(t, 0.1 * np.cos(6.0 * t) + rng.normal(0, 1e-5, len(t)), 0.02, 0.45)
    x = rng.uniform(-1.2, 1.2, 777)
    for coef in (law.coef, law._d1, law._d2, law.coef[:1], law.coef[:2]):
        assert np.array_equal(series(x, coef), C.chebval(x, coef))
    assert np.array_equal(law.phi(t), C.chebval(law._x(t), law.coef))
    assert law.phi(0.3) == C.chebval(law._x(0.3), law.coef)  # a scalar: numpy's own
