"""The cogging fit's search over periods, all periods in one pass (identify/energy_cogging.py).

:func:`energy_cogging.cogging_fit` asks, for every period ``n`` it searches (``m = n N`` rad^-1 at
the flywheel), how much of the balance's residual ``y`` the pair of cogging columns
``twice(seen sin(m psi))``, ``twice(seen cos(m psi))`` explains once the loss's columns (orthonormal
``Q``, to which ``y`` is orthogonal) are projected out of them: the drop ``|P y|^2``, ``P`` the
projection onto the pair's span. For the null it asks the same of every other period once the best
period's pair is projected out as well. The loop this replaces built each period's columns with
its own numpy calls and ran a 2-column ``lstsq`` (LAPACK's SVD) per period, twice: ~60 CPU-ms of
a drive-v1 record's identification, once per episode of the drive trainer (learning/score_ars.py;
docs/PERFORMANCE.md).

Here one compiled pass over the samples builds every period's pair (columns ``k`` and ``K + k`` of
an array (samples, 2 K) for ``K`` periods): ``exp(i n N psi)`` by one complex product per period
from the previous period's (so no sine per period and sample), the taper ``seen``, and the two
trapezoid integrals, as the loop did. Another pass projects them and sums, per pair, ``u.u``,
``u.v``, ``v.v``, ``u.y`` and ``v.y``; the drop follows by Gram-Schmidt,
``(u.y)^2 / u.u + (w.y)^2 / w.w`` with ``w`` the part of ``v`` orthogonal to ``u``: the projection
onto a 2-column span, exact in real arithmetic and equal to the SVD's to rounding where the pair is
well conditioned. Where a pair is nearly dependent (``w.w`` below :data:`DEPENDENT` of ``v.v``: the
sums would lose digits, and the SVD's cut-off could drop a direction) that pair is fitted by ``np.linalg.lstsq`` as before.

The drops differ from the loop's at rounding level only (the recurrence's phase error is ~1e-13
rad after 120 periods, below what ``m psi`` itself carries at thousands of rad), and only the
period chosen, the null's median and the ranking of the others are used downstream: the
coefficients are refitted on the chosen periods' own columns (``energy_cogging._joint``, as before).
So the estimate is unchanged bit for bit unless two drops tie to ~1e-12 (``tests/test_cogging_periods.py``
holds the drops to the loop's; docs/PERFORMANCE.md has the check on the trainer's episodes).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# w.w / v.v (sin^2 of the angle between a pair's columns) below which the pair goes to lstsq: w.w is taken as
# v.v - (u.v)^2 / u.u, which carries a relative error of about eps v.v / w.w, kept below ~1e-12 here
DEPENDENT = 1e-4


@njit(cache=True, error_model="numpy")
def period_columns(psi, dpsi, gear_ratio, periods, half_dt, scale, samples_per_cycle):
    """Every period's pair of columns, unprojected: ``out[:, k]`` = ``twice(seen sin(m psi)) / scale``,
    ``out[:, K + k]`` the same with ``cos`` (``K`` periods, consecutive integers ``n``; ``m = n gear_ratio``;
    ``twice`` the trapezoid integral of the trapezoid integral from 0, intervals ``2 half_dt``), and the
    seen cycles of each period, ``sum(m dpsi seen) / 2 pi``."""
    n = len(psi)
    K = len(periods)
    out = np.empty((n, 2 * K))
    cycles = np.zeros(K)
    m = np.empty(K)
    for k in range(K):
        m[k] = periods[k] * gear_ratio
    f_s = np.zeros(K)  # the first integrals at the previous sample
    f_c = np.zeros(K)
    s_s = np.zeros(K)  # the second integrals
    s_c = np.zeros(K)
    x_s = np.zeros(K)  # the integrands at the previous sample
    x_c = np.zeros(K)
    zr = np.empty(K)  # exp(i m psi) at this sample
    zi = np.empty(K)
    two_pi = 2 * math.pi
    for j in range(n):
        step_r, step_i = math.cos(gear_ratio * psi[j]), math.sin(gear_ratio * psi[j])
        zr[0], zi[0] = math.cos(m[0] * psi[j]), math.sin(m[0] * psi[j])
        for k in range(1, K):
            zr[k] = zr[k - 1] * step_r - zi[k - 1] * step_i
            zi[k] = zr[k - 1] * step_i + zi[k - 1] * step_r
        h = half_dt[j - 1] if j > 0 else 0.0  # at the first sample the integrals start at 0
        c = dpsi[j] * samples_per_cycle / two_pi
        for k in range(K):
            a = m[k] * c
            a2 = a * a
            a4 = a2 * a2
            seen = 1.0 / (1.0 + a4 * a4)
            cycles[k] += m[k] * dpsi[j] * seen
            xs = seen * zi[k]
            xc = seen * zr[k]
            fs = f_s[k] + (xs + x_s[k]) * h
            fc = f_c[k] + (xc + x_c[k]) * h
            s_s[k] += (fs + f_s[k]) * h
            s_c[k] += (fc + f_c[k]) * h
            f_s[k] = fs
            f_c[k] = fc
            x_s[k] = xs
            x_c[k] = xc
            out[j, k] = s_s[k] / scale
            out[j, K + k] = s_c[k] / scale
    for k in range(K):
        cycles[k] /= two_pi
    return out, cycles


@njit(cache=True, error_model="numpy")
def projected_pair_drops(X, B, y):
    """Per pair ``k`` (columns ``k`` and ``K + k`` of ``X``, ``K`` pairs): ``|P y|^2``, ``P`` the projection onto
    the span of the pair with ``B``'s span (orthonormal columns) projected out; ``y`` orthogonal to ``B``. By
    Gram-Schmidt on the pair's sums (``u.u``, ``u.v``, ``v.v``, ``u.y``, ``v.y`` of the projected columns), and
    ``w.w / v.v`` (``w`` the part of ``v`` orthogonal to ``u``): where it is small the pair is nearly dependent
    and the sums lose digits (module doc)."""
    n, c = X.shape
    K = c // 2
    q = B.shape[1]
    A = np.zeros((q, c))
    for j in range(n):
        for i in range(q):
            b = B[j, i]
            for col in range(c):
                A[i, col] += b * X[j, col]
    uu = np.zeros(K)
    uv = np.zeros(K)
    vv = np.zeros(K)
    uy = np.zeros(K)
    vy = np.zeros(K)
    row = np.empty(c)
    for j in range(n):
        for col in range(c):
            row[col] = X[j, col]
        for i in range(q):
            b = B[j, i]
            for col in range(c):
                row[col] -= b * A[i, col]
        yj = y[j]
        for k in range(K):
            u = row[k]
            v = row[K + k]
            uu[k] += u * u
            uv[k] += u * v
            vv[k] += v * v
            uy[k] += u * yj
            vy[k] += v * yj
    r = uv / uu
    ww = vv - r * uv
    wy = vy - r * uy
    return uy * uy / uu + wy * wy / ww, ww / vv


def _pair(X: np.ndarray, k: int) -> np.ndarray:
    """Pair ``k``'s two columns (samples, 2) of an array laid out as :func:`period_columns` writes it."""
    K = X.shape[1] // 2
    return X[:, [k, K + k]]


def _drops(X: np.ndarray, B: np.ndarray, y: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """:func:`projected_pair_drops` of the pairs ``rows`` of ``X``, a nearly dependent pair by ``lstsq``
    (module doc). The kernel takes every pair (one contiguous pass); the others are not read."""
    with np.errstate(divide="ignore", invalid="ignore"):
        drops, indep = projected_pair_drops(X, np.ascontiguousarray(B), np.ascontiguousarray(y))
    drops = drops[rows]
    for k in np.flatnonzero(~(np.isfinite(drops) & (indep[rows] > DEPENDENT))):
        C = _pair(X, rows[k])
        C = C - B @ (B.T @ C)
        c, *_ = np.linalg.lstsq(C, y, rcond=None)
        f = C @ c
        drops[k] = float(f @ f)
    return drops


class PeriodScan:
    """Every period's drop on ``y`` (the loss's columns ``Q`` projected out), and the null beside the best."""

    def __init__(self, psi: np.ndarray, dpsi: np.ndarray, half_dt: np.ndarray, scale: float, Q: np.ndarray,
                 y: np.ndarray, gear_ratio: float, periods: range, min_cycles: float, samples_per_cycle: float):
        ns = np.asarray(list(periods), dtype=np.int64)
        if len(ns) > 1 and not np.all(np.diff(ns) == 1):
            raise ValueError(f"PeriodScan: periods {list(periods)}; expected consecutive integers")
        self.X, cycles = period_columns(np.asarray(psi, float), np.asarray(dpsi, float), float(gear_ratio), ns,
                                        np.asarray(half_dt, float), float(scale), float(samples_per_cycle))
        self.rows = np.flatnonzero(cycles >= min_cycles)  # the periods judged (the rotor turns through enough cycles)
        self.Q, self.y = Q, y
        self.periods = [int(n) for n in ns[self.rows]]
        d = _drops(self.X, Q, y, self.rows) if len(self.rows) else np.zeros(0)
        self.drops = {n: float(v) for n, v in zip(self.periods, d)}

    def null_drops(self, best: int) -> list[float]:
        """The drop of every other period once ``best``'s pair (projected) is projected out of its columns and
        of ``y`` (``energy_cogging.drops_beside``), in the periods' order."""
        k = self.periods.index(best)
        row = self.rows[k]
        C = _pair(self.X, row)
        Qb, _ = np.linalg.qr(C - self.Q @ (self.Q.T @ C))
        yb = self.y - Qb @ (Qb.T @ self.y)
        others = np.delete(self.rows, k)
        if not len(others):
            return []
        return [float(v) for v in _drops(self.X, np.column_stack([self.Q, Qb]), yb, others)]
