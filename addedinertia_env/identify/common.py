"""Shared pieces of the identification methods: the result type and small numerics."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.records.scan_kernels import bitwise_constant
from addedinertia_env.records.series_stats import median_step
from addedinertia_env.identify.fit_kernels import lstsq as rounded_lstsq


# Plausible added inertia relative to the hull's own (rig.J_hull: hull + rod + frame + stator). A floating
# hull weighs the water it displaces, and Lamb's yaw coefficient k' of a prolate spheroid (L/B 4 to 10:
# 0.54 to 0.86, Lamb 1932 art. 115; Newman 1977 table 4.1) puts its added inertia below that water's own
# moment of inertia: lambda66 / J_hull is of order 1 (1.1 to 2.0 over the shared dev sets' seven hulls and
# the presets, shell-built model hulls being lighter than solid ones). Above LAMBDA_RATIO_WARN the result
# carries a warning; above LAMBDA_RATIO_REFUSE no hull on a rod can be that light against its water (J_hull
# in the wrong unit, g m^2 for kg m^2, or a typo): refused. The motion shows only J_hull + lambda66, so a
# wrong J_hull moves lambda66 by the same amount and nothing else in the record can flag it.
LAMBDA_RATIO_WARN = 10.0
LAMBDA_RATIO_REFUSE = 1000.0


class IdentificationError(ValueError):
    """A record that a method cannot use (wrong kind, missing phase, nothing usable)."""


@dataclass
class Result:
    """What every method returns: ``lambda66`` (kg m^2) with a 95 % interval."""

    method: str
    lambda66: float
    ci95: tuple[float, float]
    n_intervals: int
    details: dict[str, Any] = field(default_factory=dict)

    def to_json(self, verbose: bool = False) -> dict[str, Any]:
        """The result as a JSON-ready dict (lambda66 and interval in kg m^2, details); the per-interval list only when ``verbose``."""
        out = {"method": self.method, "lambda66": self.lambda66, "ci95": list(self.ci95),
               "n_intervals": self.n_intervals}
        details = dict(self.details)
        if not verbose:
            details.pop("intervals", None)
        out.update(details)
        return out


def segment(rec: RunRecord, phase: str) -> slice | None:
    """The first contiguous block of samples in ``phase``, or None (``rec.views.phase_blocks``)."""
    return rec.views.phase_blocks.first(phase)


def largest_gap(rec: RunRecord, a: int, b: int) -> tuple[float, float] | None:
    """The largest gap in ``t`` between samples ``a`` and ``b`` (inclusive) longer than the
    spec's reporting threshold (five nominal periods), as ``(t_before, gap_s)``, or None."""
    from addedinertia_env.records.record import MAX_GAP_PERIODS  # noqa: PLC0415

    period = rec.known.dt
    dt = np.diff(rec.t[a:b + 1])
    if not dt.size:
        return None
    k = int(np.argmax(dt))
    if dt[k] <= MAX_GAP_PERIODS * period * (1 + 1e-6):
        return None
    return float(rec.t[a + k]), float(dt[k])


def check_physical(result: "Result", records: list[RunRecord]) -> "Result":
    """Refuse a result no rig can have: a non-finite lambda66 or interval, a total inertia
    ``J_hull + lambda66 <= 0``, an interval wholly below zero (an added inertia is >= 0), or a
    lambda66 over :data:`LAMBDA_RATIO_REFUSE` x ``J_hull``; warn (``details['warnings']``, which
    ``addedinertia identify`` prints) beyond :data:`LAMBDA_RATIO_WARN` x ``J_hull``.

    Such a value means the records contradict their own ``rig`` blocks (wrong units, a bad
    calibration, a broken stretch of samples); it is an :class:`IdentificationError` that
    names the files, never a result.
    """
    names = ", ".join(sorted({rec.name for rec in records})) or "<no records>"
    lam = float(result.lambda66)
    lo, hi = (float(x) for x in result.ci95)
    if not all(np.isfinite([lam, lo, hi])):
        raise IdentificationError(f"{result.method} method on {names}: lambda66 = {lam!r} with interval "
                                  f"[{lo!r}, {hi!r}]; expected finite numbers (the records do not determine it)")
    j_hull = min(rec.known.J_hull for rec in records) if records else 0.0
    if j_hull + lam <= 0 or hi < 0:
        raise IdentificationError(
            f"{result.method} method on {names}: lambda66 = {lam:.6g} kg m^2 (95 % interval {lo:.6g} .. {hi:.6g}) "
            f"is physically impossible; expected an added inertia >= 0 and J_hull + lambda66 > 0 (J_hull = "
            f"{j_hull:g} kg m^2): the records contradict their rig blocks (units, calibration, broken samples?)")
    ratio = lam / j_hull
    if ratio > LAMBDA_RATIO_REFUSE:
        raise IdentificationError(
            f"{result.method} method on {names}: lambda66 = {lam:.6g} kg m^2 is {ratio:.3g} x rig.J_hull = {j_hull:g} "
            f"kg m^2; expected lambda66 / J_hull of order 1 (at most {LAMBDA_RATIO_REFUSE:g}): the motion measures "
            f"J_hull + lambda66 = {j_hull + lam:.6g} kg m^2, so J_hull must be right for lambda66 to be; is rig.J_hull "
            "in kg m^2 (hull + rod + frame + stator)?")
    if ratio > LAMBDA_RATIO_WARN:
        message = (f"lambda66 = {lam:.6g} kg m^2 is {ratio:.3g} x rig.J_hull = {j_hull:g} kg m^2, beyond the plausible "
                   f"range (lambda66 / J_hull up to {LAMBDA_RATIO_WARN:g}); the motion measures J_hull + lambda66, so "
                   "check rig.J_hull (hull + rod + frame + stator, kg m^2)")
        result.details.setdefault("warnings", []).append(message)
    return result


def local_fit(t: np.ndarray, y: np.ndarray, tc: float, half_width: float, full: bool = False, degree: int = 3):
    """Least-squares polynomial ``y ~ a0 + a1 s + a2 s^2 + ...``, ``s = t - tc``, over ``|s| <= half_width``.

    A cubic by default: a quadratic over a symmetric window biases the rate by
    (third derivative) x h^2 / 10, which is 2e-4 of the rate for a 4 s period and h = 30 ms.

    Returns the coefficients (``a1`` is the rate at ``tc``); with ``full``, also their
    covariance (from the residual scatter, at least the quantisation floor) and the RMS.
    """
    sel = np.abs(t - tc) <= half_width
    if sel.sum() < degree + 3:
        raise IdentificationError(f"too few samples ({int(sel.sum())}) around t = {tc:.4f} s for a local fit")
    s = t[sel] - tc
    X = np.vander(s, degree + 1, increasing=True)
    coef, *_ = rounded_lstsq(X, y[sel], rcond=None)
    if not full:
        return coef
    resid = y[sel] - X @ coef
    dof = max(int(sel.sum()) - degree - 1, 1)
    var = max(float(resid @ resid) / dof, 1e-24)
    cov = var * np.linalg.inv(X.T @ X)
    return coef, cov, float(np.sqrt(var))


def power_fit(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
    """Least-squares power series ``y ~ c0 + c1 x + ... + c_degree x^degree`` of 1-D float samples: the
    coefficients ``np.polynomial.polynomial.polyfit(x, y, degree)`` returns, the same numbers by the same
    steps (each column of the design scaled to unit norm, ``np.linalg.lstsq`` with ``rcond = n eps``, the
    scale divided back out; numpy's RankWarning when the design is rank-deficient), without its argument
    handling (a few microseconds a call on the energy method's short rest-rate fits)."""
    x, y = np.asarray(x) + 0.0, np.asarray(y) + 0.0
    if x.ndim != 1 or y.ndim != 1 or not len(x) or len(x) != len(y) or degree < 0:
        return np.polynomial.polynomial.polyfit(x, y, degree)  # numpy's checks and messages
    columns = np.empty((degree + 1, len(x)))  # the transposed design: row j holds x**j
    columns[0] = x * 0 + 1
    for j in range(1, degree + 1):
        columns[j] = columns[j - 1] * x if j > 1 else x
    scale = np.sqrt(np.square(columns).sum(1))
    scale[scale == 0] = 1
    coef, _, rank, _ = rounded_lstsq(columns.T / scale, y, len(x) * np.finfo(x.dtype).eps)
    if rank != degree + 1:
        warnings.warn("The fit may be poorly conditioned", np.exceptions.RankWarning, stacklevel=2)
    return coef / scale


def line_fit(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``np.polyfit(x, y, 1)`` of 1-D float samples, ``[slope, intercept]``: the same numbers by the same
    steps (columns ``x``, 1 scaled to unit norm, ``np.linalg.lstsq`` with ``rcond = n eps``, the scale
    divided back out; numpy's RankWarning when rank-deficient), without its argument handling."""
    x, y = np.asarray(x) + 0.0, np.asarray(y) + 0.0
    if x.ndim != 1 or y.ndim != 1 or len(x) < 2 or len(x) != len(y):
        return np.polyfit(x, y, 1)  # numpy's checks and messages
    design = np.empty((len(x), 2))  # np.vander(x, 2)
    design[:, 1] = 1
    design[:, 0] = x
    scale = np.sqrt((design * design).sum(axis=0))
    design /= scale
    coef, _, rank, _ = rounded_lstsq(design, y, len(x) * np.finfo(x.dtype).eps)
    if rank != 2:
        warnings.warn("Polyfit may be poorly conditioned", np.exceptions.RankWarning, stacklevel=2)
    return coef / scale


def pooled_interval(values: np.ndarray, sigmas: np.ndarray, z: float = 1.96) -> tuple[float, float, float]:
    """Inverse-variance mean of independent estimates, with a 95 % interval.

    When the estimates scatter more than their sigmas allow (reduced chi-square > 1), the
    interval is widened by the Birge ratio.
    """
    values, sigmas = np.asarray(values, float), np.maximum(np.asarray(sigmas, float), 1e-300)
    w = 1.0 / sigmas**2
    mean = float(np.sum(w * values) / np.sum(w))
    sigma = float(np.sqrt(1.0 / np.sum(w)))
    if len(values) > 1:
        chi2 = float(np.sum(w * (values - mean) ** 2)) / (len(values) - 1)
        sigma *= float(np.sqrt(max(chi2, 1.0)))
    return mean, mean - z * sigma, mean + z * sigma


def smooth_angle(t: np.ndarray, angle: np.ndarray, window_s: float = 0.04, degree: int = 3) -> np.ndarray:
    """Centred Savitzky-Golay smoothing (cubic by default) of an encoder angle.

    Work sums ``sum(torque_k * dphi_k)`` over raw quantised increments are biased when
    the controller's torque reacted to the same quantisation errors (a PD sees ``-e_k``
    and ``dphi_k`` contains ``-e_k``): the bias is ``J Kd w0 N sigma_q^2``, several
    percent of the reverse work for a 17-bit encoder. Smoothing over ~40 samples spreads
    each sample's error over the window and removes that correlation.
    """
    return smooth_angles(t, [angle], window_s, degree)[0]


def smooth_angles(t: np.ndarray, angles, window_s: float = 0.04, degree: int = 3) -> list[np.ndarray]:
    """:func:`smooth_angle` of several angle series sampled at the same instants ``t``."""
    if len(t) < 2:  # a block of one sample (a bench's sensed brake a sample off the phase change)
        return [np.asarray(a, dtype=float) for a in angles]
    dt = float(median_step(t))
    n = max(degree + 2, int(round(window_s / dt)) | 1)
    return [a.astype(float) if len(a) <= n else savgol(a, n, degree) for a in angles]


def prepare() -> None:
    """Load now what the methods load on first use (``scipy.signal``, about a second of imports; numba's kernels),
    so that a process's first identification costs what the others do (the batched env calls this
    when it is built to score episodes); the compiled kernels are loaded (or compiled) here too."""
    from scipy.signal import savgol_coeffs  # noqa: F401, PLC0415

    from addedinertia_env.records.scan_kernels import warm_up as warm_up_scans  # noqa: PLC0415
    from addedinertia_env.identify.series_kernels import warm_up  # noqa: PLC0415

    from addedinertia_env.identify.balance_kernels import warm_up as warm_up_balance  # noqa: PLC0415

    warm_up()
    warm_up_scans()
    warm_up_balance()
    from addedinertia_env.identify.fit_kernels import warm_up as warm_up_fits  # noqa: PLC0415

    warm_up_fits()


@lru_cache(maxsize=64)
def _savgol_maps(window: int, degree: int, deriv: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The filter's taps (for ``np.convolve``) and the edge maps of :func:`savgol`, delta 1.

    The edge maps take the first (last) ``window`` samples to the first (last) ``window // 2``
    outputs: the least-squares polynomial of ``degree`` through the window, differentiated
    ``deriv`` times, evaluated there (scipy's ``mode='interp'``). All three come from the
    window's Gram polynomials in closed form (:mod:`.savgol_taps`): exact to a few units in the
    last place for any window and the same bits on every CPU (scipy's ``savgol_coeffs`` solves a
    Vandermonde problem with the machine's LAPACK: 1e-8 off for a quintic over 201 samples, and
    wholly wrong over 2001, a 0.2 s window at 10 kHz).
    """
    from addedinertia_env.identify.savgol_taps import conv_taps, weights  # noqa: PLC0415

    taps = conv_taps(window, degree, deriv)
    half = window // 2
    offsets = np.arange(window, dtype=float) - half  # each output's position in its window
    left = weights(window, degree, deriv, offsets[:half])
    right = weights(window, degree, deriv, offsets[window - half:])
    for m in (left, right):
        m.flags.writeable = False
    return taps, left, right


def savgol(x: np.ndarray, window: int, degree: int, deriv: int = 0, delta: float = 1.0, *,
           interior: np.ndarray | None = None) -> np.ndarray:
    """Savitzky-Golay filter of a 1-D series: ``scipy.signal.savgol_filter(x, window, degree,
    deriv, delta)`` (mode ``interp``) to float rounding, about 5x faster (cached maps, one
    ``np.convolve``). ``window`` odd and at most ``len(x)``; ``delta``: the sample spacing
    (the derivative's unit is x's per ``delta``'s unit to the ``deriv``). ``interior``: the
    filter's ``np.convolve(x, taps, "valid")`` when the caller already has it
    (:class:`SharedSavgol`), before the division by ``delta``.
    """
    x = np.asarray(x, dtype=float)
    if window % 2 != 1 or window > len(x) or degree >= window:
        raise ValueError(f"savgol: window {window} must be odd, > degree {degree} and <= len(x) = {len(x)}")
    taps, left, right = _savgol_maps(int(window), int(degree), int(deriv))
    half = window // 2
    y = np.empty(len(x))
    # the outputs whose window lies inside x ('valid': the same dot products as the interior of 'same',
    # whose edge outputs the maps replace)
    y[half:len(x) - half] = _valid_convolution(x, taps) if interior is None else interior
    y[:half] = left @ x[:window]
    y[len(x) - half:] = right @ x[len(x) - window:]
    if deriv:
        y /= delta**deriv
    return y


ALIGNMENT_PROBES = 8  # windows at 8 consecutive samples: every alignment of a float64 in a 64-byte line


def _valid_convolution(x: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """``np.convolve(x, taps, "valid")`` of a 1-D float64 series, the same numbers.

    Every output is one dot product of ``len(taps)`` samples with the reversed taps (numpy's
    correlate calls the BLAS ``dot`` once per output). When every sample of ``x`` has the same bits
    (the hull's angle while the brake holds it), every window holds the same numbers, so every
    output is the same dot product: it is computed at :data:`ALIGNMENT_PROBES` consecutive
    windows (each memory alignment a vector kernel could see) and, when those agree bit for
    bit, copied to every output; otherwise (or for a short series) every output is computed."""
    m = len(x) - len(taps) + 1
    if m > 4 * ALIGNMENT_PROBES and x.dtype == np.float64 and x.ndim == 1 and bitwise_constant(x):
        probe = np.convolve(x[:len(taps) + ALIGNMENT_PROBES - 1], taps, "valid")
        if bitwise_constant(probe):
            return np.full(m, probe[0])
    return np.convolve(x, taps, "valid")


class SharedSavgol:
    """:func:`savgol` of slices ``x[start:stop]`` of one float series, each window's dot product computed once.

    An interior output is one dot product of the samples in its window with the taps (numpy's
    correlate calls the BLAS ``dot`` per output, at the samples' own addresses), so the ``"valid"``
    outputs of ``x[start:stop]`` are those of ``x[start0:stop]`` from ``start - start0`` on: slices
    that end at the same sample, filtered with the same window, degree and derivative, share them
    (the longer slice computes only the windows the shorter lacked). Every result is :func:`savgol`'s.
    """

    def __init__(self, x: np.ndarray):
        self.x = x
        self._valid: dict = {}  # (stop, window, degree, deriv) -> (first window's start, 'valid' outputs)

    def savgol(self, start: int, stop: int, window: int, degree: int, deriv: int = 0,
               delta: float = 1.0) -> np.ndarray:
        """``savgol(x[start:stop], window, degree, deriv, delta)`` (``0 <= start <= stop <= len(x)``)."""
        x = self.x
        seg = x[start:stop]
        if not (isinstance(x, np.ndarray) and x.dtype == np.float64 and x.ndim == 1 and 0 <= start <= stop <= len(x)
                and window % 2 == 1 and degree < window <= len(seg)):
            return savgol(seg, window, degree, deriv, delta)  # its conversions and errors
        taps = _savgol_maps(int(window), int(degree), int(deriv))[0]
        key = (stop, int(window), int(degree), int(deriv))
        hit = self._valid.get(key)
        if hit is None:
            valid = _valid_convolution(seg, taps)
        elif hit[0] <= start:
            valid = hit[1][start - hit[0]:]
        else:  # the windows starting before the known ones, then those
            valid = np.concatenate([_valid_convolution(x[start:hit[0] + window - 1], taps), hit[1]])
        if hit is None or start < hit[0]:
            self._valid[key] = (start, valid)
        return savgol(seg, window, degree, deriv, delta, interior=valid)
