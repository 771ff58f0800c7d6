"""The free stroke's smooth law and its time mirror: the reverse stroke's reference.

The patent fits a kinematic law ``phi = f(t)`` to the decelerating part of the free stroke
as the encoder saw it, and drives the hull back along ``f(2 t2 + Delta - t')``. Here ``f``
is a least-squares Chebyshev series (numpy) over ``[t_a, t2]``, where ``t_a`` is a little
before the hull passes the calibrated neutral (fastest point) and ``t2`` is where the
fitted rate vanishes. Only measured samples and the rig's known constants are used.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import chebyshev as C

from addedinertia_env.experiment.stroke_kernels import (
    chebyshev_rows,
    chebyshev_series,
    last_rate_zero,
    mapped_series,
    rates_on_grid,
    squared_residuals,
)

DEFAULT_DEGREE = 11


def series(x, coef: np.ndarray):
    """``C.chebval(x, coef)``, the same numbers; a 1-D float64 ``x`` runs the compiled loop
    (:func:`~.stroke_kernels.chebyshev_series`), anything else numpy's."""
    if (isinstance(x, np.ndarray) and x.ndim == 1 and x.dtype == np.float64 and coef.dtype == np.float64
            and coef.ndim == 1 and coef.flags.c_contiguous):
        return chebyshev_series(coef, x)
    return C.chebval(x, coef)


def chebyshev_derivative(coef: np.ndarray) -> np.ndarray:
    """The derivative's coefficients of a Chebyshev series ``coef`` (1-D, on [-1, 1]): what
    ``numpy.polynomial.chebyshev.chebder(coef)`` returns, the same numbers (its recurrence, on
    Python floats: a dozen coefficients cost less than numpy's per-call overhead)."""
    c = [float(v) for v in coef]
    n = len(c) - 1
    if n < 1:
        return np.zeros(1)  # chebder of a constant: c[:1] * 0
    der = [0.0] * n
    for j in range(n, 2, -1):
        der[j - 1] = (2 * j) * c[j]
        c[j - 2] += (j * c[j]) / (j - 2)
    if n > 1:
        der[1] = 4 * c[2]
    der[0] = c[1]
    return np.array(der)


@dataclass(frozen=True)
class StrokeLaw:
    """Smooth fit ``phi = f(t)`` of the decelerating free stroke."""

    coef: np.ndarray  # Chebyshev coefficients on the mapped interval [-1, 1]
    t_start: float  # s, start of the fitted segment
    t_stop: float  # s, where the fitted rate is zero (the forward stroke's end, t2)
    fit_rms: float  # rad, residual RMS of the fit

    def __post_init__(self) -> None:
        # Derivative series, computed once (the reference is evaluated every control step).
        d1 = chebyshev_derivative(self.coef)
        object.__setattr__(self, "_d1", d1)
        object.__setattr__(self, "_d2", chebyshev_derivative(d1))

    def _x(self, t):
        return (2.0 * np.asarray(t, dtype=float) - (self.t_start + self.t_stop)) / (self.t_stop - self.t_start)

    @property
    def _scale(self) -> float:
        return 2.0 / (self.t_stop - self.t_start)

    def phi(self, t):
        """Fitted hull angle at ``t`` (s; float or array), rad."""
        return series(self._x(t), self.coef)

    def rate(self, t):
        """Fitted hull rate at ``t`` (s), rad/s."""
        return series(self._x(t), self._d1) * self._scale

    def accel(self, t):
        """Fitted hull acceleration at ``t`` (s), rad/s^2."""
        return series(self._x(t), self._d2) * self._scale**2

    @property
    def duration(self) -> float:
        """Length of the fitted stroke, s."""
        return self.t_stop - self.t_start

    @property
    def phi_stop(self) -> float:
        """Fitted angle at the stop ``t_stop``, rad."""
        return float(self.phi(self.t_stop))

    def inertia_prior(self, c: float, phi_neutral: float) -> float:
        """``J_h + lambda66`` seen at the stop, where rate-dependent damping vanishes:
        ``J = -c (phi2 - phi_n) / f''(t2)``. A prior, biased by any memory or dry friction."""
        return float(-c * (self.phi_stop - phi_neutral) / self.accel(self.t_stop))


@dataclass(frozen=True)
class MirroredReference:
    """``phi_ref(t) = f(t2 - (t - t_begin))`` for ``t`` in ``[t_begin, t_begin + duration]``."""

    law: StrokeLaw
    t_begin: float  # s, start of the reverse stroke (end of the hold)

    @property
    def t_end(self) -> float:
        """End of the reverse stroke, s."""
        return self.t_begin + self.law.duration

    def _mirror(self, t):
        if isinstance(t, float):
            return self.law.t_stop - (min(max(t, self.t_begin), self.t_end) - self.t_begin)
        return self.law.t_stop - (np.clip(t, self.t_begin, self.t_end) - self.t_begin)

    def phi(self, t):
        """Reference angle at ``t`` (s; clamped to the stroke), rad."""
        return self.law.phi(self._mirror(t))

    def rate(self, t):
        """Reference rate at ``t`` (s), rad/s (the mirror's sign)."""
        return -self.law.rate(self._mirror(t))

    def accel(self, t):
        """Reference acceleration at ``t`` (s), rad/s^2."""
        return self.law.accel(self._mirror(t))


def fit_stroke(t: np.ndarray, phi: np.ndarray, t_start: float, t_stop_guess: float,
               degree: int = DEFAULT_DEGREE) -> StrokeLaw:
    """Fit the decelerating stroke on ``[t_start, t_stop_guess]`` and locate its stop.

    ``t_stop_guess`` is the moment the brake was set; the fitted rate's zero nearest to
    it (searched a little beyond it) is returned as ``t_stop``.

    The numbers are numpy's: ``C.chebfit`` on the selected samples, the rate zero from
    ``C.chebval`` on a grid, the law re-expressed with ``C.chebinterpolate``; the element-wise
    series run as compiled loops of the same operations (:mod:`.stroke_kernels`), the sums,
    the least-squares solve and the matrix product in numpy (tests/test_stroke_law.py holds
    the result equal to the numpy calls, bit for bit).
    """
    sel = (t >= t_start) & (t <= t_stop_guess)
    if sel.sum() < 3 * degree:
        raise ValueError(f"free stroke too short to fit: {int(sel.sum())} samples on "
                         f"[{t_start:.3f}, {t_stop_guess:.3f}] s, need at least {3 * degree}")
    ts, ps = t[sel], phi[sel]
    a, b = ts[0], ts[-1]
    x = (2.0 * ts - (a + b)) / (b - a)
    coef = _chebfit(x, ps, degree)
    rms = float(np.sqrt(np.mean(squared_residuals(coef, x, ps))))
    # Rate zero near the brake time: solve on a fine grid over the last 20 % of the stroke
    # (the rate of the law on [a, b], StrokeLaw(coef, a, b).rate, without building that law).
    tt = np.linspace(a + 0.8 * (b - a), b, 2001)
    d1 = chebyshev_derivative(coef)
    k, r_k, r_next = last_rate_zero(d1, tt, a, b)  # the last sign change of the rate on the grid
    if k >= 0:
        t_stop = float(tt[k] - r_k * (tt[k + 1] - tt[k]) / (r_next - r_k))
    else:
        t_stop = float(tt[np.argmin(np.abs(rates_on_grid(d1, tt, a, b)))])
    # Re-express the same polynomial on [a, t_stop] so that t_stop is the law's end: interpolated at
    # degree + 1 Chebyshev points of [a, t_stop], which a polynomial of this degree meets exactly
    # (C.chebinterpolate of the series on [a, b] mapped onto [a, t_stop]).
    points, rows = _interpolation_nodes(degree)
    coef_new = np.dot(rows, mapped_series(coef, points, a, b, t_stop))
    coef_new[0] /= degree + 1
    coef_new[1:] /= 0.5 * (degree + 1)
    return StrokeLaw(coef=coef_new, t_start=a, t_stop=t_stop, fit_rms=rms)


def _chebfit(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
    """``C.chebfit(x, y, degree)`` for 1-D ``x``, ``y`` and an integer ``degree``: the same
    scaled least-squares problem handed to ``np.linalg.lstsq`` (numpy's ``polyutils._fit``),
    the Chebyshev rows compiled (:func:`~.stroke_kernels.chebyshev_rows`)."""
    x = x + 0.0
    y = y + 0.0
    lhs = chebyshev_rows(x, degree)  # chebvander(x, degree).T
    scl = np.sqrt(np.square(lhs).sum(1))
    scl[scl == 0] = 1
    c, _, rank, _ = np.linalg.lstsq(lhs.T / scl, y, len(x) * np.finfo(x.dtype).eps)
    c = c / scl
    if rank != degree + 1:
        warnings.warn("The fit may be poorly conditioned", np.exceptions.RankWarning, stacklevel=3)
    return c


@functools.lru_cache(maxsize=None)
def _interpolation_nodes(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """``C.chebinterpolate``'s nodes (``chebpts1(degree + 1)``) and the matrix it multiplies the
    function's values by (``chebvander(nodes, degree).T``), computed by numpy once per degree."""
    points = C.chebpts1(degree + 1)
    rows = C.chebvander(points, np.asarray(degree)).T
    points.flags.writeable = rows.flags.writeable = False
    return points, rows
