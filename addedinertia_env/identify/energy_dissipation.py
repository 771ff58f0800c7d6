"""The energy method's dissipation law: the damping torque ``D(w) = d1 |w| + d2 w^2`` fitted to the forward
stroke, and the dissipation mismatch ``dW`` it leaves where the reverse stroke does not retrace the
forward stroke's speed (physics.md section 4).

Part of the energy method (:mod:`addedinertia_env.identify.energy`).
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.records.series_stats import median_step
from addedinertia_env.identify.common import SharedSavgol, savgol
from addedinertia_env.identify.fit_kernels import lstsq as rounded_lstsq


DAMPING_FIT_WINDOW_S = 0.1  # s, Savitzky-Golay window of the rates and accelerations of the damping fit


def forward_damping_law(rec: RunRecord, free: slice, k2: int, J_total: float, c: float,
                        phi_n: float, rates: SharedSavgol | None = None) -> dict | None:
    """Damping torque magnitude ``D(w) = d1 |w| + d2 w^2`` (N m) seen on the forward stroke.

    From ``J phi'' + c (phi - phi_n) = -D(w) sign(w)`` with the total inertia ``J_total``
    (kg m^2) given (a first estimate): least squares for ``d1, d2`` on smoothed derivatives
    of the free stroke's second half. Fitting ``J`` jointly would put the acceleration's
    noise among the regressors and shrink ``J`` (and inflate ``d2`` several-fold) when the
    encoder's quantisation is a sizeable part of the acceleration. ``rates``: the rate filter of
    the record's ``phi`` shared with the dissipation mismatch (:class:`~.common.SharedSavgol`).
    """
    t, phi = rec.t, rec["phi"]
    a = free.start + (k2 - free.start) // 3
    dt = float(median_step(t[free]))
    win = max(7, int(round(DAMPING_FIT_WINDOW_S / dt)) | 1)
    if k2 - a < 2 * win:
        return None
    start = a - win if a >= win else a
    seg = phi[start:k2 + 1]
    if rates is not None and rates.x is phi:
        w = rates.savgol(start, k2 + 1, win, 3, deriv=1, delta=dt)
    else:
        w = savgol(seg, win, 3, deriv=1, delta=dt)
    acc = savgol(seg, win, 3, deriv=2, delta=dt)
    keep = slice(win, len(seg) - win // 2)
    w, acc, ph = w[keep], acc[keep], seg[keep]
    # -c (phi - phi_n) - J acc = d1 w + d2 w|w|   (linear in d1, d2)
    X = np.empty((len(w), 2))  # the columns w, w |w|
    X[:, 0] = w
    np.multiply(w, np.abs(w), out=X[:, 1])
    y = -c * (ph - phi_n) - J_total * acc
    coef, *_ = rounded_lstsq(X, y, rcond=None)
    d1, d2 = (float(x) for x in coef)
    if not (np.isfinite(d1) and np.isfinite(d2)):
        return None
    if d2 < 0:  # refit linear only
        d1, d2 = float(rounded_lstsq(X[:, :1], y, rcond=None)[0][0]), 0.0
        cov = np.zeros((2, 2))
        cov[:1, :1] = _block_covariance(X[:, :1], y - X[:, 0] * d1, win)
    else:
        cov = _block_covariance(X, y - X @ np.array([d1, d2]), win)
    return {"J": J_total, "d1": max(d1, 0.0), "d2": d2, "cov": cov}


def _block_covariance(X: np.ndarray, resid: np.ndarray, block: int) -> np.ndarray:
    """Covariance of least-squares coefficients of ``X`` with residuals ``resid`` that are correlated over
    ``block`` samples (the rate filter's window): the sandwich form with the scores summed per block of
    ``2 block`` samples (nan when fewer than three blocks)."""
    n = len(resid)
    size = 2 * block
    g = n // size
    if g < 3:
        return np.full((X.shape[1], X.shape[1]), np.nan)
    bread = np.linalg.pinv(X.T @ X)
    idx = np.minimum(np.arange(n) // size, g - 1)
    scores = np.zeros((g, X.shape[1]))
    np.add.at(scores, idx, X * resid[:, None])
    meat = scores.T @ scores * (g / (g - 1))
    return bread @ meat @ bread


class DissipationMismatch:
    """``dW(phi1) = W_reverse - W_forward`` between ``phi1`` and the stop, from the two strokes'
    speed profiles over angle and the forward stroke's damping law; returns (dW, sigma) in J.
    ``rates``: the rate filter of ``phi`` shared with the damping law (:class:`~.common.SharedSavgol`)."""

    def __init__(self, t, phi, free, k2, k3, rev, law, direction, rates: SharedSavgol | None = None):
        def speed_over_angle(a: int, b: int):
            lo, hi = max(a, 0), min(b, len(t) - 1)
            dt = float(median_step(t[lo:hi]))
            win = max(7, int(round(DAMPING_FIT_WINDOW_S / dt)) | 1)
            if rates is not None and rates.x is phi:
                speed = np.abs(rates.savgol(lo, hi + 1, win, 3, deriv=1, delta=dt))
            else:
                speed = np.abs(savgol(phi[lo:hi + 1], win, 3, deriv=1, delta=dt))
            ang = phi[lo:hi + 1]
            order = np.argsort(ang)
            return ang[order], speed[order]

        af, sf = speed_over_angle(free.start, k2)
        ar, sr = speed_over_angle(k3, rev.stop - 1)
        phi2 = phi[k2]
        self.grid = np.linspace(min(af.min(), ar.min()), max(af.max(), ar.max()), 400)
        vf, vr = np.interp(self.grid, af, sf), np.interp(self.grid, ar, sr)
        dD = law["d1"] * (vr - vf) + law["d2"] * (vr * vr - vf * vf)
        # Cumulative integral from the stop phi2 back to each grid angle, along the stroke direction.
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (dD[1:] + dD[:-1]) * np.diff(self.grid))])
        self.cum, self.phi2, self.direction = cum, phi2, direction
        # the same integral per unit d1 and per unit d2: the law's coefficients' covariance gives dW's
        parts = []
        for dx in (vr - vf, vr * vr - vf * vf):
            parts.append(np.concatenate([[0.0], np.cumsum(0.5 * (dx[1:] + dx[:-1]) * np.diff(self.grid))]))
        self.parts = np.stack(parts)
        cov = law.get("cov")
        self.cov = cov if cov is not None and np.all(np.isfinite(cov)) else None

    def __call__(self, phi1):
        """(dW, sigma) at the angle(s) ``phi1``, J: floats for a float, arrays for an array.

        ``sigma`` is the damping law's own uncertainty (its two coefficients' covariance, the residuals
        clustered over the rate filter's window) carried through the integral; where the fit gave none
        (a stroke too short for three blocks), half of ``dW``."""
        dW = self.direction * (np.interp(self.phi2, self.grid, self.cum) - np.interp(phi1, self.grid, self.cum))
        if self.cov is not None:
            g = np.stack([np.interp(self.phi2, self.grid, p) - np.interp(phi1, self.grid, p) for p in self.parts])
            sigma = np.sqrt(np.maximum(np.einsum("i...,ij,j...->...", g, self.cov, g), 0.0))
        else:
            sigma = 0.5 * np.abs(dW)
        if np.ndim(dW) == 0:
            return float(dW), float(sigma)
        return dW, sigma
