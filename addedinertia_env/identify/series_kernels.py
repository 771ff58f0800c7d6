"""Compiled loops over sample series (numba), for the energy method's identification.

Each kernel is the one implementation of its computation (the numpy code it replaced is
gone); its docstring says which numpy expression it equals and whether bit for bit (same
operations in the same order) or to float rounding. ``tests/test_series_kernels.py``
holds every kernel to an independent reference (numpy, scipy). Compiled with
``cache=True`` (the machine code is kept in ``__pycache__``), never ``fastmath``: IEEE
operations in source order, so sequential sums are those of ``np.cumsum``, and
``error_model="numpy"``: a division by zero gives inf or nan as in numpy, never an exception.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from addedinertia_env.records.scan_kernels import numpy_sign


@njit(cache=True, error_model="numpy")
def twice_integrated(x, half_dt):
    """Per row of ``x`` (rows, m): the trapezoid integral of the trapezoid integral from 0, for
    sample intervals ``2 half_dt`` (m - 1). Equals, bit for bit, twice
    ``out = concatenate([0], cumsum((out[1:] + out[:-1]) * half_dt))`` along each row."""
    rows, m = x.shape
    out = np.empty((rows, m))
    for r in range(rows):
        first = 0.0  # the first integral at sample k
        second = 0.0
        out[r, 0] = 0.0
        for k in range(m - 1):
            first_next = first + (x[r, k + 1] + x[r, k]) * half_dt[k]
            second = second + (first_next + first) * half_dt[k]
            out[r, k + 1] = second
            first = first_next
    return out


@njit(cache=True, error_model="numpy")
def lag_ranking(by, gram, k, frac, yy):
    """The flywheel calibration's ranking of its lags (``energy_calibration._lag_rss``): for lag ``j``, the
    blended column ``z = (1 - f) B[k] + f B[k + 1]`` (``f = frac[j]``, ``k = k[j]``) leaves
    ``yy - (z.y)^2 / z.z`` (``z.y``, ``z.z`` from ``by = B y`` and ``gram = B B^T``; ``yy`` when
    ``z.z <= 0``). Returns ``(rss, rows)``: that bound raised by ``2 tol`` plus its spread
    (``tol = 1e-9 yy``), and the sorted lags within ``tol`` of the smallest bound and their
    neighbours (the rows to form explicitly). Bit for bit the numpy expressions (nan-propagating
    min and max)."""
    n = len(k)
    bound = np.empty(n)
    for j in range(n):
        f = frac[j]
        g = 1.0 - f
        a = k[j]
        zy = g * by[a] + f * by[a + 1]
        zz = g * g * gram[a, a] + 2.0 * g * f * gram[a, a + 1] + f * f * gram[a + 1, a + 1]
        bound[j] = yy - (zy * zy / zz if zz > 0 else 0.0)
    lo, hi = bound[0], bound[0]
    for j in range(n):
        v = bound[j]
        if np.isnan(v) or np.isnan(lo):
            lo = hi = np.nan
        else:
            lo, hi = min(lo, v), max(hi, v)
    tol = 1e-9 * yy
    mark = np.zeros(n, dtype=np.bool_)
    for j in range(n):
        if bound[j] <= lo + tol:
            for r in (j - 1, j, j + 1):
                mark[min(max(r, 0), n - 1)] = True
    rss = np.empty(n)
    for j in range(n):
        rss[j] = bound[j] + 2.0 * tol + (hi - lo)
    return rss, np.nonzero(mark)[0]


@njit(cache=True, error_model="numpy")
def fit_windows(t, tc, half_width):
    """First and one-past-last sample with ``|t - tc[j]| <= half_width`` for each ``tc[j]`` (``t``
    ascending; both the first candidate when none is inside). Exact: the candidates a couple of samples
    past ``searchsorted`` of ``tc -+ half_width`` are tested with ``abs(t - tc) <= half_width``."""
    n = len(t)
    first = np.empty(len(tc), dtype=np.int64)
    stop = np.empty(len(tc), dtype=np.int64)
    for j in range(len(tc)):
        lo = min(max(np.searchsorted(t, tc[j] - half_width, side="left") - 2, 0), n)
        hi = min(max(np.searchsorted(t, tc[j] + half_width, side="right") + 2, 0), n)
        a, b = lo, lo  # the first and one past the last candidate inside (a scan from each end)
        for k in range(lo, hi):
            if abs(t[k] - tc[j]) <= half_width:
                a = k
                for k_last in range(hi - 1, k - 1, -1):
                    if abs(t[k_last] - tc[j]) <= half_width:
                        b = k_last + 1
                        break
                break
        first[j], stop[j] = a, b
    return first, stop


@njit(cache=True, error_model="numpy")
def polynomial_roots_near_zero(coef, dcoef, levels, steps):
    """For each row ``j``: Newton's iterate for ``p_j(x) = levels[j]`` from ``x = 0``, at most ``steps``
    steps, stopping at a fixed point; ``p_j`` the power series ``coef[j]`` (increasing powers) and
    ``dcoef[j]`` its derivative's. Horner as ``np.polynomial.polynomial.polyval`` (``c[-1] + x * 0``, then
    ``c[k] + y * x``), bit for bit the vectorised iteration over all rows."""
    rows, terms = coef.shape
    out = np.empty(rows)
    for j in range(rows):
        x = 0.0
        for _ in range(steps):
            p = coef[j, terms - 1] + x * 0.0
            for k in range(terms - 2, -1, -1):
                p = coef[j, k] + p * x
            dp = dcoef[j, terms - 2] + x * 0.0
            for k in range(terms - 3, -1, -1):
                dp = dcoef[j, k] + dp * x
            x_next = x - (p - levels[j]) / dp
            if x_next == x:
                break
            x = x_next
        out[j] = x
    return out



@njit(cache=True, error_model="numpy")
def gradient(f, x):
    """``np.gradient(f, x)`` of a 1-D series ``f`` at the abscissae ``x`` (at least two samples; first-order
    edges), bit for bit: centred differences ``(f[k+1] - f[k-1]) / (2 dx)`` when every interval equals the
    first, otherwise numpy's second-order weights for uneven intervals."""
    n = len(f)
    out = np.empty(n)
    dx = x[1:] - x[:-1]
    uniform = True
    for k in range(1, n - 1):
        if dx[k] != dx[0]:
            uniform = False
            break
    if uniform:
        two_dx = 2.0 * dx[0]
        for k in range(1, n - 1):
            out[k] = (f[k + 1] - f[k - 1]) / two_dx
    else:
        for k in range(1, n - 1):
            dx1, dx2 = dx[k - 1], dx[k]
            a = -(dx2) / (dx1 * (dx1 + dx2))
            b = (dx2 - dx1) / (dx1 * dx2)
            c = dx1 / (dx2 * (dx1 + dx2))
            out[k] = a * f[k - 1] + b * f[k] + c * f[k + 1]
    out[0] = (f[1] - f[0]) / dx[0]
    out[n - 1] = (f[n - 1] - f[n - 2]) / dx[n - 2]
    return out



@njit(cache=True, error_model="numpy")
def scaled_deviation(t, first, tc, half_width, canonical):
    """``np.max(np.abs(x - canonical))`` over the rows ``x[j] = (t[first[j]:first[j] + m] - tc[j]) /
    half_width`` (``m = len(canonical)``), without forming them: the same operations element by
    element, so the same number (nan when any is nan, as ``np.max``)."""
    m = len(canonical)
    worst = 0.0 if len(first) else np.nan
    for j in range(len(first)):
        for k in range(m):
            d = abs((t[first[j] + k] - tc[j]) / half_width - canonical[k])
            if np.isnan(d):
                return np.nan
            if d > worst:
                worst = d
    return worst


@njit(cache=True, error_model="numpy")
def canonical_abscissae(t, first, tc, half_width, m, grid):
    """A crossing fit's scaled abscissae ``(t[first:first + m] - tc) / half_width`` rounded to multiples of
    ``1 / grid`` (a power of two): ``np.round(row * grid) / grid`` (``np.round`` is ``rint``), element by element."""
    out = np.empty(m)
    for k in range(m):
        out[k] = np.rint((t[first + k] - tc) / half_width * grid) / grid
    return out


@njit(cache=True, error_model="numpy")
def is_ascending(x):
    """``bool(np.all(np.diff(x) >= 0))`` of a 1-D array (False at a nan step, as numpy)."""
    for k in range(len(x) - 1):
        if not x[k + 1] - x[k] >= 0:
            return False
    return True



@njit(cache=True, error_model="numpy")
def count_crossings(t, phi, a, b, k, q):
    """Where a quantised angle ``phi`` (encoder step ``q``, rad) steps between samples ``a`` and ``b``:
    per count crossed, its instant relative to ``t[k]`` (s) and the angle midway between the two
    readings (rad); a step of several counts in one sample spreads them over it (count ``m`` of ``n``
    at ``(m + 0.5) / n``). Returns ``(tau, levels)``, empty when fewer than four counts. Element by
    element the numpy expressions of ``energy_rest.crossings_fit`` (``n = max(1, round(|d| / q))``,
    ``t0 + (m + 0.5) / n (t1 - t0)``, ``phi0 + sign(d) (m + 0.5) q``), bit for bit."""
    total = 0
    for s in range(a, b):
        d = phi[s + 1] - phi[s]
        if d != 0:
            total += int(max(1.0, np.rint(abs(d) / q)))
    if total < 4:
        return np.empty(0), np.empty(0)
    tau = np.empty(total)
    levels = np.empty(total)
    c = 0
    for s in range(a, b):
        d = phi[s + 1] - phi[s]
        if d != 0:
            n = int(max(1.0, np.rint(abs(d) / q)))
            t0, t1 = t[s], t[s + 1]
            for m in range(n):
                tau[c] = (t0 + (m + 0.5) / float(n) * (t1 - t0)) - t[k]
                levels[c] = phi[s] + np.sign(d) * (m + 0.5) * q
                c += 1
    return tau, levels


@njit(cache=True, error_model="numpy")
def first_at_or_past(phi, a, b, offset, direction, levels):
    """The crossing search of ``crossings.first_crossings`` on a finite stroke: with ``x = direction *
    phi[a:b]`` and its running maximum ``top`` (``np.maximum.accumulate``), per level the first ``k`` with
    ``top[k] >= direction * level`` (``np.searchsorted(top, ..., side="left")``) as ``offset + k``, or -1
    past the end; and whether ``x[0] >= direction * level`` (reached at the first sample). Returns ``(out,
    reached, ok)``; ``ok`` is False (and the rest unset) when an ``x`` or a level is not finite."""
    n = b - a
    top = np.empty(n)
    out = np.empty(len(levels), dtype=np.int64)
    reached = np.zeros(len(levels), dtype=np.bool_)
    for k in range(n):
        x = direction * phi[a + k]
        if not np.isfinite(x):
            return out, reached, False
        top[k] = x if k == 0 or x > top[k - 1] else top[k - 1]
    for j in range(len(levels)):
        if not np.isfinite(levels[j]):
            return out, reached, False
    for j in range(len(levels)):
        target = direction * levels[j]
        lo, hi = 0, n
        while lo < hi:
            mid = (lo + hi) // 2
            if top[mid] < target:
                lo = mid + 1
            else:
                hi = mid
        out[j] = offset + lo if lo < n else -1
        reached[j] = direction * phi[a] >= target
    return out, reached, True


@njit(cache=True, error_model="numpy")
def accumulated_kernels(indices, weights, lengths, factors, size):
    """``np.bincount(indices, weights=np.repeat(factors, lengths) * weights, minlength=size)``: kernel ``r``
    (``lengths[r]`` consecutive entries of ``indices``, ``weights``) scaled by ``factors[r]`` and added sample
    by sample in order, as bincount sums."""
    top = size
    for k in range(len(indices)):
        if indices[k] < 0:
            raise ValueError("'list' argument must have no negative elements")
        if indices[k] + 1 > top:
            top = indices[k] + 1
    out = np.zeros(top)
    k = 0
    for r in range(len(lengths)):
        f = factors[r]
        for _ in range(lengths[r]):
            out[indices[k]] += f * weights[k]
            k += 1
    return out


@njit(cache=True, error_model="numpy")
def accumulated_windows(first, sizes, offsets, weights, fits, factors, size):
    """:func:`accumulated_kernels` of kernels over consecutive samples: kernel ``r`` is fit ``f = fits[r]``'s,
    indices ``first[f] + arange(sizes[f])`` and weights ``weights[offsets[f]:offsets[f] + sizes[f]]``, scaled
    by ``factors[r]`` and added sample by sample, kernel after kernel (the same sums in the same order)."""
    top = size
    for r in range(len(fits)):
        f = fits[r]
        if sizes[f] > 0:
            if first[f] < 0:
                raise ValueError("'list' argument must have no negative elements")
            if first[f] + sizes[f] > top:
                top = first[f] + sizes[f]
    out = np.zeros(top)
    for r in range(len(fits)):
        f = fits[r]
        start, at, c = first[f], offsets[f], factors[r]
        for j in range(sizes[f]):
            out[start + j] += c * weights[at + j]
    return out


@njit(cache=True, error_model="numpy")
def place_rows(out, offsets, rows):
    """``out[offsets[r]:offsets[r] + rows.shape[1]] = rows[r]`` for every row ``r`` (a copy)."""
    m = rows.shape[1]
    for r in range(rows.shape[0]):
        at = offsets[r]
        for j in range(m):
            out[at + j] = rows[r, j]


@njit(cache=True, error_model="numpy")
def calibration_target(tt, th, psi, f_visc, f_coul, J_f, w_s):
    """The angle the flywheel calibration (``energy_calibration.flywheel_calibration``) explains, and the half sample
    intervals: with ``om = gradient(psi, tt)`` and the friction ``f_visc om + f_coul tanh(om / w_s)`` (dry friction smoothed over the rate ``w_s``), ``th +
    twice_integrated(friction) / J_f``, and ``0.5 * np.diff(tt)``: the numpy expressions element by element."""
    m = len(tt)
    om = gradient(psi, tt)
    half = np.empty(m - 1)
    for k in range(m - 1):
        half[k] = 0.5 * (tt[k + 1] - tt[k])
    target = np.empty(m)
    target[0] = th[0] + 0.0 / J_f
    first, second = 0.0, 0.0
    prev = f_visc * om[0] + f_coul * np.tanh(om[0] / w_s)
    for k in range(m - 1):
        cur = f_visc * om[k + 1] + f_coul * np.tanh(om[k + 1] / w_s)
        first_next = first + (cur + prev) * half[k]
        second = second + (first_next + first) * half[k]
        target[k + 1] = th[k + 1] + second / J_f
        first, prev = first_next, cur
    return target, half


@njit(cache=True, error_model="numpy")
def window_rows(x, starts, m):
    """Rows of ``m`` consecutive samples of ``x`` from each of ``starts``: the sample indices
    ``starts[:, None] + np.arange(m)`` and the values ``x[indices]``."""
    idx = np.empty((len(starts), m), dtype=np.int64)
    rows = np.empty((len(starts), m))
    for r in range(len(starts)):
        for j in range(m):
            idx[r, j] = starts[r] + j
            rows[r, j] = x[starts[r] + j]
    return idx, rows


def warm_up() -> None:
    """Load every kernel's machine code now (from the cache, or compiled: a few seconds once), so that
    the first identification in a process costs what the others do."""
    t = np.arange(8) * 1e-3
    twice_integrated(np.ones((1, 8)), 0.5 * np.diff(t))
    one = np.ones(1, dtype=np.int64)
    accumulated_windows(one, one, one - 1, t, one - 1, t[:1], 8)
    place_rows(np.empty(8), one - 1, np.ones((1, 8)))
    fit_windows(t, t[:2], 2e-3)
    polynomial_roots_near_zero(np.ones((1, 3)), np.ones((1, 2)), np.zeros(1), 8)
    gradient(t, t)
    is_ascending(t)
    count_crossings(t, t, 0, 7, 0, 1e-3)
    scaled_deviation(t, np.zeros(1, dtype=np.int64), t[:1], 1.0, t[:2])
    lag_ranking(np.ones(3), np.eye(3), np.zeros(2, dtype=np.int64), np.zeros(2), 1.0)
    twice_integrated(np.lib.stride_tricks.sliding_window_view(t, 4), 0.5 * np.diff(t[:4]))
    first_at_or_past(t, 0, 8, 0, -1.0, t[:3])
    canonical_abscissae(t, 0, 0.0, 1.0, 4, 2.0**40)
    window_rows(t, np.arange(2), 3)
    accumulated_kernels(np.arange(8), t, np.array([3, 5]), t[:2], 8)
    calibration_target(t, t, t, 0.1, 0.01, 2.0, 0.01)
