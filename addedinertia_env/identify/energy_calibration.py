"""The energy method's calibration of the motor torque on the flywheel: the torque per logged ampere and
the current channel's lag, from the flywheel's own balance ``J_f (w + Omega)' = k_t i - M_f``
(physics.md section 8), so that neither the data-sheet ``k_t`` nor the current sensor's gain sets
the scale of the motor's work.

Part of the energy method (:mod:`addedinertia_env.identify.energy`).
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.identify.rotor_friction import ROTOR_COULOMB_RATE_SCALE
from addedinertia_env.identify.series_kernels import calibration_target, lag_ranking, twice_integrated
from addedinertia_env.records.series_stats import median_step
from addedinertia_env.identify.fit_kernels import line_basis, project_out_line


MAX_LAG_S = 0.012  # s, the longest current-channel lag the flywheel calibration looks for
LAG_PRECISION = 0.02  # the current lag must be fitted to this fraction of a sample period to be used


def flywheel_calibration(t, theta, psi, i, a: int, b: int, J_f: float, k_t: float, f_visc: float,
                         f_coul: float, w_s: float | None = None) -> tuple[float, float] | None:
    """Torque per logged ampere relative to ``k_t`` (scale) and the current channel's lag (s),
    from the flywheel's own balance ``J_f theta'' = s k_t i(t - lag) - M_f`` (physics.md s8).

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
    return scale, lag


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
