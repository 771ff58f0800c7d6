"""The textbook free-decay method (physics.md section 5; source 004, roll-decay processing).

From a free decay with the motor passive:

* the extrema of ``phi(t)`` (local quartic fits where the smoothed rate changes sign);
* per full period (extremum ``k`` to ``k + 2``) the damped period ``T_d``;
* the decrement per half swing ``delta = ln(s_k / s_(k+1))`` from successive peak-to-peak
  swings ``s_k = |phi_(k+1) - phi_k|`` (swings do not depend on where the centre is, so a
  neutral offset does not bias them), and ``zeta = delta / sqrt(pi^2 + delta^2)``;
* ``w_n = 2 pi / T_d / sqrt(1 - zeta^2)``, ``J_total = c / w_n^2``,
  ``lambda66 = J_total - J_h - kappa J_f`` (``kappa``: how far the flywheel swings with
  the hull, measured; 0 for an ideally free flywheel, 1 for a locked one).

Why ``J_f`` is not simply added: with the motor open-circuit the flywheel turns on its
own bearing, so, were the bearing frictionless, no torque would reach it and its absolute
angle ``theta = phi + psi`` would not swing with the hull; the hull's equation (subtract
the two rows of the mass matrix, physics.md section 2) is
``(J_h + lambda66) phi'' = -c (phi - phi_n) + damping - J_f theta''``. A real bearing's
friction drags the flywheel part of the way (at a 0.01 rad swing and 2 mN m of dry
friction, by 20 to 50 %), which would add ``kappa J_f`` to the swinging inertia and bias
lambda66 by whole percents on a light hull. So ``kappa`` is *measured* per period: the
in-phase part of the recorded ``theta`` regressed on ``phi`` (with a quadrature term and
a slow spin trend), and ``lambda66 = J_total - J_h - kappa J_f``. A flywheel locked to
the hull gives ``kappa = 1`` by itself; a record that says ``experiment.flywheel:
"locked"`` is held to that.

Damping that is not linear: the ``1 - zeta^2`` correction is exact only for linear
damping. With the amplitude-dependent (quadratic) damping of a real hull the per-period
estimates drift with amplitude; on the simulated Wigley rig the drift is about
``+zeta^2 J_total`` (a full correction's worth, 0.1 to 4 % of lambda66). Rather than
trust one amplitude, the per-period values are fitted against ``zeta^2`` and the fit is
read at ``zeta = 0`` (vanishing damping, where every damping law gives ``T_d = T_n``).
The slope has a prior ``0 +- J_total`` so that a decay whose ``zeta`` hardly changes
(linear damping) falls back to the plain mean with ``zeta^2 J_total`` of uncertainty.
The line is trusted to half of what it extrapolates beyond the least-damped period
(``beta zeta_min^2 / 2`` is added to the uncertainty: the drift need not be exactly
linear in ``zeta^2``).

Uncertainty (95 %): per period, extremum-timing noise from the local fits' covariance
and the flywheel-follow fit's; neighbouring periods share an extremum, so each period's
variance is doubled; the intercept's variance is widened by the Birge ratio when the
periods scatter beyond that noise; runs are pooled by inverse variance.

Only the record's samples and ``rig`` block are used; never ``truth``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.identify.common import IdentificationError, Result, local_fit, pooled_interval, segment

Z95 = 1.96
MIN_SWING_COUNTS = 60  # hull-encoder counts: smaller swings are left out (quantisation)


@dataclass
class Extremum:
    """One extremum of a free decay: its time (s), hull angle (rad) and 1-sigma timing error (s)."""

    t: float  # s
    phi: float  # rad
    sigma_t: float  # s, 1-sigma timing error from the local fit


@dataclass
class Period:
    """One full swing, extremum k to k + 2."""

    run: str
    t_mid: float  # s, time of the middle extremum
    swing: float  # rad, peak-to-peak swing before the middle extremum
    T_d: float  # s, damped period
    zeta: float  # -, damping ratio from the half-swing decrement at the middle extremum
    J_total: float  # kg m^2
    kappa: float  # -, share of the hull's swing the flywheel follows (bearing drag)
    lambda66: float  # kg m^2
    sigma_stat: float  # kg m^2, from timing noise and the flywheel-follow fit
    correction: float  # kg m^2, zeta^2 J_total: what the 1 - zeta^2 factor took off


def identify_free_decay(records: list[RunRecord]) -> Result:
    """lambda66 (kg m^2) from one or more free-decay records, with a 95 % interval."""
    if not records:
        raise IdentificationError("free-decay method: no records given")
    periods: list[Period] = []
    per_run, sigmas, slopes = [], [], []
    for rec in records:
        run_periods = _run_periods(rec)
        periods += run_periods
        value, sigma, slope = _zero_damping_fit(run_periods)
        per_run.append(value)
        sigmas.append(sigma)
        slopes.append(slope)
    value, lo, hi = pooled_interval(np.array(per_run), np.array(sigmas), z=Z95)
    return Result(method="free-decay", lambda66=value, ci95=(lo, hi), n_intervals=len(periods),
                  details={"n_runs": len(records), "per_run": per_run, "per_run_sigma": sigmas,
                           "slope_vs_zeta2": slopes, "mean_period_s": float(np.mean([p.T_d for p in periods])),
                           "zeta_range": [float(min(p.zeta for p in periods)), float(max(p.zeta for p in periods))],
                           "intervals": [asdict(p) for p in periods]})


def _run_periods(rec: RunRecord) -> list[Period]:
    kind = rec.experiment.get("kind")
    if kind != "free-decay":
        raise IdentificationError(f"{rec.name}: the free-decay method needs a record of kind 'free-decay', "
                                  f"not {kind!r}; simulate one with `addedinertia simulate --kind free-decay`")
    rig = rec.known
    J_h, c = rig.J_hull, rig.c_torsion
    flywheel = rec.experiment.get("flywheel", "free")
    if flywheel not in ("free", "locked"):
        raise IdentificationError(f"{rec.name}: experiment.flywheel is {flywheel!r}; expected 'free' or 'locked'")
    J_f = rig.J_flywheel
    free = segment(rec, "free")
    if free is None:
        raise IdentificationError(f"{rec.name}: no 'free' phase (the decay with the motor passive)")
    t, phi, theta = rec.t[free], rec["phi"][free], rec["phi"][free] + rec["psi"][free]
    counts = rig.phi_counts
    min_swing = MIN_SWING_COUNTS * 2 * math.pi / counts if counts > 0 else 1e-6
    ext = _extrema(t, phi)
    periods = []
    for k in range(len(ext) - 2):
        a, b, e = ext[k], ext[k + 1], ext[k + 2]
        s1, s2 = abs(b.phi - a.phi), abs(e.phi - b.phi)
        if min(s1, s2) < min_swing or (b.phi - a.phi) * (e.phi - b.phi) >= 0:
            continue
        T_d = e.t - a.t
        delta = math.log(s1 / s2)
        zeta = max(delta, 0.0) / math.sqrt(math.pi**2 + delta**2)
        w_n = 2.0 * math.pi / T_d / math.sqrt(1.0 - zeta**2)
        J_total = c / w_n**2
        sigma_T = math.hypot(a.sigma_t, e.sigma_t)
        kappa, s_kappa = (1.0, 0.0) if flywheel == "locked" else _flywheel_follow(t, phi, theta, a.t, e.t)
        periods.append(Period(run=rec.name, t_mid=b.t, swing=s1, T_d=T_d, zeta=zeta, J_total=J_total,
                              kappa=kappa, lambda66=J_total - J_h - kappa * J_f,
                              sigma_stat=math.hypot(2.0 * J_total * sigma_T / T_d, J_f * s_kappa),
                              correction=zeta**2 * J_total))
    if len(periods) < 2:
        raise IdentificationError(f"{rec.name}: only {len(periods)} usable full swing(s) in the free phase "
                                  f"(swings under {MIN_SWING_COUNTS} encoder counts are left out); "
                                  "record more periods or twist further (alpha)")
    return periods


def _zero_damping_fit(periods: list[Period]) -> tuple[float, float, float]:
    """One run: ``lambda66_k = lambda66 + beta zeta_k^2`` by weighted least squares.

    Returns the intercept (lambda66 at vanishing damping), its 1-sigma and the slope
    ``beta`` (kg m^2). The prior row ``beta = 0 +- J_total`` keeps the fit defined when
    ``zeta`` barely varies.
    """
    lam = np.array([p.lambda66 for p in periods])
    z2 = np.array([p.zeta**2 for p in periods])
    # Neighbouring periods share an extremum: double each variance (about half are independent).
    sig = np.sqrt(2.0) * np.maximum(np.array([p.sigma_stat for p in periods]), 1e-12)
    J_scale = float(np.median([p.J_total for p in periods]))
    X = np.vstack([np.column_stack([np.ones_like(z2), z2]) / sig[:, None], [[0.0, 1.0 / J_scale]]])
    y = np.concatenate([lam / sig, [0.0]])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    cov = np.linalg.inv(X.T @ X)
    resid = (lam - coef[0] - coef[1] * z2) / sig
    chi2 = float(resid @ resid) / max(len(lam) - 2, 1)
    # The straight line is trusted to half of what it extrapolates beyond the
    # least-damped period (the drift need not be exactly linear in zeta^2).
    reach = 0.5 * abs(float(coef[1])) * float(z2.min())
    return float(coef[0]), float(np.sqrt(cov[0, 0] * max(chi2, 1.0) + reach**2)), float(coef[1])


def _flywheel_follow(t, phi, theta, ta: float, tb: float) -> tuple[float, float]:
    """In-phase ratio of the flywheel's absolute swing ``theta`` to the hull's over [ta, tb], and its sigma.

    ``theta ~ kappa phi + q phi' + (slow spin: cubic in time)``; the quadrature term
    ``q`` takes up the part of the drag that acts like damping.
    """
    sel = (t >= ta) & (t <= tb)
    if sel.sum() < 20:
        return 0.0, 0.0
    ts, ph = t[sel] - 0.5 * (ta + tb), phi[sel]
    dt = float(np.median(np.diff(ts)))
    rate = np.gradient(ph, dt)
    rate = np.convolve(rate, np.ones(21) / 21.0, mode="same")  # quantised differences: smooth
    X = np.column_stack([ph, rate, np.ones_like(ts), ts, ts**2, ts**3])
    coef, *_ = np.linalg.lstsq(X, theta[sel], rcond=None)
    resid = theta[sel] - X @ coef
    var = float(resid @ resid) / max(len(ts) - X.shape[1], 1)
    cov = var * np.linalg.pinv(X.T @ X)
    return float(coef[0]), float(np.sqrt(max(cov[0, 0], 0.0)))


def _extrema(t: np.ndarray, phi: np.ndarray) -> list[Extremum]:
    """Extrema of a decaying swing: sign changes of a smoothed rate, refined by local quartics."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    dt = float(np.median(np.diff(t)))
    n = max(7, int(round(0.2 / dt)) | 1)
    if len(phi) <= 3 * n:
        raise IdentificationError(f"free phase of {len(phi)} samples is too short for a decay analysis")
    rate = savgol_filter(phi, n, 3, deriv=1, delta=dt)
    idx = np.nonzero(np.sign(rate[1:]) * np.sign(rate[:-1]) < 0)[0] + 1
    if len(idx) < 3:
        raise IdentificationError(f"only {len(idx)} extrema in the free phase; expected a decay of several swings")
    half = float(np.median(np.diff(idx))) * dt  # s, provisional half period
    kept = [idx[0]]
    for k in idx[1:]:  # noise near a turning point: keep one sign change per half period
        if (t[k] - t[kept[-1]]) > 0.5 * half:
            kept.append(k)
    h = 0.15 * half
    out = []
    for k in kept:
        tc = t[k]
        if tc - h < t[0] or tc + h > t[-1]:
            continue
        coef, cov, _ = local_fit(t, phi, tc, h, full=True, degree=4)
        poly = np.polynomial.Polynomial(coef)
        d1, d2 = poly.deriv(), poly.deriv(2)
        s = 0.0
        for _ in range(8):  # Newton on the rate's root
            s -= d1(s) / d2(s)
        if abs(s) > h:
            continue
        grad = np.array([j * s ** (j - 1) if j else 0.0 for j in range(len(coef))])  # d(rate)/d(coef)
        sigma_t = float(np.sqrt(max(grad @ cov @ grad, 0.0))) / abs(float(d2(s)))
        out.append(Extremum(t=float(tc + s), phi=float(poly(s)), sigma_t=sigma_t))
    return out
