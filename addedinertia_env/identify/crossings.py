"""Where a stroke crosses its boundary angles, and the hull's rate there: many angles at once.

The energy method evaluates its balance at a few dozen boundary angles per record
(:mod:`.energy`). Each angle needs the sample after which each stroke crossed it
(:func:`first_crossings`) and a local quintic through the encoder angle around that
sample, solved for the instant it equals the angle (:func:`crossing_fits`). Both are
written on arrays of angles, so one record costs a few dozen numpy calls instead of a
few thousand; every angle's numbers are those of the one-angle computation (the same
operations element by element; where the fits' scaled abscissae agree to 1e-11, as on an
evenly sampled record, one pseudo-inverse serves them all, which changes the rates by
float rounding only).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from addedinertia_env.identify.series_kernels import (
    canonical_abscissae,
    first_at_or_past,
    fit_windows,
    is_ascending,
    place_rows,
    polynomial_roots_near_zero,
    scaled_deviation,
    window_rows,
)
from addedinertia_env.identify.common import IdentificationError
from addedinertia_env.identify.fit_kernels import shared_design_fits

SHARED_DESIGN_TOLERANCE = 1e-11  # fits whose scaled abscissae (in [-1, 1]) agree this closely share one pseudo-inverse


def first_crossings(phi: np.ndarray, a: int, b: int, levels: np.ndarray, direction: float) -> np.ndarray:
    """For each of ``levels``: the first sample in [a, b) after which ``phi`` has crossed it
    moving in ``direction`` (the index of the first sample at or past it), or -1."""
    levels = np.asarray(levels, dtype=float)
    span = range(len(phi))[a:b]  # the samples phi[a:b]
    if len(span) >= 2 and phi.ndim == 1 and phi.dtype == np.float64 and levels.ndim == 1:
        # The first sample at or past a level that the stroke starts short of is the crossing:
        # a search in the running maximum (sign(d (phi - level)) is that of d phi - d level, exactly).
        out, reached, finite = first_at_or_past(phi, span.start, span.stop, int(a), float(direction), levels)
        if finite:
            past = np.nonzero(reached)[0]  # levels already reached at the first sample: the full test
            if len(past):
                out[past] = _first_crossings_plain(phi, a, b, levels[past], direction)
            return out
    return _first_crossings_plain(phi, a, b, levels, direction)


def _first_crossings_plain(phi: np.ndarray, a: int, b: int, levels: np.ndarray, direction: float) -> np.ndarray:
    """:func:`first_crossings` by testing every pair of samples against every level."""
    seg = direction * (phi[a:b][None, :] - levels[:, None])
    hit = (seg[:, :-1] < 0) & (seg[:, 1:] >= 0)
    first = np.argmax(hit, axis=1)
    return np.where(hit.any(axis=1), a + first + 1, -1) if hit.shape[1] else np.full(len(levels), -1)


def _polyval(coef: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Power series with per-row coefficients ``coef`` (fits x terms) at ``x`` (Horner, as ``polyval``)."""
    out = coef[:, -1] + x * 0
    for j in range(2, coef.shape[1] + 1):
        out = coef[:, -j] + out * x
    return out


def crossing_fits(t: np.ndarray, phi: np.ndarray, ks: np.ndarray, levels: np.ndarray,
                  half_width: float, degree: int) -> dict:
    """Where a local polynomial through ``phi`` around sample ``ks[j]`` equals ``levels[j]``.

    For each fit, least squares of ``degree`` in ``(t - t[k]) / half_width`` over
    ``|t - t[k]| <= half_width``, then Newton (8 steps from ``t[k]``) for the crossing.
    Returns arrays over the fits: ``t`` (s), ``rate`` (rad/s), ``sigma_rate`` (rad/s, from
    the fit's residual scatter), and ``kernel``: per fit the rate's linear kernel over the
    samples, ``(indices, weights)`` (a :class:`WindowKernels`); ``windows``: the same kernels as ``(first, size, offset, weights)``
    (fit ``j``'s indices are ``first[j] + arange(size[j])``, its weights ``weights[offset[j]:offset[j] +
    size[j]]``). Raises :class:`IdentificationError` for the first fit
    with fewer than ``degree + 3`` samples.
    """
    ks = np.asarray(ks, dtype=np.int64)
    levels = np.asarray(levels, dtype=float)
    n_fit = len(ks)
    if not n_fit:
        none = np.zeros(0, dtype=np.int64)
        return {"t": np.zeros(0), "rate": np.zeros(0), "sigma_rate": np.zeros(0), "kernel": [],
                "windows": (none, none, none, np.zeros(0))}
    tc = t[ks]
    ascending = is_ascending(t)
    if ascending:
        first, stop = fit_windows(t, tc, float(half_width))
    else:  # not sorted: the plain test over the whole record
        sels = [np.nonzero(np.abs(t - c) <= half_width)[0] for c in tc]
        first = np.array([s[0] if len(s) else 0 for s in sels], dtype=np.int64)
        stop = np.array([s[-1] + 1 if len(s) else 0 for s in sels], dtype=np.int64)
        if any(len(s) and s[-1] + 1 - s[0] != len(s) for s in sels):
            raise IdentificationError("the record's time column is not ordered; expected increasing 't'")
    size = stop - first
    short = np.nonzero(size < degree + 3)[0]
    if len(short):
        j = int(short[0])
        raise IdentificationError(f"too few samples ({int(size[j])}) around t = {tc[j]:.4f} s for a local fit")
    out_t, rate, sigma = np.empty(n_fit), np.empty(n_fit), np.empty(n_fit)
    if degree >= 1:  # evenly sampled (every group shares its design): one compiled pass per group
        fused = _fused_fits(t, phi, ks, levels, half_width, degree, tc, first, size, out_t, rate, sigma)
        if fused is not None:
            return fused
    powers = np.arange(degree + 1)
    coef = np.empty((n_fit, degree + 1))
    groups = []  # (fits, sample indices, angles, design, pseudo-inverse): P0/X0 shared, or P/X per fit
    for m in sorted(set(size.tolist())):  # the window lengths (np.unique's, ascending)
        g = np.nonzero(size == m)[0]
        idx, y = window_rows(phi, first[g], m)  # (fits, m) sample indices and angles
        shared = _shared_design(t, first[g], tc[g], m, half_width, degree)
        if shared is not None:  # one design for the group
            X0, P0 = shared
            coef[g] = y @ P0.T
            groups.append((g, idx, y, X0, P0, True))
        else:
            x_scaled = (t[idx] - tc[g][:, None]) / half_width
            X = np.empty((len(g), m, degree + 1))  # np.vander(sv / half_width, degree + 1, increasing=True)
            X[:, :, 0] = 1.0
            if degree:
                X[:, :, 1:] = x_scaled[:, :, None]
                np.multiply.accumulate(X[:, :, 1:], out=X[:, :, 1:], axis=2)
            P = np.linalg.pinv(X)
            coef[g] = np.matmul(P, y[:, :, None])[:, :, 0]  # (fits, degree + 1)
            groups.append((g, idx, y, X, P, False))
    # Newton on poly(x) = level for every fit (8 steps at most; a fit stops at its fixed point)
    dcoef = coef[:, 1:] * powers[1:]
    x = polynomial_roots_near_zero(coef, dcoef, levels, 8)
    rate[:] = _polyval(dcoef, x) / half_width
    out_t[:] = tc + x * half_width
    grad_all = np.where(powers > 0, powers * x[:, None] ** np.maximum(powers - 1, 0), 0.0) / half_width
    first, size, offsets, flat = _kernel_windows(first, size)
    for g, idx, y, X, P, is_shared in groups:
        m = idx.shape[1]
        grad = grad_all[g]
        if is_shared:
            fitted = coef[g] @ X.T
            kernel = grad @ P  # (fits, m)
        else:
            fitted = np.matmul(X, coef[g][:, :, None])[:, :, 0]
            kernel = np.matmul(grad[:, None, :], P)[:, 0, :]
        resid = y - fitted
        var = np.maximum(np.einsum("ij,ij->i", resid, resid) / max(m - degree - 1, 1), 1e-24)
        sigma[g] = np.sqrt(var) * np.linalg.norm(kernel, axis=1)
        place_rows(flat, offsets[g], kernel)  # flat[offsets[g][:, None] + arange(m)] = kernel
    return _fits_result(out_t, rate, sigma, (first, size, offsets, flat))


def _kernel_windows(first, size) -> tuple:
    """``(first, size, offsets, flat)``: the fits' windows and room for every kernel's weights, fit after
    fit, in one array (fit ``j``'s at ``flat[offsets[j]:offsets[j] + size[j]]``, to be filled)."""
    first, size = np.asarray(first, dtype=np.int64), np.asarray(size, dtype=np.int64)
    offsets = np.zeros(len(size), dtype=np.int64)
    np.cumsum(size[:-1], out=offsets[1:])
    return first, size, offsets, np.empty(int(size.sum()))


def _fits_result(out_t, rate, sigma, windows) -> dict:
    """What :func:`crossing_fits` returns, from its arrays and the filled ``windows``."""
    return {"t": out_t, "rate": rate, "sigma_rate": sigma, "kernel": WindowKernels(windows), "windows": windows}


def _fused_fits(t, phi, ks, levels, half_width, degree, tc, first, size, out_t, rate, sigma):
    """:func:`crossing_fits` by one compiled pass per window length (:func:`~.fit_kernels.shared_design_fits`,
    equal to the numpy path below it to float rounding), when every group of fits shares one design; None
    otherwise (the numpy path then runs)."""
    designs = []
    for m in sorted(set(size.tolist())):
        g = np.nonzero(size == m)[0]
        shared = _shared_design(t, first[g], tc[g], m, half_width, degree)
        if shared is None:
            return None
        designs.append((g, shared))
    first, size, offsets, flat = windows = _kernel_windows(first, size)
    phi = np.ascontiguousarray(phi, dtype=float)
    for g, (X0, P0) in designs:
        shared_design_fits(phi, first, tc, levels, X0, P0, float(half_width), 8, g, flat, offsets,
                           out_t, rate, sigma)
    return _fits_result(out_t, rate, sigma, windows)


class WindowKernels(Sequence):
    """The fits' rate kernels as a sequence of ``(sample indices, weights)``, each pair made when it is
    read, from :func:`crossing_fits`' ``windows`` (``fits``: which fits, in order; all by default).
    Slicing gives the kernels of those fits (``kernels[0::2]``: every other fit)."""

    def __init__(self, windows: tuple, fits: np.ndarray | None = None):
        self.windows = windows
        self.fits = np.arange(len(windows[0])) if fits is None else fits

    def __len__(self) -> int:
        return len(self.fits)

    def __getitem__(self, j):
        if isinstance(j, slice):
            return WindowKernels(self.windows, self.fits[j])
        first, size, offsets, flat = self.windows
        f = int(self.fits[j])
        return np.arange(first[f], first[f] + size[f]), flat[offsets[f]:offsets[f] + size[f]]


_DESIGNS: dict = {}  # (degree, canonical abscissae as bytes) -> (design, pseudo-inverse), across records
_DESIGNS_MAX = 512
_GRID = 2.0**40  # canonical abscissae: multiples of 2**-40 (9.1e-13; rounding moves them by at most 4.6e-13)


def _shared_design(t: np.ndarray, first: np.ndarray, tc: np.ndarray, m: int, half_width: float, degree: int):
    """The design ``X0`` and pseudo-inverse ``P0`` that every fit of a group shares, or None.

    Fit ``j`` of the group has the scaled abscissae ``(t[first[j]:first[j] + m] - tc[j]) / half_width``
    (in [-1, 1]). The shared design is built on canonical abscissae: the group's first row rounded to
    multiples of 2**-40. Fits share it when every row agrees with those to
    :data:`SHARED_DESIGN_TOLERANCE`. The canonical row depends on the group alone (not on what
    was computed before), so the pair is kept across calls: records on one sampling grid reuse
    it, and every result is the same whatever ran before."""
    canonical = canonical_abscissae(t, int(first[0]), float(tc[0]), float(half_width), m, _GRID)  # exact scalings
    if scaled_deviation(t, first, tc, half_width, canonical) > SHARED_DESIGN_TOLERANCE:
        return None
    key = (degree, canonical.tobytes())
    hit = _DESIGNS.get(key)
    if hit is not None:
        return hit
    X0 = np.vander(canonical, degree + 1, increasing=True)
    P0 = np.linalg.pinv(X0)  # (degree + 1, m)
    if len(_DESIGNS) >= _DESIGNS_MAX:
        _DESIGNS.clear()
    _DESIGNS[key] = (X0, P0)
    return X0, P0
