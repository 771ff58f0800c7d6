"""The record's compiled loops (record_kernels.py, and the series behind StrokeLaw) against the numpy
expressions they stand for, value for value."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev as C

from addedinertia_env.experiment.reference import fit_stroke, series
from addedinertia_env.experiment.metrics import electric_energy, samples_at_limit, saturated_fraction
from addedinertia_env.records.record import RunRecord
from addedinertia_env.records.record_kernels import phase_mask

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


def _limit_record(rng, n, u_max, i_max, voltage=True):
    """A record whose commands sit at, near and past their limits (with nan and signed zeros)."""
    i_cmd = rng.choice([0.0, -0.0, i_max, -i_max, 0.999 * i_max, 0.998 * i_max, np.nan, 2.0 * i_max], n)
    samples = {"t": np.arange(n) * 1e-3, "i_cmd": i_cmd, "i": rng.choice([0.0, i_max, -i_max, 0.5, np.nan], n),
               "phase": np.array(rng.choice(NAMES, n).tolist(), dtype="<U7")}
    if voltage:
        samples["u_cmd"] = rng.choice([0.0, -0.0, 12.0, -12.0, 0.999 * 12.0, 11.0, np.nan], n)
    rig = {"J_hull": 0.1, "J_flywheel": 0.01, "c_torsion": 1.0, "phi_neutral": 0.0, "k_t": 0.1, "R": 1.0,
           "sample_rate": 1000.0, "i_max": i_max, "u_max": u_max}
    return RunRecord(samples=samples, meta={"rig": {k: v for k, v in rig.items() if v is not None}})


def test_saturated_fraction_equals_the_numpy_mean():
    rng = np.random.default_rng(3)
    for u_max, i_max, voltage in ((12.0, 5.0, True), (None, 5.0, True), (12.0, 5.0, False), (12.0, None, True)):
        rec = _limit_record(rng, 2000, u_max, i_max if i_max is not None else 5.0, voltage)
        if i_max is None:
            del rec.meta["rig"]["i_max"]
        for mask in ((rec.phase == "hold") | (rec.phase == "reverse"), np.ones(2000, dtype=bool),
                     np.eye(1, 2000, 7, dtype=bool)[0]):
            expected = float(np.mean(samples_at_limit(rec)[mask]))
            assert saturated_fraction(rec, mask) == expected
        assert saturated_fraction(rec, np.zeros(2000, dtype=bool)) == 0.0
