"""The energy method's pooling: from the balance at many boundary angles to one run's lambda66 and its
uncertainty (a dense set of angles averaged with smooth Hann weights, or separate angles pooled by
inverse variance), with the first pass that gives the total inertia for the damping law.

Part of the energy method (:mod:`addedinertia_env.identify.energy`), which pools the runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.identify.common import line_fit, pooled_interval
from addedinertia_env.identify.energy_balance import Interval, RunBalance


# Boundary angles as fractions of the way from the calibrated neutral to the stop phi2:
# the patent drops the nearly uniform middle of the stroke, and too near the stop the
# kinetic energy (the denominator) vanishes. ``DEFAULT_FRACTIONS`` spans the range; the
# balance is evaluated at ``DENSE_ANGLES`` angles across it and averaged with Hann weights.
DEFAULT_FRACTIONS = (0.25, 0.75)
DENSE_ANGLES = 41


def hann_weights(fractions: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Smooth weights over boundary-angle fractions, zero at ``lo`` and ``hi``, peak in the middle."""
    x = (np.asarray(fractions, float) - lo) / (hi - lo)
    return np.where((x > 0) & (x < 1), np.sin(np.pi * np.clip(x, 0, 1)) ** 2, 0.0)


@dataclass
class RunEstimate:
    """One run's lambda66 and its 1-sigma (kg m^2) with the boundary-angle intervals behind them."""

    value: float
    sigma: float
    intervals: list[Interval]
    counts: tuple[int, int] | None = None  # (usable, all) angles when ``intervals`` is not kept
    # the 1-sigma parts (kg m^2): "rate", "current", "common", "trend", and "slope_noise" (kg m^2 per rad,
    # the rate noise of the per-angle values' slope): what a correction of the per-angle values needs to
    # rebuild the budget (identify/memory_energy.py)
    parts: dict | None = None
    # the motor work's scale, its relative 1-sigma in the budget and where it came from
    # (RunBalance.torque_scale_summary)
    torque_scale: dict | None = None


def run_estimate(rec: RunRecord, work: str, fractions, asymmetry_correction: bool,
                 interval_details: bool = True) -> RunEstimate:
    """One record's estimate (:class:`RunEstimate`): the first pass, then every boundary angle's
    interval combined (or, with ``interval_details=False``, the same numbers from the angles' columns)."""
    balance, phi1_list, weights, first = prepared_balance(rec, work, fractions, asymmetry_correction,
                                                          first_value_only=True)
    if not np.isfinite(first.value):
        return first
    phi1 = np.asarray(phi1_list, dtype=float)
    estimate = None
    if not interval_details and weights is not None:  # the numbers alone, from the angles' columns
        estimate = _dense_from_columns(balance, balance.interval_columns(phi1), weights)
    if estimate is None or not np.isfinite(estimate.value):
        estimate = _combine(balance, balance.intervals(phi1), weights)
    estimate.torque_scale = balance.torque_scale_summary()
    return estimate


def prepared_balance(rec: RunRecord, work: str = "reaction", fractions=DEFAULT_FRACTIONS,
                     asymmetry_correction: bool = True, first_value_only: bool = False):
    """A record's :class:`RunBalance` after the first pass, its boundary angles (rad), their
    weights (None: pooled by inverse variance) and the first pass's estimate.

    The first pass (no dissipation-mismatch correction) gives the total inertia that the
    damping-law fit and the hull's energy at rest then use. ``first_value_only``: when the
    first estimate is finite, only its value is computed (its ``sigma`` is nan and it holds
    no intervals; the value is the same number); the full estimate otherwise.
    """
    balance = RunBalance(rec, work, asymmetry_correction)
    given = rec.experiment.get("phi1")
    dense = not given and len(fractions) == 2
    if given:
        phi1_list, weights = [float(x) for x in given], None
    elif dense:
        f, weights = _dense_fractions(fractions[0], fractions[1], DENSE_ANGLES)
        phi1_list = list(balance.phi_n + f * (balance.phi2 - balance.phi_n))
    else:
        phi1_list, weights = [balance.phi_n + x * (balance.phi2 - balance.phi_n) for x in fractions], None
    first = None
    if first_value_only and weights is not None:  # the Hann-weighted value alone (what the second pass needs)
        value = balance.weighted_value(np.asarray(phi1_list, dtype=float), weights)
        if np.isfinite(value):
            first = RunEstimate(value, float("nan"), [])
    if first is None:
        first = _combine(balance, balance.intervals(np.asarray(phi1_list, dtype=float)), weights)
    if np.isfinite(first.value):
        balance.use_total_inertia(first.value + balance.J_h)
    return balance, phi1_list, weights, first


def _dense_fractions(lo, hi, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.linspace(lo, hi, n)`` and their :func:`hann_weights` over ``(lo, hi)``: kept (read-only) for
    float bounds, which give the same arrays every time; computed afresh for any other kind of number."""
    if type(lo) is float and type(hi) is float:
        return _dense_fractions_of_floats(lo, hi, n)
    f = np.linspace(lo, hi, n)
    return f, hann_weights(f, lo, hi)


@lru_cache(maxsize=16)
def _dense_fractions_of_floats(lo: float, hi: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    f = np.linspace(lo, hi, n)
    weights = hann_weights(f, lo, hi)
    for x in (f, weights):
        x.flags.writeable = False
    return f, weights


def _combine(balance: "RunBalance", intervals: list[Interval], weights) -> RunEstimate:
    """One run's estimate from its boundary angles: Hann-weighted (dense) or inverse-variance pooled."""
    ok = [k for k, iv in enumerate(intervals) if not iv.rejected]
    if not ok:
        return RunEstimate(float("nan"), float("inf"), intervals)
    lam = np.array([intervals[k].lambda66 for k in ok])
    if weights is None:  # separate angles, pooled by inverse variance (Birge-widened)
        s_ind = np.array([intervals[k].sigma_independent for k in ok])
        value, lo, _ = pooled_interval(lam, s_ind)
        s_common = float(np.median([intervals[k].sigma_common for k in ok]))
        for iv in intervals:
            iv.weight = 0.0 if iv.rejected else 1.0
        return RunEstimate(value, float(np.hypot((value - lo) / 1.96, s_common)), intervals)
    g = np.array([weights[k] for k in ok])
    if g.sum() <= 0:
        return RunEstimate(float("nan"), float("inf"), intervals)
    g = g / g.sum()
    for iv in intervals:
        iv.weight = 0.0
    for gk, k in zip(g, ok):
        intervals[k].weight = float(gk)
    used = [intervals[k] for k in ok]
    value, sigma, parts = _dense_estimate(balance, g, lam, [iv.phi1 for iv in used], [iv.lambda66 for iv in used],
                                   [iv.w1f for iv in used], [iv.w1r for iv in used],
                                   [iv.terms["s_current"] for iv in used], [iv.sigma_common for iv in used],
                                   [iv.sigma_independent for iv in used],
                                   [iv.terms["rate_kernel_f"] for iv in used], [iv.terms["rate_kernel_r"] for iv in used])
    for iv in used:  # the kernels are bulky; keep the JSON small
        iv.terms.pop("rate_kernel_f", None)
        iv.terms.pop("rate_kernel_r", None)
    return RunEstimate(value, sigma, intervals, parts=parts)


def _dense_from_columns(balance: "RunBalance", cols: dict, weights: np.ndarray) -> RunEstimate:
    """:func:`_combine`'s Hann-weighted estimate from :meth:`RunBalance.interval_columns` (the same
    numbers, no :class:`Interval` records; nan when no angle is usable)."""
    good = cols["good"]
    if not len(good):
        return RunEstimate(float("nan"), float("inf"), [], (0, len(cols["phi1"])))
    rows = np.nonzero(~cols["rejected"])[0]
    ok = good[rows].tolist()
    counts = (len(ok), len(cols["phi1"]))
    if not ok:
        return RunEstimate(float("nan"), float("inf"), [], counts)
    if isinstance(weights, np.ndarray) and weights.dtype == np.float64 and weights.ndim == 1:
        g = weights[good[rows]]  # the same numbers as np.array([weights[k] for k in ok])
    else:
        g = np.array([weights[k] for k in ok])
    total = g.sum()
    if total <= 0:
        return RunEstimate(float("nan"), float("inf"), [], counts)
    g = g / total
    lam = np.asarray(cols["lam"], dtype=float)[rows]
    lam_list = lam.tolist()  # the Python floats the Interval records hold

    def pick(name):
        return np.asarray(cols[name], dtype=float)[rows].tolist()

    fits = np.empty(2 * len(rows), dtype=np.int64)  # the used angles' forward and reverse fits, in turn
    fits[0::2], fits[1::2] = 2 * rows, 2 * rows + 1
    value, sigma, parts = _dense_estimate(balance, g, lam, cols["phi1"][good[rows]].tolist(), lam_list,
                                   pick("w1f"), pick("w1r"), pick("s_current"), pick("s_common"),
                                   pick("s_independent"), None, None, (cols["windows"], fits))
    return RunEstimate(value, sigma, [], counts, parts)


def _dense_estimate(balance: "RunBalance", g: np.ndarray, lam: np.ndarray, phi1: list, lam_list: list,
                    w1f: list, w1r: list, s_current: list, s_common: list, s_independent: list,
                    kernels_f: list | None, kernels_r: list | None, windows=None) -> tuple[float, float, dict]:
    """The Hann-weighted lambda66 of a run and its 1-sigma (kg m^2) from its usable angles: normalised
    weights ``g``, per-angle values ``lam`` (array) and, per angle, ``phi1``, ``lam_list`` (the same values
    as Python floats), rates, uncertainty parts and rate kernels ``(indices, weights)``; or, instead of
    the kernels' lists, ``windows``: ``(crossing_fits' windows, the used fits in order)``; and the 1-sigma
    parts (:attr:`RunEstimate.parts`)."""
    value = float(g @ lam)

    def noise_of(weights):  # the rate noise of a linear combination of the angles' values
        if windows is not None:
            return balance.rate_sigma_of_windows(weights, lam_list, w1f, w1r, *windows)
        return balance.rate_sigma(weights, lam_list, w1f, w1r, kernels_f, kernels_r)

    s_rate = noise_of(g)
    s_cur = float(g @ np.array(s_current))
    s_com = float(g @ np.array(s_common))
    # What the angles' values do beyond their modelled noise is taken from the values themselves:
    # their scatter about a line enters the average as its autocovariance says, and the line's
    # slope, less its own rate noise (the same kernels with the slope's least-squares weights),
    # is structure (_trend_excess).
    p = np.array(phi1)
    s_slope = noise_of(_slope_weights(p)) if len(lam) >= 6 else 0.0
    s_trend = _trend_excess(p, lam, np.array(s_independent), g, s_slope)
    parts = {"rate": s_rate, "current": s_cur, "common": s_com, "trend": s_trend, "slope_noise": s_slope}
    return value, float(np.sqrt(s_rate**2 + s_cur**2 + s_com**2 + s_trend**2)), parts


def _slope_weights(phi1: np.ndarray) -> np.ndarray:
    """Weights ``c`` with ``c @ lam`` the least-squares slope of ``lam`` over ``phi1``."""
    d = phi1 - phi1.mean()
    ss = float(d @ d)
    return d / ss if ss > 0 else np.zeros_like(d)


TREND_LAGS = 5  # angles: the Bartlett window of the residuals' autocovariance (41 angles over half the stroke)


def _trend_excess(phi1: np.ndarray, lam: np.ndarray, s: np.ndarray, g: np.ndarray, s_slope: float = 0.0) -> float:
    """What the per-angle estimates ``lam`` (kg m^2, at angles ``phi1``, weights ``g``, modelled per-angle
    noise ``s``) add to the run's 1-sigma beyond that noise, kg m^2: two parts.

    * Scatter about a straight line in phi1 beyond ``s``: the variance of the residuals' ``g``-weighted
      mean, estimated from the residuals themselves (their autocovariance over :data:`TREND_LAGS`
      neighbours, Bartlett-weighted: a heteroskedasticity-and-autocorrelation-consistent estimate),
      times the fraction of their weighted mean square that ``s`` does not explain. Point-to-point
      scatter averages out over the angles as its own correlation says, not as a fixed number of
      independent blocks; scatter the modelled noise explains is already in the rate and current parts.
    * The line's slope, less its own noise ``s_slope`` (kg m^2 per rad): the estimate then depends on
      where the boundary is taken, and a quarter of the end-to-end change is kept."""
    if len(lam) < 6:
        return 0.0
    coef = line_fit(phi1, lam)
    resid = lam - ((0.0 * phi1 + coef[0]) * phi1 + coef[1])  # np.polyval(coef, phi1), Horner from zero
    u = g * resid
    n = len(u)
    var = float(u @ u)
    for k in range(1, min(TREND_LAGS, n - 1) + 1):
        var += 2.0 * (1.0 - k / (TREND_LAGS + 1.0)) * float(u[k:] @ u[:-k])
    mean_square = float(np.sum(g * resid**2))
    unexplained = max(1.0 - float(np.sum(g * s**2)) / mean_square, 0.0) if mean_square > 0 else 0.0
    scatter = math.sqrt(max(var, 0.0) * unexplained)
    # The mean over the range equals the line's value at the weighted centre; a slope means
    # the estimate depends on where the boundary is taken: a quarter of the end-to-end change
    # is kept as uncertainty.
    slope = math.sqrt(max(float(coef[0]) ** 2 - s_slope**2, 0.0))
    slope_part = 0.25 * slope * float(phi1.max() - phi1.min())  # np.ptp's two reductions
    return float(np.hypot(scatter, slope_part))
