"""Compiled least-squares pieces of the energy method, equal to numpy's to float rounding (not bit for bit).

Unlike :mod:`~addedinertia_env.identify.series_kernels`, these do not reproduce numpy's summation order
(a BLAS ``ddot``/``gemm`` order is not reproducible in numba): every sum here is a fixed, documented
order of its own, so the results are the same on every machine and differ from the numpy code they
replaced in the last bits (lambda66 by at most 3e-14 relative over 792 records, no lag, acceptance,
rejection or error outcome changed; /work/notes of session 7, "i13round"). What they save is numpy's
per-call overhead on small problems: the crossing fits of one record in one pass
(:func:`shared_design_fits`), the calibration's projection (:func:`line_basis`, :func:`project_out_line`), and the small
full-rank least-squares fits (:func:`lstsq`). tests/test_fit_kernels.py holds each to its numpy form.
"""

from __future__ import annotations

import numpy as np
from numba import njit

@njit(cache=True, error_model="numpy", inline="always")
def _dot(a, a0, b, b0, n):
    """``sum(a[a0:a0 + n] * b[b0:b0 + n])``: 8 lane sums (lane ``l`` takes elements ``l, l + 8, ...``),
    the remainder into lane order, then ((l0 + l1) + (l2 + l3)) + ((l4 + l5) + (l6 + l7))."""
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
    full = n - n % 8
    for i in range(0, full, 8):
        s0 += a[a0 + i] * b[b0 + i]
        s1 += a[a0 + i + 1] * b[b0 + i + 1]
        s2 += a[a0 + i + 2] * b[b0 + i + 2]
        s3 += a[a0 + i + 3] * b[b0 + i + 3]
        s4 += a[a0 + i + 4] * b[b0 + i + 4]
        s5 += a[a0 + i + 5] * b[b0 + i + 5]
        s6 += a[a0 + i + 6] * b[b0 + i + 6]
        s7 += a[a0 + i + 7] * b[b0 + i + 7]
    rest = 0.0
    for i in range(full, n):
        rest += a[a0 + i] * b[b0 + i]
    return ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7)) + rest


@njit(cache=True, error_model="numpy")
def shared_design_fits(phi, first, tc, levels, X0, P0, half_width, steps, fits, flat, offsets,
                       out_t, rate, sigma):
    """The crossing fits of one group sharing the design ``X0`` (m, terms) and its pseudo-inverse ``P0``
    (terms, m) (``crossings.crossing_fits``, to float rounding): for each fit ``f`` of ``fits``, the
    coefficients ``P0 @ phi[first[f]:first[f] + m]``, Newton (``steps`` at most, from 0, stopping at a fixed
    point) for ``poly = levels[f]``, the rate, the crossing time, the rate kernel ``grad @ P0`` (written to
    ``flat[offsets[f]:offsets[f] + m]``) and its sigma (residual scatter x kernel norm)."""
    terms, m = P0.shape
    dof = max(m - terms, 1)
    coef = np.empty(terms)
    dcoef = np.empty(terms - 1)
    grad = np.empty(terms)
    kern = np.empty(m)
    fitted = np.empty(m)
    X0T = np.ascontiguousarray(X0.T)
    for r in range(len(fits)):
        f = fits[r]
        s = first[f]
        for p in range(terms):
            coef[p] = _dot(P0[p], 0, phi, s, m)
        for p in range(1, terms):
            dcoef[p - 1] = coef[p] * p
        x = 0.0
        for _ in range(steps):
            pv = coef[terms - 1] + x * 0.0
            for k in range(terms - 2, -1, -1):
                pv = coef[k] + pv * x
            dp = dcoef[terms - 2] + x * 0.0
            for k in range(terms - 3, -1, -1):
                dp = dcoef[k] + dp * x
            x_next = x - (pv - levels[f]) / dp
            if x_next == x:
                break
            x = x_next
        d = dcoef[terms - 2] + x * 0.0
        for k in range(terms - 3, -1, -1):
            d = dcoef[k] + d * x
        rate[f] = d / half_width
        out_t[f] = tc[f] + x * half_width
        grad[0] = 0.0
        xp = 1.0
        for p in range(1, terms):
            grad[p] = p * xp / half_width
            xp *= x
        # kernel = grad @ P0 and fitted = X0 @ coef, each over the terms in increasing order
        # (vectorised over the samples; X0T = X0.T contiguous)
        for j in range(m):
            kern[j] = grad[0] * P0[0, j]
            fitted[j] = X0T[0, j] * coef[0]
        for p in range(1, terms):
            gp = grad[p]
            cp = coef[p]
            for j in range(m):
                kern[j] += gp * P0[p, j]
                fitted[j] += X0T[p, j] * cp
        for j in range(m):
            fitted[j] = phi[s + j] - fitted[j]
            flat[offsets[f] + j] = kern[j]
        rr = _dot(fitted, 0, fitted, 0, m)
        kk = _dot(kern, 0, kern, 0, m)
        var = max(rr / dof, 1e-24)
        sigma[f] = np.sqrt(var) * np.sqrt(kk)


@njit(cache=True, error_model="numpy")
def line_basis(tt):
    """The orthonormal pair spanning ``(1, tt - tt[0])`` over the samples ``tt`` (s), as the columns of
    an ``(m, 2)`` array: ``1/sqrt(m)`` and the centred ``tt`` normalised (no QR)."""
    m = len(tt)
    mean = 0.0
    for k in range(m):
        mean += tt[k] - tt[0]
    mean /= m
    Q = np.empty((m, 2))
    nn = 0.0
    for k in range(m):
        Q[k, 0] = 1.0 / np.sqrt(m)
        Q[k, 1] = (tt[k] - tt[0]) - mean
        nn += Q[k, 1] * Q[k, 1]
    nrm = np.sqrt(nn)
    for k in range(m):
        Q[k, 1] /= nrm
    return Q


@njit(cache=True, error_model="numpy")
def project_out_line(x, Q):
    """Each row of ``x`` with its least-squares fit on ``(1, tt - tt[0])`` removed, twice (the calibration's
    ``projected``, to float rounding); ``Q``: :func:`line_basis` of ``tt``."""
    rows, m = x.shape
    q1 = Q[0, 0]
    q2 = np.ascontiguousarray(Q[:, 1])
    out = np.empty((rows, m))
    for r in range(rows):
        for k in range(m):
            out[r, k] = x[r, k]
        for _ in range(2):
            c1 = 0.0
            for k in range(m):
                c1 += out[r, k]
            c1 *= q1
            c2 = _dot(out[r], 0, q2, 0, m)
            for k in range(m):
                out[r, k] = out[r, k] - c1 * q1 - c2 * q2[k]
    return out


@njit(cache=True, error_model="numpy")
def qr_least_squares(A, b):
    """Least squares ``A c ~ b`` (``A``: rows >= columns) by Householder QR (no pivoting), back substitution.
    Returns ``(c, ratio)`` with ``ratio = min |R_kk| / max |R_kk|`` (0 for a zero column): the caller
    falls back to an SVD solver when it is small."""
    m, n = A.shape
    R = A.copy()
    y = b.copy()
    diag = np.empty(n)
    for k in range(n):
        s = 0.0
        for i in range(k, m):
            s += R[i, k] * R[i, k]
        nrm = np.sqrt(s)
        if nrm == 0.0:
            return np.full(n, np.nan), 0.0
        alpha = -nrm if R[k, k] >= 0 else nrm
        v0 = R[k, k] - alpha
        vv = s - R[k, k] * R[k, k] + v0 * v0  # |v|^2, v = (v0, R[k+1:, k])
        R[k, k] = v0
        for j in range(k + 1, n):
            d = 0.0
            for i in range(k, m):
                d += R[i, k] * R[i, j]
            f = 2.0 * d / vv
            for i in range(k, m):
                R[i, j] -= f * R[i, k]
        d = 0.0
        for i in range(k, m):
            d += R[i, k] * y[i]
        f = 2.0 * d / vv
        for i in range(k, m):
            y[i] -= f * R[i, k]
        diag[k] = alpha
    c = np.empty(n)
    for k in range(n - 1, -1, -1):
        acc = y[k]
        for j in range(k + 1, n):
            acc -= R[k, j] * c[j]
        c[k] = acc / diag[k]
    lo, hi = abs(diag[0]), abs(diag[0])
    for k in range(n):
        lo, hi = min(lo, abs(diag[k])), max(hi, abs(diag[k]))
    return c, lo / hi


QR_RATIO_MIN = 1e-8  # below: numpy's SVD solver decides the rank (rcond semantics kept)


def lstsq(A, b, rcond=None):
    """``np.linalg.lstsq(A, b, rcond)`` (1-D ``b``): for a clearly full-rank float64 ``A`` by
    :func:`qr_least_squares` (to float rounding; residuals and singular values None, rank = columns);
    otherwise numpy's (its rank decision, warnings and numbers)."""
    if (isinstance(A, np.ndarray) and isinstance(b, np.ndarray) and A.ndim == 2
            and b.ndim == 1 and A.dtype == np.float64 and b.dtype == np.float64 and A.shape[0] >= A.shape[1] >= 1
            and A.shape[0] == b.shape[0]):
        c, ratio = qr_least_squares(np.ascontiguousarray(A), b)
        if ratio > QR_RATIO_MIN and np.all(np.isfinite(c)):
            return c, None, A.shape[1], None
    return np.linalg.lstsq(A, b, rcond)


def warm_up() -> None:
    """Load the kernels' machine code now (cache or compile)."""
    x = np.arange(16.0)
    one = np.zeros(1, dtype=np.int64)
    X0 = np.vander(np.linspace(-1, 1, 9), 6, increasing=True)
    shared_design_fits(x, one, x[:1], x[:1], X0, np.linalg.pinv(X0), 1.0, 8, one, np.empty(9), one,
                       np.empty(1), np.empty(1), np.empty(1))
    project_out_line(np.ones((2, 16)), line_basis(x))
    qr_least_squares(np.vander(x, 3), x)
