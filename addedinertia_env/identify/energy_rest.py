"""The energy method's rest angles: the hull's angle at the end of the free stroke (t2) and at the brake's
release (t3), fitted to the instants where the quantised encoder reading steps, and the encoder's step.

Part of the energy method (:mod:`addedinertia_env.identify.energy`); :class:`~.energy_balance.RunBalance`
takes its spring term's rests from these fits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from addedinertia_env.identify.series_kernels import count_crossings, twice_integrated
from addedinertia_env.identify.fit_kernels import lstsq as rounded_lstsq


REST_FIT_S = 0.08  # s, span of encoder steps before t2 and after t3 that give the rest angles


def power_series(coef: np.ndarray, x):
    """``sum(coef[j] x**j)`` at ``x`` (float or array) by Horner's rule, as ``np.polynomial.Polynomial(coef)(x)``
    computes it (``coef[-1] + x * 0``, then ``coef[j] + y * x``), the same numbers."""
    y = coef[-1] + x * 0
    for c in coef[-2::-1]:
        y = c + y * x
    return y


def power_series_derivative(coef: np.ndarray) -> np.ndarray:
    """Coefficients of the derivative of the power series ``coef`` (``Polynomial(coef).deriv().coef``)."""
    if len(coef) < 2:
        return coef[:1] * 0
    return np.array([j * coef[j] for j in range(1, len(coef))])


def crossings_fit(t: np.ndarray, phi: np.ndarray, k: int, span_s: float, q: float):
    """The angle (rad) as a function of time from sample ``k`` (s) (power-series coefficients), fitted to the instants where a quantised reading steps, within
    ``span_s`` seconds before (negative) or after (positive) it: a quadratic in time through
    (step instant, midpoint of the two readings), without a linear term after ``k`` (the hull
    starts from rest there). None when fewer than four steps."""
    if span_s < 0:
        a, b = int(np.searchsorted(t, t[k] + span_s)), k
    else:
        a, b = k, int(np.searchsorted(t, t[k] + span_s, side="right")) - 1
    tau, levels = count_crossings(t, phi, a, b, k, q)
    if not len(tau):
        return None
    # Before t2 the hull may pass its stop and come back a little: a free quadratic. After t3
    # it starts from rest at the brake's release: no linear term (a free one, extrapolated
    # back over the first count's dwell, is off by a count or more).
    X = np.empty((len(tau), 3 if span_s < 0 else 2))  # the columns 1, (tau,) tau^2
    X[:, 0] = 1.0
    X[:, -1] = tau**2
    if span_s < 0:
        X[:, 1] = tau
    coef, *_ = rounded_lstsq(X, levels, rcond=None)
    if span_s < 0:
        return coef
    return np.array([coef[0], 0.0, coef[1]])


@dataclass(frozen=True)
class ReleaseFit:
    """The hull's angle after the brake's release, from :func:`released_fit`: ``rest`` (rad, the angle at
    the release) and ``angle`` (rad, the fitted angle on the samples ``k..k + len(angle) - 1``)."""

    rest: float
    inverse_inertia: float  # 1 / kg m^2, the fit's scale of the torque's double integral
    angle: np.ndarray


def released_fit(t: np.ndarray, phi: np.ndarray, k: int, span_s: float, q: float,
                 torque: np.ndarray) -> ReleaseFit | None:
    """The angle after the brake's release at sample ``k``, fitted to the instants where the
    quantised reading steps within ``span_s`` seconds (positive) after it, with the hull's own law
    of motion as its shape: ``phi(tau) = rest + G(tau) / J`` with ``G`` the double integral from the
    release (where the hull is at rest) of ``torque`` (N m, per sample: the spring's and the motor's
    reaction, what the rig block and the current say act on the hull), ``rest`` and ``1 / J`` fitted.

    Why not a quadratic in time (:func:`crossings_fit`): that assumes a constant acceleration, but
    after the release the motor's torque changes within milliseconds (a feedback controller's current
    ramps up as the reference pulls away), so the acceleration changes by a tenth over the span and
    a quadratic through the steps reads the rest 0.15 to 0.5 counts off, always the same way (the
    spring term's -0.03 % of lambda66). The other torques are left out: the damping grows from zero
    with the speed (``b1 tau / 3 J``, under 1e-3 of the motion here) and the spring's own change is of
    order ``(omega tau)^2 / 12``; a constant torque not in ``torque`` rescales ``1 / J`` only. None
    when fewer than four steps or the fit's ``1 / J`` is not positive (no torque to shape it)."""
    b = int(np.searchsorted(t, t[k] + span_s, side="right")) - 1
    tau, levels = count_crossings(t, phi, k, b, k, q)
    if not len(tau) or b - k < 2:
        return None
    s = t[k:b + 1] - t[k]
    f = np.asarray(torque[k:b + 1], dtype=float)
    G = twice_integrated(f[None, :], 0.5 * np.diff(s))[0]  # J x the angle moved (trapezoid, twice)
    X = np.column_stack([np.ones(len(tau)), np.interp(tau, s, G)])
    coef, *_ = rounded_lstsq(X, levels, rcond=None)
    if not coef[1] > 0.0:
        return None
    return ReleaseFit(float(coef[0]), float(coef[1]), coef[0] + coef[1] * G)


def encoder_step(angle: np.ndarray, counts: int) -> float:
    """Encoder step, rad: from the counts per turn, or the smallest step seen when not given."""
    if counts:
        return 2.0 * np.pi / float(counts)
    steps = np.abs(np.diff(angle))
    steps = steps[steps > 0]
    return float(np.min(steps)) if len(steps) else 0.0
