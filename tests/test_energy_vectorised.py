"""The energy method's array paths against the plain computations they replace.

The energy method evaluates its balance at dozens of boundary angles at once
(:func:`~addedinertia_env.identify.crossings.crossing_fits`, ``RunBalance.intervals``),
fits the current's lag for every lag at once (``flywheel_calibration``) and smooths with
cached Savitzky-Golay maps (:func:`~addedinertia_env.identify.common.savgol`). Each is held
here to the straightforward one-at-a-time computation (written out in this file, as the
method was before it was vectorised) on batched-env episodes, clean and through DAQ
quirks: a jittered clock, dropped samples, a decimated record, the release logged as
moving, and a brake column that flips a sample off the phase change.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_coeffs, savgol_filter

from addedinertia_env.records.daq import Quirks, apply_quirks
from addedinertia_env.identify import identify
from addedinertia_env.identify import energy, energy_balance, energy_calibration, energy_pooling
from addedinertia_env.identify.common import _valid_convolution, savgol
from addedinertia_env.identify.crossings import crossing_fits, first_crossings
from addedinertia_env.identify.savgol_taps import conv_taps
from addedinertia_env.identify.rotor_friction import ROTOR_COULOMB_RATE_SCALE
from addedinertia_env.vector.env import ReverseStrokeVectorEnv

SHORT = dict(hold_s=0.5, fixed={"period_s": 3.0}, action_repeat=10)


def _brake_off_phase(rec):
    """The brake column set one sample after the hold begins (a sensed brake a sample late)."""
    s = {k: np.array(v, copy=True) for k, v in rec.samples.items()}
    k = int(np.nonzero(s["phase"] == "hold")[0][0])
    s["brake"][k] = s["brake"][k - 1]
    return type(rec)(s, rec.meta)


@pytest.fixture(scope="module")
def records():
    env = ReverseStrokeVectorEnv(2, **SHORT)
    env.reset(seed=11)
    rng = np.random.default_rng(4)
    clean = []
    while len(clean) < 2:
        _, _, term, _, _ = env.step(rng.uniform(-0.4, 0.4, size=(2, 1)).astype(np.float32))
        clean += [env.record(int(e)) for e in np.nonzero(term)[0]]
    out = {}
    variants = {"jitter": Quirks(jitter=3e-5), "drop": Quirks(drop=0.002, drop_release=True),
                "decimated": Quirks(decimate=2), "release moving": Quirks(release_moving=True)}
    for j, rec in enumerate(clean):
        out[f"clean {j}"] = rec
        out[f"brake off-phase {j}"] = _brake_off_phase(rec)
        for name, q in variants.items():
            out[f"{name} {j}"] = apply_quirks(rec, q, np.random.default_rng(j))
    return out


@pytest.mark.parametrize("n, window, degree, deriv", [(6000, 201, 5, 0), (900, 101, 3, 1), (900, 101, 3, 2),
                                                      (41, 41, 3, 0), (9, 7, 3, 1)])
def test_savgol_equals_scipys_filter(n, window, degree, deriv):
    x = 0.3 + np.cumsum(np.random.default_rng(n).normal(size=n)) * 1e-3
    ours, scipys = savgol(x, window, degree, deriv, 1e-3), savgol_filter(x, window, degree, deriv, delta=1e-3)
    # scipy's filter to its own accuracy (its taps: a Vandermonde solve, 1e-8 off for a quintic over 201
    # samples; ours are exact to rounding, tests/test_savgol_taps.py)
    np.testing.assert_allclose(ours, scipys, rtol=0, atol=3e-8 * np.max(np.abs(scipys)))
    # the taps: scipy's to its own accuracy (a Vandermonde solve, 1e-8 for a quintic over 201 samples)
    taps = conv_taps(window, degree, deriv)
    np.testing.assert_allclose(taps, savgol_coeffs(window, degree, deriv=deriv), rtol=0,
                               atol=1e-7 * np.max(np.abs(taps)))
    # the interior: np.convolve's own dot products ('valid' mode), bit for bit those of its 'same' mode
    half = window // 2
    same = np.convolve(x, taps, "same") / 1e-3**deriv if deriv else np.convolve(x, taps, "same")
    np.testing.assert_array_equal(ours[half:n - half], same[half:n - half])


@pytest.mark.parametrize("value", [0.123456789, -1.75, 0.0, -0.0, 1e-300, np.nan, np.inf])
@pytest.mark.parametrize("n, window, degree, deriv", [(4700, 201, 5, 0), (260, 201, 5, 0), (900, 101, 3, 1),
                                                      (60, 41, 3, 0)])
def test_savgol_of_a_constant_block_is_numpys_convolution(value, n, window, degree, deriv):
    # a braked hull's angle: every window the same numbers, one dot product copied (or every one computed)
    x = np.full(n, value)
    taps = conv_taps(window, degree, deriv)
    np.testing.assert_array_equal(_valid_convolution(x, taps), np.convolve(x, taps, "valid"))
    for view in (x, np.full(2 * n, value)[::2], np.r_[7.0, x][1:]):  # strided, and offset by one sample
        with np.errstate(invalid="ignore"):  # inf: the edge maps' products are nan (and warn) either way
            got = savgol(view, window, degree, deriv, 1e-3)
        half = window // 2
        expected = np.convolve(view, taps, "valid") / 1e-3**deriv if deriv else np.convolve(view, taps, "valid")
        np.testing.assert_array_equal(got[half:n - half], expected)
    # one sample off the constant: the full convolution
    y = x.copy()
    y[n // 2] = 0.5
    np.testing.assert_array_equal(_valid_convolution(y, taps), np.convolve(y, taps, "valid"))


def _one_fit(t, phi, k, level, half_width, degree):
    """One crossing fit, as the method computed it angle by angle."""
    tc = t[k]
    sel = np.nonzero(np.abs(t - tc) <= half_width)[0]
    X = np.vander((t[sel] - tc) / half_width, degree + 1, increasing=True)
    pinv = np.linalg.pinv(X)
    poly = np.polynomial.Polynomial(pinv @ phi[sel])
    dpoly = poly.deriv()
    x = 0.0
    for _ in range(8):
        x -= (poly(x) - level) / dpoly(x)
    grad = np.array([j * x ** (j - 1) if j else 0.0 for j in range(degree + 1)]) / half_width
    kernel = grad @ pinv
    resid = phi[sel] - X @ poly.coef
    var = max(float(resid @ resid) / max(len(sel) - degree - 1, 1), 1e-24)
    return tc + x * half_width, dpoly(x) / half_width, np.sqrt(var) * np.linalg.norm(kernel), sel, kernel


def test_crossing_fits_equal_the_fits_one_at_a_time(records):
    for name, rec in records.items():
        bal = energy.RunBalance(rec.without_truth())
        levels = bal.phi_n + np.linspace(0.25, 0.75, 9) * (bal.phi2 - bal.phi_n)
        ks = first_crossings(bal.phi, bal.free.start, bal.k2, levels, bal.direction)
        assert np.all(ks > 0), name
        for k, level in zip(ks, levels):  # the first crossing, as a scan would find it
            seg = bal.direction * (bal.phi[bal.free.start:bal.k2] - level)
            assert k == bal.free.start + np.nonzero((seg[:-1] < 0) & (seg[1:] >= 0))[0][0] + 1
        got = crossing_fits(bal.t, bal.phi, ks, levels, energy.RATE_HALF_WIDTH, energy.RATE_DEGREE)
        for j, (k, level) in enumerate(zip(ks, levels)):
            tc, rate, sigma, sel, kernel = _one_fit(bal.t, bal.phi, k, level, energy.RATE_HALF_WIDTH,
                                                    energy.RATE_DEGREE)
            assert got["t"][j] == pytest.approx(tc, rel=0, abs=1e-12), name
            assert got["rate"][j] == pytest.approx(rate, rel=1e-10), name
            assert got["sigma_rate"][j] == pytest.approx(sigma, rel=1e-8), name
            assert np.array_equal(got["kernel"][j][0], sel), name
            np.testing.assert_allclose(got["kernel"][j][1], kernel, rtol=0, atol=1e-10 * np.abs(kernel).max())
        first, size, offset, weights = got["windows"]  # the same kernels, over consecutive samples
        assert len(got["kernel"]) == len(ks)
        for j, (idx, kernel) in enumerate(got["kernel"]):
            np.testing.assert_array_equal(idx, first[j] + np.arange(size[j]))
            np.testing.assert_array_equal(kernel, weights[offset[j]:offset[j] + size[j]])
        odd = got["kernel"][1::2]  # a slice: those fits' kernels
        assert len(odd) == len(ks[1::2])
        for (idx, kernel), (idx2, kernel2) in zip(odd, [got["kernel"][j] for j in range(1, len(ks), 2)]):
            np.testing.assert_array_equal(idx, idx2)
            np.testing.assert_array_equal(kernel, kernel2)
        assert np.array_equal(got["kernel"][-1][1], got["kernel"][len(ks) - 1][1])
        with pytest.raises(IndexError):
            got["kernel"][len(ks)]


def test_all_angles_at_once_equal_each_angle_alone(records):
    for name, rec in records.items():
        balance, phi1, weights, first = energy.prepared_balance(rec.without_truth())
        assert np.isfinite(first.value), name
        together = balance.intervals(np.asarray(phi1))
        for p, iv in zip(phi1, together):
            alone = energy.RunBalance(rec.without_truth())
            alone.use_total_inertia(first.value + alone.J_h)
            one = alone.interval(p)
            assert one.rejected == iv.rejected, name
            if not iv.rejected:
                assert one.lambda66 == pytest.approx(iv.lambda66, rel=1e-10), name
                assert one.sigma == pytest.approx(iv.sigma, rel=1e-8), name
                assert one.terms["dW"] == pytest.approx(iv.terms["dW"], rel=1e-10, abs=1e-15), name


def _calibration_lag_by_lag(t, theta, psi, i, a, b, J_f, k_t, f_visc, f_coul, w_s=None, noise_i=0.0):
    """The flywheel calibration's lag search with one least-squares fit per lag (rss per lag); ``w_s``: the
    rotor dry friction's rate scale the balance passed (the record's coast, or the default); ``noise_i`` (the
    current's noise, for the calibration's sigma) does not enter the search."""
    w_s = ROTOR_COULOMB_RATE_SCALE if w_s is None else w_s
    tt, th = t[a:b + 1], theta[a:b + 1]
    om = np.gradient(psi[a:b + 1], tt)
    friction = f_visc * om + f_coul * np.tanh(om / w_s)  # the energy method's smoothed rotor dry friction

    def twice(x):
        c1 = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(tt))])
        return np.concatenate([[0.0], np.cumsum(0.5 * (c1[1:] + c1[:-1]) * np.diff(tt))])

    y = th + twice(friction) / J_f
    rss = []
    for lag in np.arange(-2e-3, energy.MAX_LAG_S + 1e-9, 2.5e-4):
        X = np.column_stack([np.ones_like(tt), tt - tt[0], k_t * twice(np.interp(tt + lag, t, i)) / J_f])
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ coef
        rss.append(float(r @ r))
    return np.array(rss)


def test_flywheel_calibration_equals_a_fit_per_lag(records, monkeypatch):
    seen = []
    original = energy_balance.flywheel_calibration

    def spy(*args):
        seen.append(args)
        return original(*args)

    monkeypatch.setattr(energy_balance, "flywheel_calibration", spy)
    calibrated = 0
    for name, rec in records.items():
        seen.clear()
        bal = energy.RunBalance(rec.without_truth())
        (args,) = seen
        rss = _calibration_lag_by_lag(*args)
        lags = np.arange(-2e-3, energy.MAX_LAG_S + 1e-9, 2.5e-4)
        j = int(np.argmin(rss))
        if not bal.calibrated:
            continue
        calibrated += 1
        den = rss[j - 1] - 2 * rss[j] + rss[j + 1]
        lag = lags[j] + 0.5 * (rss[j - 1] - rss[j + 1]) / den * (lags[1] - lags[0])
        assert bal.current_lag == pytest.approx(lag, rel=0, abs=1e-9), name
    assert calibrated >= 2, "the episodes should calibrate the current's lag on the flywheel"


def test_lag_search_ranks_like_every_residual_formed(records, monkeypatch):
    """The lag search forms the residuals of the best lag and its neighbours only (the others
    ranked through the unprojected shifts' products): same best lag and the same three sums of
    squares (to 1e-12) as forming every lag's projected residuals."""
    original = energy_calibration._lag_rss
    checked = []

    def spy(t, i, a, b, lags, twice, projected, Q, y):
        rss = original(t, i, a, b, lags, twice, projected, Q, y)
        full = energy_calibration._explicit_rss(energy_calibration._lagged_twice(t, i, a, b, lags, lambda x: projected(twice(x))), y)
        j = int(np.argmin(full))
        assert int(np.argmin(rss)) == j
        near = slice(max(j - 1, 0), j + 2)
        np.testing.assert_allclose(rss[near], full[near], rtol=1e-12, atol=0)
        assert np.all(rss >= full[j] * (1 - 1e-12))  # the others are never taken for the best
        checked.append(energy_calibration._lagged_twice(t, i, a, b, lags, twice, blend=False) is not None)
        return rss

    monkeypatch.setattr(energy_calibration, "_lag_rss", spy)
    for rec in records.values():
        energy.RunBalance(rec.without_truth())
    assert any(checked), "some records should be evenly sampled (the ranked path)"


def test_identify_on_each_record_is_finite_and_repeatable(records):
    for name, rec in list(records.items())[:3]:
        a, b = identify([rec], "energy"), identify([rec], "energy")
        assert np.isfinite(a.lambda66) and a.lambda66 == b.lambda66, name


def test_no_angles_give_no_fits():
    t = np.arange(100) * 1e-3
    got = crossing_fits(t, np.sin(t), np.zeros(0, dtype=int), np.zeros(0), 0.01, 3)
    assert got["t"].shape == (0,) and got["kernel"] == []
    assert np.array_equal(first_crossings(np.sin(t), 0, 50, np.array([2.0]), 1.0), [-1])  # never reached


def test_first_crossings_search_equals_the_plain_test():
    """The running-maximum search finds the same crossing samples as testing every pair of samples."""
    from addedinertia_env.identify.crossings import _first_crossings_plain

    rng = np.random.default_rng(7)
    for _ in range(2000):
        n = int(rng.integers(3, 60))
        phi = np.round(np.cumsum(rng.normal(0.3, 1.0, n)) * 2) / 2  # quantised, back and forth
        levels = rng.uniform(phi.min() - 1, phi.max() + 1, 7)
        levels[:2] = phi[rng.integers(0, n, 2)]  # levels equal to samples
        direction = float(rng.choice([-1.0, 1.0]))
        a = int(rng.integers(0, n - 2))
        b = int(rng.integers(a + 2, n + 1))
        assert np.array_equal(first_crossings(phi, a, b, levels, direction),
                              _first_crossings_plain(phi, a, b, levels, direction))


def test_first_pass_value_equals_the_full_first_pass(records):
    """The first pass's value alone (what identify uses) is the number the full first pass gives."""
    for name, rec in records.items():
        balance, phi1, weights, first = energy.prepared_balance(rec.without_truth())
        fresh = energy.RunBalance(rec.without_truth())
        assert fresh.weighted_value(np.asarray(phi1), weights) == first.value, name


def test_identification_does_not_depend_on_what_ran_before(records):
    """Shared fit designs are kept across records; the estimates must not depend on the order."""
    from addedinertia_env.identify import crossings

    recs = list(records.values())
    crossings._DESIGNS.clear()
    forward = [identify([r], "energy").lambda66 for r in recs]
    crossings._DESIGNS.clear()
    backward = [identify([r], "energy").lambda66 for r in reversed(recs)][::-1]
    assert forward == backward


def test_numbers_without_interval_records_equal_the_full_result(records):
    """interval_details=False (the batched env's scoring) gives the same numbers as the full result."""
    for name, rec in records.items():
        full, lean = identify([rec], "energy"), identify([rec], "energy", interval_details=False)
        assert (lean.lambda66, lean.ci95, lean.n_intervals) == (full.lambda66, full.ci95, full.n_intervals), name
        assert "intervals" not in lean.details and "intervals" in full.details, name
        assert lean.details == {k: v for k, v in full.details.items() if k != "intervals"}, name


def test_polynomial_fits_equal_numpys_to_rounding():
    from addedinertia_env.identify.common import line_fit, power_fit  # noqa: PLC0415

    rng = np.random.default_rng(23)
    for case in range(100):
        n = int(rng.integers(3, 80))
        x = np.sort(rng.normal(size=n)) * 10.0 ** rng.uniform(-4, 1)
        y = rng.normal(size=n) + 3.0 * x
        for degree in (1, 2, 3):  # to float rounding (fit_kernels.lstsq for full-rank designs)
            if n > degree:
                want = np.polynomial.polynomial.polyfit(x, y, degree)
                np.testing.assert_allclose(power_fit(x, y, degree), want, rtol=1e-9, atol=1e-12 * np.max(np.abs(want)))
        want = np.polyfit(x, y, 1)
        np.testing.assert_allclose(line_fit(x, y), want, rtol=1e-9, atol=1e-12 * np.max(np.abs(want)))
    with pytest.warns(np.exceptions.RankWarning):  # a design of one repeated abscissa
        power_fit(np.ones(5), np.arange(5.0), 2)
    with pytest.warns(np.exceptions.RankWarning):
        line_fit(np.ones(5), np.arange(5.0))


def test_angle_columns_equal_the_numpy_expressions():
    from addedinertia_env.identify.balance_kernels import angle_uncertainties, angle_values  # noqa: PLC0415
    from addedinertia_env.identify.energy import BalanceTerms, inertia_from_terms  # noqa: PLC0415
    from addedinertia_env.records.scan_kernels import squared_step_sums, true_counts  # noqa: PLC0415

    rng = np.random.default_rng(29)
    n, samples, k2, k3, J_h = 41, 3000, 1400, 1700, 0.012
    terms = {name: rng.normal(size=n) * 10.0 ** rng.uniform(-4, 0) for name in
             ("spring", "A_f", "A_r", "B_f", "B_r", "K1", "K2", "K3", "K4", "hull_rest", "dW")}
    w1f, w1r = rng.normal(size=n), rng.normal(size=n)
    w1f[3], w1r[5] = 1e-14, np.nan  # the mismatch's floor and a nan rate
    T = BalanceTerms(phi1=rng.normal(size=n), t1=rng.random(n), t4=rng.random(n), w1f=w1f, w1r=w1r, **terms)
    k1s, k4s = rng.integers(0, k2, size=n), rng.integers(k3 + 1, samples + 5, size=n)
    saturated = rng.random(samples) < 0.05
    count = true_counts(saturated)
    lam_np = inertia_from_terms(T, J_h)
    sat_np = (count[np.minimum(k4s + 1, len(count) - 1)] - count[k3]) / (np.minimum(k4s + 1, samples) - k3)
    mismatch_np = np.abs(np.abs(w1r) - np.abs(w1f)) / np.maximum(np.abs(w1f), 1e-12)
    f = [getattr(T, name) for name in ("spring", "A_f", "A_r", "B_f", "B_r", "K1", "K2", "K3", "K4", "hull_rest",
                                        "dW", "w1f", "w1r")]
    lam, sat, mismatch = angle_values(*f, J_h, count, samples, k3, k4s)
    np.testing.assert_array_equal(lam, lam_np)
    np.testing.assert_array_equal(sat, sat_np)
    np.testing.assert_array_equal(mismatch, mismatch_np)
    np.testing.assert_array_equal(angle_values(*f, J_h, np.zeros(0, dtype=np.int64), 0, k3, k4s)[1], np.zeros(n))

    sigma_f, sigma_r, s_dW = rng.random(n) * 1e-3, rng.random(n) * 1e-3, rng.random(n) * 1e-4
    dsq = squared_step_sums(np.cumsum(rng.normal(size=samples)) * 1e-4)
    k_t, noise_i, gain_u = 0.05, 0.01, 0.005

    def work_noise(a, b):  # the numpy expression of RunBalance's work noise
        total = dsq[np.minimum(b, len(dsq) - 1)] - dsq[np.minimum(a, len(dsq) - 1)]
        return k_t * noise_i * np.sqrt(np.maximum(total, 0.0) / 2.0)

    denom = 0.5 * (w1f**2 + w1r**2)
    s_den = np.hypot(w1f * sigma_f, w1r * sigma_r)
    s_current = np.hypot(work_noise(k1s, k2), work_noise(k3, k4s)) / denom
    s_independent = np.hypot(s_current, (lam_np + J_h) * s_den / denom)
    s_common = np.hypot(gain_u * np.hypot(T.A_f, T.A_r), s_dW) / denom
    got = angle_uncertainties(lam, T.A_f, T.A_r, w1f, w1r, sigma_f, sigma_r, s_dW, k1s, k4s, k2, k3, dsq,
                              k_t * noise_i, gain_u, J_h)
    for ours, theirs in zip(got, (s_independent, s_common, np.hypot(s_independent, s_common), s_current)):
        np.testing.assert_array_equal(ours, theirs)


def test_rate_sigma_from_windows_equals_it_from_the_kernel_lists(records):
    for name, rec in records.items():
        balance, phi1, weights, first = energy.prepared_balance(rec.without_truth())
        cols = balance.interval_columns(np.asarray(phi1))
        rows = np.nonzero(~cols["rejected"])[0][::2]  # every other usable angle: a subset of the fits
        g = np.asarray(weights)[cols["good"][rows]]
        g = g / g.sum()
        lam, w1f, w1r = (np.asarray(cols[k])[rows].tolist() for k in ("lam", "w1f", "w1r"))
        kernels = [[cols["fits"][side]["kernel"][r] for r in rows.tolist()] for side in "fr"]
        fits = np.ravel(np.stack([2 * rows, 2 * rows + 1], axis=1))
        assert (balance.rate_sigma_of_windows(g, lam, w1f, w1r, cols["windows"], fits)
                == balance.rate_sigma(g, lam, w1f, w1r, *kernels)), name


def test_shared_savgol_equals_savgol():
    from addedinertia_env.identify.common import SharedSavgol  # noqa: PLC0415

    rng = np.random.default_rng(8)
    x = np.cumsum(rng.normal(size=3000)) * 1e-3
    x[2000:2600] = x[2000]  # a constant stretch
    shared = SharedSavgol(x)
    # later slices start before, after and at the known ones (the same end), other ends, other filters
    for start, stop, window, degree, deriv in [(900, 2900, 101, 3, 1), (300, 2900, 101, 3, 1), (1200, 2900, 101, 3, 1),
                                               (300, 2900, 101, 3, 1), (0, 2900, 101, 3, 1), (0, 2900, 101, 3, 2),
                                               (100, 2500, 51, 3, 1), (2000, 2700, 201, 5, 0), (0, 3000, 7, 3, 1)]:
        expected = savgol(x[start:stop], window, degree, deriv, 1e-3)
        np.testing.assert_array_equal(shared.savgol(start, stop, window, degree, deriv, 1e-3), expected)
    with pytest.raises(ValueError, match="window"):
        shared.savgol(2900, 2950, 101, 3, 1, 1e-3)
    np.testing.assert_array_equal(SharedSavgol(x.astype(np.float32)).savgol(0, 900, 101, 3, 1, 1e-3),
                                  savgol(x.astype(np.float32)[:900], 101, 3, 1, 1e-3))


def test_dense_fractions_are_those_computed_afresh():
    for lo, hi in [(0.25, 0.75), (0.1, 0.9), (0.25, 0.75)]:
        f, w = energy_pooling._dense_fractions(lo, hi, energy.DENSE_ANGLES)
        np.testing.assert_array_equal(f, np.linspace(lo, hi, energy.DENSE_ANGLES))
        np.testing.assert_array_equal(w, energy.hann_weights(np.linspace(lo, hi, energy.DENSE_ANGLES), lo, hi))
        assert not f.flags.writeable and not w.flags.writeable
    f, w = energy_pooling._dense_fractions(np.float32(0.25), 1, 5)  # other kinds of numbers: computed as before
    np.testing.assert_array_equal(w, energy.hann_weights(np.linspace(np.float32(0.25), 1, 5), np.float32(0.25), 1))


def test_terms_of_the_second_pass_are_those_computed_afresh(records):
    """The parts of the balance the total inertia does not change are kept from the first pass."""
    for name, rec in records.items():
        balance, phi1, weights, first = energy.prepared_balance(rec.without_truth())
        again = balance.terms_many(np.asarray(phi1))
        again["terms"].A_f[:] = np.nan  # a caller's changes stay in its own copy
        again["k1s"][:] = -1
        got = balance.terms_many(np.asarray(phi1))
        fresh = energy.RunBalance(rec.without_truth())
        fresh.use_total_inertia(first.value + fresh.J_h)
        expected = fresh.terms_many(np.asarray(phi1))
        for key in ("k1s", "k4s", "s_dW", "good"):
            np.testing.assert_array_equal(got[key], expected[key], err_msg=name)
        for field in energy.BalanceTerms.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(got["terms"], field), getattr(expected["terms"], field),
                                          err_msg=f"{name} {field}")
