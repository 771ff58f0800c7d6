"""The energy method's calibration of the motor torque on the flywheel: the torque per logged ampere and
the current channel's lag, from the flywheel's own balance ``J_f (w + Omega)' = k_t i - M_f``
(physics.md section 8), so that neither the data-sheet ``k_t`` nor the current sensor's gain sets
the scale of the motor's work.

Part of the energy method (:mod:`addedinertia_env.identify.energy`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from addedinertia_env.identify.rotor_friction import ROTOR_COULOMB_RATE_SCALE
from addedinertia_env.identify.series_kernels import calibration_target, lag_ranking, twice_integrated
from addedinertia_env.records.series_stats import median_step
from addedinertia_env.identify.fit_kernels import line_basis, project_out_line


MAX_LAG_S = 0.012  # s, the longest current-channel lag the flywheel calibration looks for
LAG_PRECISION = 0.02  # the current lag must be fitted to this fraction of a sample period to be used
# s, the Bartlett (Newey-West) bandwidth of the calibration residuals' scores: twice the window of the angles'
# smoothing (energy_work.WORK_SMOOTHING_S, 0.2 s), through which the rotor friction's rate enters the fitted angle,
# as the dissipation law's scores are summed over twice its filter's window (energy_dissipation)
CALIBRATION_HAC_S = 0.4
# relative, the calibration model's own error, root-sum-squared into every scale's sigma: the balance takes the
# logged current as linear between samples, shifted by one lag, while the motor's current moves within a sample
# (its winding's L/R, the drive's steps); the lag then takes up part of that and the scale the rest. Measured on
# the simulator, where the torque per logged ampere is known (1 / (1 + the current sensor's gain error)): on the
# 16 lag-pinned reverse runs of the drawn hulls with noise-free sensors, seeds 1-13, the scale's error has rms
# 1.0e-4 while the fit's own sigma is 2e-6 to 6e-5 (held out, seeds 14-18: 4 runs, rms 0.7e-4; docs/INTERVALS.md)
CALIBRATION_MODEL_ERROR = 1.0e-4
NOISE_SHARE_DRAWS = 16  # draws of the stated current noise for its expected share of the residuals' HAC


class FlywheelCalibration(NamedTuple):
    """The flywheel calibration (:func:`flywheel_calibration`): torque per logged ampere relative to ``k_t``
    (``scale``), the current channel's lag (``lag``, s), the scale's own 1-sigma (``sigma``) and its two parts
    (``sigma_current``: the logged current's white noise through the fit, lag and scale together;
    ``sigma_residual``: the fit's residuals, HAC; with :data:`CALIBRATION_MODEL_ERROR` beside them), and the
    lag's 1-sigma from the first two (s)."""

    scale: float
    lag: float
    sigma: float
    sigma_current: float
    sigma_residual: float
    sigma_lag: float


def flywheel_calibration(t, theta, psi, i, a: int, b: int, J_f: float, k_t: float, f_visc: float,
                         f_coul: float, w_s: float | None = None,
                         noise_i: float = 0.0) -> FlywheelCalibration | None:
    """Torque per logged ampere relative to ``k_t`` (scale), the current channel's lag (s) and the
    scale's own 1-sigma (:class:`FlywheelCalibration`), from the flywheel's own balance
    ``J_f theta'' = s k_t i(t - lag) - M_f`` (physics.md s8).

    ``theta = phi + psi`` is the flywheel's absolute angle; over samples ``a..b`` (the end of
    the hold and the reverse stroke, where the motor drives) it is fitted, twice integrated,
    by least squares for each lag on a 0.25 ms grid (refined by a parabola). ``J_f`` and the
    rotor friction come from the rig block: the flywheel's inertia is what calibrates the
    torque, so a current-sensor gain error or a torque constant off its data sheet, and a
    current channel that lags the encoders, no longer enter the motor's work. None when the
    span is too short, the fit is poor (residual over 1e-3 rad rms: friction or offset not
    as stated over a long hold), or the lag is not pinned to :data:`LAG_PRECISION` of a
    sample: a current without fast changes (an ideal tracking controller's) lets a lag
    and a scale trade off, and the fit then lands a few ms and half a percent off. ``w_s``: the
    rotor's dry friction's rate scale (rotor_friction.creep_rate_scale where the record shows it).
    ``noise_i``: the logged current's white noise (A rms), for the sigma (:func:`calibration_sigma`).
    """
    if b - a < 200:
        return None
    tt, th = t[a:b + 1], theta[a:b + 1]
    # the angle the fit explains (kept for the final fit): th + the friction's torque (from psi, already
    # smoothed phase by phase) twice integrated over J_f; and the half sample intervals
    target, half_dtt = calibration_target(tt, th, psi[a:b + 1], float(f_visc), float(f_coul), float(J_f),
                                           ROTOR_COULOMB_RATE_SCALE if w_s is None else float(w_s))
    y = target

    def twice(x):  # trapezoid integral of the integral, from 0, along the last axis
        return twice_integrated(np.atleast_2d(x), half_dtt).reshape(np.shape(x))

    lags = np.arange(-2e-3, MAX_LAG_S + 1e-9, 2.5e-4)
    # Least squares on (1, t - t_a, the lagged current's column), every lag at once: the first two
    # columns are shared, so they are projected out (twice, for orthogonality to rounding;
    # fit_kernels.project_out_line) and each lag's column is then a one-column fit.

    Q = line_basis(tt)

    def projected(x):  # the rows with the first two columns projected out
        return project_out_line(np.atleast_2d(x), Q).reshape(np.shape(x))

    y = projected(y)
    rss = _lag_rss(t, i, a, b, lags, twice, projected, Q, y)  # k_t / J_f leaves the residuals
    j = int(np.argmin(rss))
    if not 0 < j < len(lags) - 1 or np.sqrt(rss[j] / len(tt)) > 1e-3:
        return None
    den = rss[j - 1] - 2 * rss[j] + rss[j + 1]
    step = lags[1] - lags[0]
    sigma_lag = float(np.sqrt(2.0 * rss[j] / (len(tt) - 3) * step**2 / den)) if den > 0 else np.inf
    if sigma_lag > LAG_PRECISION * float(median_step(tt)):
        return None  # a smooth current: lag and scale trade off against each other
    frac = 0.5 * (rss[j - 1] - rss[j + 1]) / den if den > 0 else 0.0
    lag = float(lags[j] + frac * (lags[1] - lags[0]))
    # the third coefficient of the fit on (1, t - t_a, z) by the projection theorem (y is projected already)
    z = projected(k_t * twice(np.interp(tt + lag, t, i)) / J_f)
    scale = float((z @ y) / (z @ z))
    if not 0.5 < scale < 2.0:
        return None
    step = 0.1 * float(median_step(tt))  # the lag's column: the model's derivative in the lag, central
    dz = (projected(k_t * twice(np.interp(tt + lag + step, t, i)) / J_f)
          - projected(k_t * twice(np.interp(tt + lag - step, t, i)) / J_f)) / (2.0 * step)
    s_current, s_resid, s_lag = calibration_sigma(t, tt, lag, y, z, scale * dz, scale, k_t / J_f, noise_i, half_dtt)
    sigma = float(np.sqrt(s_current**2 + s_resid**2 + CALIBRATION_MODEL_ERROR**2))
    return FlywheelCalibration(scale, lag, sigma, s_current, s_resid, s_lag)


def _twice_adjoint(g: np.ndarray, half_dt: np.ndarray) -> np.ndarray:
    """``T^T g`` for the double trapezoid integral ``T`` of :func:`~.series_kernels.twice_integrated` (sample
    intervals ``2 half_dt``): what a unit change of each integrated sample does to ``g . (T x)``."""
    def once(v):  # adjoint of out[k] = sum_{j<k} (x_j + x_{j+1}) h_j
        suffix = np.concatenate([np.cumsum(v[::-1])[::-1], [0.0]])  # suffix[k] = sum_{j>=k} v_j
        out = np.zeros_like(v)
        out[:-1] += half_dt * suffix[1:-1]
        out[1:] += half_dt * suffix[1:-1]
        return out
    return once(once(np.asarray(g, dtype=float)))


def bartlett_long_run(U: np.ndarray, bandwidth: int) -> np.ndarray:
    """The long-run covariance of the sums of the rows of ``U`` (p, n): ``G_0 + sum_k w_k (G_k + G_k^T)`` with
    Bartlett weights ``w_k = 1 - k / (bandwidth + 1)``, ``G_k = sum_t U[:, t] U[:, t + k]^T`` (Newey & West 1987,
    Econometrica 55: 703-708; positive semidefinite)."""
    p, n = U.shape
    L = int(min(max(bandwidth, 0), n - 1))
    F = np.fft.rfft(U, 2 * n, axis=1)
    # G[a, b, k] = sum_t U[a, t] U[b, t + k] (zero-padded, so not circular)
    G = np.fft.irfft(F[:, None, :].conj() * F[None, :, :], 2 * n, axis=2)[:, :, :L + 1]
    w = 1.0 - np.arange(L + 1) / (L + 1.0)
    S = np.einsum("abk,k->ab", G[:, :, 1:], w[1:])
    return G[:, :, 0] + S + S.T


def calibration_sigma(t, tt, lag, y, z, z_lag, scale, gain, noise_i, half_dtt) -> tuple[float, float, float]:
    """The flywheel calibration's own 1-sigma of the scale, in two parts, and the lag's 1-sigma (s).

    The fit is ``y ~ scale z(lag)`` (both projected off the line), linearised in ``(scale, lag)`` with the
    columns ``X = (z, z_lag)`` (``z_lag = scale dz/dlag``): lag and scale trade where the current is smooth,
    so the scale's variance is read from the pair's joint covariance ``A^-1 (...) A^-1``, ``A = X X^T``.
    - current: the logged current's white noise (``noise_i`` A rms) is in the columns, not in ``y``
      (errors in variables): it moves ``(scale, lag)`` by ``-A^-1 X^T (scale P T L di) gain`` (``T`` the
      double integral, ``L`` the lag's interpolation, ``P`` the projection; ``gain = k_t / J_f``), a
      variance ``(scale gain noise_i)^2 A^-1 (M M^T) A^-1`` with ``M = L^T T^T X`` row by row, exact
      for white noise. A twice-integrated noise is correlated over the whole span, which no
      residual-based estimate with a finite bandwidth recovers: it is carried analytically.
    - residual: the fit's residuals' scores ``X r`` through their Bartlett long-run covariance
      (:func:`bartlett_long_run`, :data:`CALIBRATION_HAC_S`): the encoders' quantisation and the
      rotor friction's misfit, correlated over the rate filter's window, and the rest of the model's error;
      less the current noise's own expected share of that estimate (:func:`_current_share_of_hac`), which
      the first part holds already.
    The calibration model's error (:data:`CALIBRATION_MODEL_ERROR`) is added by the caller. Returns
    ``(scale sigma from the current, scale sigma from the residuals, lag sigma in s)``.
    """
    X = np.stack([np.asarray(z, float), np.asarray(z_lag, float)])
    A_inv = np.linalg.inv(X @ X.T)
    dt = float(median_step(tt))
    # the lagged current's samples and weights, as np.interp takes them (any grid; clamped at the ends)
    x = np.clip(np.asarray(tt) + lag, t[0], t[-1])
    k = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
    f = np.clip((x - t[k]) / (t[k + 1] - t[k]), 0.0, 1.0)
    M = np.zeros((2, len(t)))
    for row, col in zip(M, X):
        g = _twice_adjoint(col, half_dtt)
        np.add.at(row, k, (1.0 - f) * g)
        np.add.at(row, k + 1, f * g)
    cov_current = (scale * gain * noise_i) ** 2 * (A_inv @ (M @ M.T) @ A_inv)
    r = np.asarray(y, float) - scale * X[0]
    bandwidth = int(round(CALIBRATION_HAC_S / dt))
    cov_resid = A_inv @ bartlett_long_run(X * r, bandwidth) @ A_inv
    if noise_i > 0.0:  # the current noise's own share of that estimate, already in cov_current: taken out
        cov_resid = cov_resid - _current_share_of_hac(t, tt, k, f, X, A_inv, scale * gain * noise_i, half_dtt,
                                                      bandwidth)
    return (float(np.sqrt(max(cov_current[0, 0], 0.0))), float(np.sqrt(max(cov_resid[0, 0], 0.0))),
            float(np.sqrt(max(cov_current[1, 1] + max(cov_resid[1, 1], 0.0), 0.0))))



def _current_share_of_hac(t, tt, k, f, X, A_inv, c, half_dtt, bandwidth) -> np.ndarray:
    """The expected share of a white current noise (``c`` = scale k_t / J_f x its rms) in the residual-based
    sandwich ``A^-1 HAC(X r) A^-1``: the noise twice integrated and projected like the fit's columns, less what
    the fit's two parameters absorb (``(I - H)``, ``H`` the hat matrix of ``X``), its scores' Bartlett covariance,
    averaged over :data:`NOISE_SHARE_DRAWS` draws (a fixed seed: the estimate is a function of the record).
    Without it the twice-integrated noise, correlated over the whole span, would count in both parts."""
    rng = np.random.default_rng(20261128)
    Q = line_basis(tt)
    total = np.zeros((2, 2))
    for _ in range(NOISE_SHARE_DRAWS):
        e = rng.standard_normal(len(t))
        lagged = (1.0 - f) * e[k] + f * e[k + 1]
        dz = project_out_line(twice_integrated(lagged[None, :], half_dtt), Q)[0]
        dr = -c * (dz - X.T @ (A_inv @ (X @ dz)))
        total += A_inv @ bartlett_long_run(X * dr, bandwidth) @ A_inv
    return total / NOISE_SHARE_DRAWS


def _lag_rss(t, i, a, b, lags, twice, projected, Q, y):
    """Residual sum of squares of the one-column fit ``y ~ c z_lag`` for every lag, where
    ``z_lag = projected(twice(np.interp(t[a:b + 1] + lag, t, i)))`` (the calibration's lagged current,
    twice integrated and projected; ``y`` projected already); the residuals of the lags that can be
    the best one or its neighbours are formed explicitly (no cancellation), the others only bounded.

    On an evenly sampled stretch each lag's row blends two whole-sample shifts (:func:`_lagged_twice`),
    so the ~16 shifts ``B`` are twice integrated but not projected: with ``P = I - Q Q^T`` (``Q``: the
    projection's :func:`~.fit_kernels.line_basis`), ``z.y`` and ``z.z`` follow for every lag from ``B y`` and
    ``B B^T - (B Q)(B Q)^T``, ``|y|^2 - (z.y)^2 / z.z`` ranks the lags, and the rows within rounding of
    the smallest (and their neighbours) are formed, projected and summed. Otherwise (or if the ranking
    is not clear-cut) every row is formed."""
    blended = _lagged_twice(t, i, a, b, lags, twice, blend=False)
    if blended is None:
        return _explicit_rss(_lagged_twice(t, i, a, b, lags, lambda x: projected(twice(x))), y)
    base, k, frac = blended
    BQ = base @ Q
    rss, rows = lag_ranking(base @ y, base @ base.T - BQ @ BQ.T, k, frac, float(y @ y))
    g = 1.0 - frac
    Z = projected(g[rows, None] * base[k[rows]] + frac[rows, None] * base[k[rows] + 1])
    rss[rows] = _explicit_rss(Z, y)
    j = int(np.argmin(rss))
    formed = set(rows.tolist())
    if all(r in formed for r in (max(j - 1, 0), j, min(j + 1, len(lags) - 1))):
        return rss
    return _explicit_rss(_lagged_twice(t, i, a, b, lags, lambda x: projected(twice(x))), y)


def _explicit_rss(Z: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per row of ``Z``: the residual sum of squares of ``y ~ c z`` (least squares), residuals formed explicitly."""
    zz = np.einsum("ij,ij->i", Z, Z)
    coef = (Z @ y) / np.where(zz > 0, zz, np.inf)
    r = y[None, :] - coef[:, None] * Z
    return np.einsum("ij,ij->i", r, r)


def _lagged_twice(t: np.ndarray, i: np.ndarray, a: int, b: int, lags: np.ndarray, linear, blend: bool = True):
    """``linear(np.interp(t[a:b + 1] + lag, t, i))`` for every lag (rows), for a map ``linear``
    acting row by row (the calibration's double integral and projection).

    On an evenly sampled stretch (intervals equal to 1e-9), the current at ``t + lag`` is the
    blend ``(1 - f) i[k + n] + f i[k + n + 1]`` of two whole-sample shifts, and the map is
    linear: so only the ~16 whole-sample shifts are mapped and each lag blends two of them
    (equal to interpolating first, to float rounding). Otherwise every lag is interpolated.
    With ``blend=False``: the shifts' rows ``B``, each lag's first row ``k`` and weight ``f`` (row
    ``(1 - f) B[k] + f B[k + 1]``) on an evenly sampled stretch, None otherwise.
    """
    m = b + 1 - a
    dt = (t[b] - t[a]) / max(m - 1, 1)
    steps = lags / dt
    n = np.floor(steps + 1e-9).astype(np.int64)
    frac = np.clip(steps - n, 0.0, 1.0)
    lo, hi = a + int(n.min()), b + int(n.max()) + 1
    if lo >= 0 and hi < len(t) and m > 1:
        d = np.diff(t[lo:hi + 1])
        if np.max(np.abs(d - dt)) <= 1e-9 * dt:
            shifts = np.arange(int(n.min()), int(n.max()) + 2)
            # the shifted copies as one strided view: row r is i[a + shifts[r]:a + shifts[r] + m]
            base = linear(np.lib.stride_tricks.sliding_window_view(i[a + shifts[0]:a + shifts[-1] + m], m))
            k = n - shifts[0]
            if not blend:
                return base, k, frac
            return (1.0 - frac)[:, None] * base[k] + frac[:, None] * base[k + 1]
    if not blend:
        return None
    return linear(np.interp(t[a:b + 1][None, :] + lags[:, None], t, i))


# The current channel's timing when the flywheel cannot pin its lag: the record's sampling rule
# (energy_work.interval_mean_current) is taken as the timing, uncertain by this fraction of a sample
# interval. Where the lag is pinned (lqr runs, 17- and 20-bit encoders), the fitted lags lie 0.05 to
# 0.16 ms from 0 at 1 kHz, within about 0.1 ms of the interval rule's own offset (0.08 ms for L/R = one sample).
RULE_LAG_UNCERTAINTY = 0.1


def scale_at_sampling_rule(t, theta, psi, i_mean, a: int, b: int, J_f: float, k_t: float, f_visc: float,
                           f_coul: float, noise_i: float, w_s: float | None = None) -> tuple[float, float] | None:
    """Torque per logged ampere relative to ``k_t`` and its 1-sigma, from the flywheel's balance over
    samples ``a..b`` with the current timed by the record's own sampling rule (``i_mean``: the mean
    current over each sample interval, as the motor work takes it), when :func:`flywheel_calibration`
    cannot pin the lag (a smooth current lets lag and scale trade).

    The span should start at the brake's release: over a hold with no current the flywheel creeps at
    rates no encoder resolves, where the rotor's dry friction is not known (its law at rest is the
    rig's, not the block's), and a fit that reaches into the hold takes that misfit for scale (up to
    1 % on unquantised records). The 1-sigma is the root sum of squares of three parts, each the
    scale's own error source: the logged current's noise (white, ``noise_i`` A rms) through the double
    integral, the angle's residual scatter (the encoders' quantisation), and the timing, a lag of
    :data:`RULE_LAG_UNCERTAINTY` of a sample through the scale's slope against the lag. None when the
    span is under 200 samples or the scale is outside 0.5..2. ``w_s``: as :func:`flywheel_calibration`'s.
    """
    if b - a < 200:
        return None
    tt, th = t[a:b + 1], theta[a:b + 1]
    target, half_dtt = calibration_target(tt, th, psi[a:b + 1], float(f_visc), float(f_coul), float(J_f),
                                          ROTOR_COULOMB_RATE_SCALE if w_s is None else float(w_s))
    Q = line_basis(tt)

    def projected(x):
        return project_out_line(np.atleast_2d(x), Q).reshape(np.shape(x))

    y = projected(target)
    h = np.diff(tt)
    dt = float(median_step(tt))

    def column(shift: float) -> np.ndarray:  # the interval means shifted by ``shift`` s, twice integrated, scaled
        m = np.asarray(i_mean[a:b], dtype=float)
        if shift:
            mid = 0.5 * (tt[1:] + tt[:-1])
            m = np.interp(mid + shift, mid, m)
        rate = np.concatenate([[0.0], np.cumsum(m * h)])
        angle = np.concatenate([[0.0], np.cumsum(0.5 * h * (rate[1:] + rate[:-1]))])
        return projected(k_t * angle / J_f)

    z = column(0.0)
    zz = float(z @ z)
    if not zz > 0.0:
        return None
    scale = float((z @ y) / zz)
    if not 0.5 < scale < 2.0:
        return None
    r = y - scale * z
    # the current's noise: white per sample; its double integral's weight on the scale is (M^T z) / z.z
    c1 = np.cumsum(z[::-1])[::-1]
    w = dt * dt * (np.cumsum(c1[::-1])[::-1] - c1)
    s_noise = abs(scale) * (k_t / J_f) * noise_i * float(np.linalg.norm(w)) / zz
    s_angle = float(np.sqrt((r @ r) / max(len(r) - 3, 1) / zz))
    step = RULE_LAG_UNCERTAINTY * dt
    up, down = column(step), column(-step)
    s_lag = 0.5 * abs(float((up @ y) / (up @ up)) - float((down @ y) / (down @ down)))
    return scale, float(np.sqrt(s_noise**2 + s_angle**2 + s_lag**2))
