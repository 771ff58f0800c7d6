"""The water's radiation memory identified from the rig's own records (physics.md section 6).

At a free surface the radiation moment on the hull is (Cummins 1962)

    Q_rad = -A66(inf) phi'' - mu,     mu = integral_0^t K(t - s) phi'(s) ds,
    K(j w) = B66(w) + j w (A66(w) - A66(inf)).

The records hold what pins it down (no kernel shape assumed): right after the release and
after the brake lets go the hull's acceleration is set by A66(inf) (the water has not yet
responded); over the swing the water acts as A66 at the swing frequency; the transient in
between shows how fast the water remembers. A66(0), the spec's lambda66, is an
extrapolation from those frequencies: it is reported with the spread over the low-order
passive model families that fit the records.

**The hull's own equation.** The motor's torque is internal to hull + flywheel (it acts on
the rotor and, as a reaction, on the stator fixed to the hull), so the hull row of the mass
matrix (physics.md section 2) holds without the motor's current:

    (J_h + J_f + A66(inf)) phi'' + J_f psi'' + mu + b1 w + b2 w|w| + q sgn w + T0
        = -c (phi - phi_n)                                    (on every unbraked sample)

Integrated twice from the start ``t0`` of a window (the *integral* form: angles only, no
differentiated encoder noise, and the acceleration step at a release is not smeared by a
filter)::

    -(J_h + J_f) dphi - J_f dpsi - c II(phi - phi_n)
        = A66(inf) dphi + sum_i theta_i d(G_i phi) + b1 I(dphi) + b2 II(w|w|) + q II(sgn w)
          + T0 (t - t0)^2 / 2 - P0 (t - t0)

``d`` is the change since ``t0``, ``I``/``II`` single/double integrals from ``t0``, ``P0`` the
window's unknown initial momentum (one nuisance per window). The memory is
``mu = s^2 (sum_i theta_i G_i(s)) phi``, i.e. ``K(s) = s sum_i theta_i G_i(s)`` with the
``G_i`` a basis of strictly proper first- and second-order sections with chosen poles:
linear in ``A66(inf)``, ``theta``, ``b1``, ``b2``... for given poles, so the poles are searched
(variable projection, :func:`scipy.optimize.least_squares`) and the rest solved by least
squares. Then ``A66(w) = A66(inf) + Re sum theta_i G_i(j w)``, ``A66(0) = A66(inf) + sum
theta_i G_i(0)``, and the model is passive where ``Re K(j w) >= 0`` on a frequency grid.

Families (:data:`FAMILIES`): one real pole (A66 falls monotonically: a mass coupled
through a damper), one complex pair (A66 may rise above A66(0) before falling: the
free-surface's resonant shape), two real poles, a pair and a real pole, two pairs; each but the
one real pole also without an instantaneous part (``-sp``, strictly proper: ``B66(inf) = 0``, as
potential-flow radiation has; see :func:`_kernel_map` for why the records need that told to them:
an instantaneous part of the kernel is a damping, and trades against A66(inf)). The reported family
is the simplest of those that fit (fewest parameters). The memory-free model (``none``) is fitted too; memory is declared only when it explains most
of what the memory-free model leaves (:data:`MEMORY_RSS_RATIO`) with a passive model, and most of what its
amplitude-dependent rival leaves: the memory-free equation with a stiffening rod's odd terms
(:data:`STIFFENING_POWERS`), the best family refitted on top of it (memory is linear; within one run a rod's
amplitude-dependent swing can pass for memory).

Intervals: per family, the coefficients' covariance is clustered by window (the integral
form's residuals are correlated within a window), the pole positions' share added by
perturbing them along the fit's Jacobian; the reported 95 % interval of each quantity is
that of the mixture of the passive families' estimates, each weighted by its Akaike weight
with the windows as the independent pieces of evidence (:mod:`~addedinertia_env.identify.model_average`;
before: the union over every family within :data:`FAMILY_RSS_TOLERANCE` of the best residual, which the
worst family kept sized). A66(inf)'s variance is clustered by stretch of free motion (its evidence is the
instants after each start from rest) with Student's t; its interval is built on log A66(inf) (a positive
quantity whose families' estimates spread by factors, not by amounts) and holds the reported family's
jackknife over those stretches (:func:`jackknife_a_inf`).

Only the records' samples and ``rig`` blocks are read; never ``truth``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from addedinertia_env.identify.model_average import akaike_weights, mixture_interval
from addedinertia_env.records.record import RunRecord, braked

# The passive families searched: each a tuple of sections, 'r' one real pole, 'c' a complex pair.
# A name ending in STRICT_SUFFIX is the same family without an instantaneous part (see _kernel_map).
STRICT_SUFFIX = "-sp"
FAMILIES: dict[str, tuple[str, ...]] = {"r1": ("r",), "c1": ("c",), "c1-sp": ("c",), "r2": ("r", "r"),
                                        "r2-sp": ("r", "r"), "c1r1": ("c", "r"), "c1r1-sp": ("c", "r"),
                                        "c2": ("c", "c"), "c2-sp": ("c", "c")}
MAX_STARTS = 2  # starting pole sets per family (a slow and a fast section, both ways round)
WINDOW_S = 1.5  # s: integral-form windows (long against the memory's ~0.1-1 s, short against drift)
ROW_STEP_S = 0.02  # s: one equation row every 20 ms (the integral form is smooth)
MEMORY_RSS_RATIO = 0.05  # memory declared when a passive model leaves < 5 % of the memory-free residual
FAMILY_RSS_TOLERANCE = 1.25  # the reported family: the simplest within 25 % of the best residual
MIN_FAMILY_WEIGHT = 1e-3  # families with a smaller Akaike weight are left out of the average (and its corrections)
# The memory fit's own resolution, as a share of the memory's part of A66(0) (A66(0) - A66(inf)): on records
# without noise every variance estimate vanishes, and what is left is the fit's discretisation against the
# water's (Tustin sections, the Hann smoothing). Measured on the noise-free drawn hulls of the interval calibration
# (docs/INTERVALS.md, session 12): errors of 2-6 parts per million of A66(0), up to 1.2e-5 of its memory part;
# A66(0)'s interval is never narrower than +- this share of it.
RESOLUTION = 2e-5
MIN_STRETCHES = 3  # stretches of free motion needed to estimate the memory model's error from the records
PASSIVE_GAP = 2.0  # a non-passive fit better than this many times the best passive one: memory not pinned down
PASSIVITY_TOLERANCE = 0.02  # min Re K(jw) >= -2 % of max |Re K(jw)| on the grid (fit noise)
OMEGA_GRID = np.logspace(-2, 3, 300)  # rad/s, passivity grid
MIN_FREE_S = 3.0  # s of unbraked motion needed
MIN_RELEASES = 1  # starts from rest (a release or a brake letting go) needed
POLE_RANGE = (0.3, 60.0)  # rad/s: searched pole magnitudes (the rig's records resolve this band)
Z95 = 1.96
POLE_SEARCH = dict(x_scale=1.0, diff_step=1e-4, max_nfev=60, xtol=1e-6, ftol=1e-10)  # least_squares' options
STIFFENING_POWERS = (3, 5)  # the torsion rod's odd nonlinear terms c d^n (d = phi - phi_n): memory's amplitude-dependent rival


class MemoryNotIdentifiable(ValueError):
    """The records cannot show the water's memory (no transient, too short, no passive fit)."""


# --- the records, on a uniform grid -----------------------------------------------------
@dataclass
class _Series:
    name: str
    t: np.ndarray
    phi: np.ndarray
    psi: np.ndarray
    free: np.ndarray  # bool: the hull unbraked (the equation holds)
    dt: float
    J_h: float
    J_f: float
    c: float
    phi_n: float


def _series(rec: RunRecord) -> _Series:
    known = rec.known
    dt = 1.0 / known.sample_rate
    t = np.asarray(rec.t, float)
    # The even grid ends at the first gap too long to bridge (over a second): no equation holds across
    # it, and a grid through a gap of hours would not fit in memory. Shorter gaps are held, below.
    long_gaps = np.nonzero(np.diff(t) > max(1.0, 5.0 * dt))[0]
    t_end = t[long_gaps[0]] if long_gaps.size else t[-1]
    grid = t[0] + dt * np.arange(int(math.floor((t_end - t[0]) / dt + 1e-6)) + 1)
    held = braked(rec)
    if "brake" not in rec.samples:  # no brake column: the phases say when the hull moves freely
        held = held | ~np.isin(np.asarray(rec.phase), ("free", "reverse"))
    free = np.interp(grid, t, held.astype(float)) < 1e-9
    # a gap in the samples (over five periods) is no place for an equation: treated as held
    gaps = np.nonzero(np.diff(t) > 5.0 * dt)[0]
    for k in gaps:
        free[(grid >= t[k]) & (grid <= t[k + 1])] = False
    return _Series(rec.name, grid, _smooth(np.interp(grid, t, rec["phi"])), _smooth(np.interp(grid, t, rec["psi"])), free, dt,
                   known.J_hull, known.J_flywheel, known.c_torsion, known.phi_neutral)


def _record_kind(rec: RunRecord) -> str:
    """The kind of run a record is, for grouping its stretches of free motion: the experiment's ``kind`` where the
    record states it, else ``reverse-symmetric`` where a reverse stroke is in its phases, else ``free-decay``."""
    kind = (rec.meta.get("experiment") or {}).get("kind") if isinstance(rec.meta, dict) else None
    if isinstance(kind, str) and kind:
        return kind
    return "reverse-symmetric" if "reverse" in set(np.asarray(rec.phase).astype(str)) else "free-decay"


SMOOTH_HALF = 10  # samples: half-width of the Hann smoothing applied to phi and psi before the equation


def _smooth(x: np.ndarray, half: int = SMOOTH_HALF) -> np.ndarray:
    """A zero-phase Hann-window average (``2 half + 1`` samples). Every term of the hull's
    equation but the drag is linear in the angles, so the smoothed angles obey the same
    equation wherever the window lies in free motion (rows closer than ``half`` to a brake
    are dropped); the encoder's quantisation above ~40 Hz, which a fast memory pole could
    otherwise fit as inertia, is removed."""
    if half < 1 or len(x) < 2 * half + 1:
        return x
    w = np.hanning(2 * half + 3)[1:-1]
    w /= w.sum()
    pad = np.r_[np.full(half, x[0]), x, np.full(half, x[-1])]
    return np.convolve(pad, w, mode="valid")


def _cumtrapz(y: np.ndarray, dt: float) -> np.ndarray:
    out = np.empty_like(y)
    out[0] = 0.0
    np.cumsum((y[1:] + y[:-1]) * (0.5 * dt), out=out[1:])
    return out


def _free_segments(free: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.r_[0, free.astype(np.int8), 0]))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


@dataclass
class _Window:
    series: int
    start: int
    rows: np.ndarray  # sample indices of the equation rows


class MemoryData:
    """The integral-form equation rows of a hull's records (see the module doc)."""

    BASE = ("A66_inf", "b1", "b2", "q", "T0")

    def __init__(self, records: list[RunRecord], window_s: float = WINDOW_S, row_step_s: float = ROW_STEP_S):
        self.series = [_series(r) for r in records]
        self.windows: list[_Window] = []
        base, ys, stiff = [], [], []
        segment_of_window: list[int] = []  # which stretch of free motion (a start from rest, mostly) each window is in
        n_segments = 0
        self._stretch_kinds: list[tuple[str, int]] = []  # (its record's kind, its place in the record) per stretch
        self.free_s = 0.0
        self.releases = 0
        for k, s in enumerate(self.series):
            if len(s.phi) < 2:
                continue  # no rate to read: a record cut to one sample holds no free motion (it is not identifiable)
            place = 0  # this record's stretches so far
            w = np.gradient(s.phi, s.dt)
            step = max(1, int(round(row_step_s / s.dt)))
            n_win = max(2, int(round(window_s / s.dt)))
            for a, b in _free_segments(s.free):
                if a > 0:
                    self.releases += 1  # a start from rest: the brake let go
                a, b = a + SMOOTH_HALF if a > 0 else a, b - SMOOTH_HALF if b < len(s.free) else b
                if b - a < n_win // 3:
                    continue
                n_segments += 1
                self._stretch_kinds.append((_record_kind(records[k]), place))
                place += 1
                self.free_s += (b - a) * s.dt
                for a0 in range(a, b - n_win // 3, n_win):
                    b0 = min(a0 + n_win, b)
                    seg = slice(a0, b0)
                    tt = s.t[seg] - s.t[a0]
                    dphi = s.phi[seg] - s.phi[a0]
                    ww = w[seg]
                    y = (-(s.J_h + s.J_f) * dphi - s.J_f * (s.psi[seg] - s.psi[a0])
                         - s.c * _cumtrapz(_cumtrapz(s.phi[seg] - s.phi_n, s.dt), s.dt))
                    cols = np.stack([dphi, _cumtrapz(dphi, s.dt), _cumtrapz(_cumtrapz(ww * np.abs(ww), s.dt), s.dt),
                                     _cumtrapz(_cumtrapz(np.sign(ww), s.dt), s.dt), 0.5 * tt**2], axis=1)
                    sel = np.arange(step, len(tt), step)
                    if len(sel) < 3:
                        continue
                    self.windows.append(_Window(k, a0, sel + a0))
                    segment_of_window.append(n_segments - 1)
                    base.append((cols[sel], tt[sel]))
                    ys.append(y[sel])
                    d = s.phi[seg] - s.phi_n
                    stiff.append(np.stack([s.c * _cumtrapz(_cumtrapz(d**n, s.dt), s.dt) for n in STIFFENING_POWERS],
                                          axis=1)[sel])
        if not self.windows:
            raise MemoryNotIdentifiable("no unbraked motion long enough for the hull's equation")
        n_rows = sum(len(y) for y in ys)
        self.n_windows = len(self.windows)
        self.segment_of_window = np.asarray(segment_of_window, dtype=np.int64)
        X = np.zeros((n_rows, len(self.BASE) + self.n_windows))
        self.window_of_row = np.zeros(n_rows, dtype=np.int64)
        r = 0
        for j, ((cols, tt), y) in enumerate(zip(base, ys)):
            X[r:r + len(y), :len(self.BASE)] = cols
            X[r:r + len(y), len(self.BASE) + j] = -tt
            self.window_of_row[r:r + len(y)] = j
            r += len(y)
        self.X, self.Y = X, np.concatenate(ys)
        # the amplitude-dependent alternative to memory (not part of the fit; see stiffness_alternative)
        self.S = np.vstack(stiff)
        scale = np.sqrt(np.mean(X**2, axis=0))
        self.scale = np.where(scale > 0, scale, 1.0)
        # the base columns projected out once (variable projection)
        self.Q, _ = np.linalg.qr(X / self.scale)
        self.Yp = self.Y - self.Q @ (self.Q.T @ self.Y)

    # -- memory columns for a pole set -------------------------------------------------
    def memory_columns(self, sections: list[tuple], strict: bool = False) -> np.ndarray:
        """``d(G_i phi)`` since each window's start for the basis of ``sections``
        (``('r', a)``: 1/(s + a); ``('c', wn, z)``: 1/D and s/D, D = s^2 + 2 z wn s + wn^2), in the
        free coefficients (``strict``: without the kernel's instantaneous part, :func:`_kernel_map`)."""
        from scipy import signal  # noqa: PLC0415

        per_series = []
        filters: dict[float, list] = {}  # the discrete sections per sampling step (computed once per call)
        for s in self.series:
            cols = []
            if s.dt not in filters:
                filters[s.dt] = [(*bilinear(n, d, 1.0 / s.dt),) for n, d in _section_tfs(sections)]
                filters[s.dt] = [(bd, ad, signal.lfilter_zi(bd, ad)) for bd, ad in filters[s.dt]]
            for bd, ad, zi1 in filters[s.dt]:
                zi = zi1 * s.phi[0]
                cols.append(signal.lfilter(bd, ad, s.phi, zi=zi)[0])
            per_series.append(np.stack(cols, axis=1))
        M = np.vstack([per_series[w.series][w.rows] - per_series[w.series][w.start] for w in self.windows])
        return M @ _kernel_map(sections, strict)

    def projected_residual(self, sections: list[tuple], strict: bool = False) -> np.ndarray:
        """The residual of the memory-free equation after the memory columns of ``sections`` (a kernel's poles)
        are fitted by least squares in the space the projection leaves, in the equation's units (N m s^2)."""
        M = self.memory_columns(sections, strict)
        Mp = M - self.Q @ (self.Q.T @ M)
        coef, *_ = np.linalg.lstsq(Mp, self.Yp, rcond=None)
        return self.Yp - Mp @ coef

    def solve(self, sections: list[tuple], strict: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All coefficients (the memory's free ones first, then :attr:`BASE`, then the windows' momenta), the
        residual, and the full design."""
        M = self.memory_columns(sections, strict) if sections else np.zeros((len(self.Y), 0))
        X = np.hstack([M, self.X])
        sc = np.sqrt(np.mean(X**2, axis=0))
        sc = np.where(sc > 0, sc, 1.0)
        coef, *_ = np.linalg.lstsq(X / sc, self.Y, rcond=None)
        coef = coef / sc
        return coef, self.Y - X @ coef, X

    def with_columns(self, extra: np.ndarray) -> MemoryData:
        """The same rows with the columns ``extra`` added to the memory-free equation (a rival's terms)."""
        import copy  # noqa: PLC0415

        out = copy.copy(self)
        out.X = np.hstack([self.X, extra])
        scale = np.sqrt(np.mean(out.X**2, axis=0))
        out.scale = np.where(scale > 0, scale, 1.0)
        out.Q, _ = np.linalg.qr(out.X / out.scale)
        out.Yp = out.Y - out.Q @ (out.Q.T @ out.Y)
        return out

    def without_segment(self, k: int) -> MemoryData:
        """The same equation without the rows of stretch ``k`` of free motion (a jackknife sample)."""
        import copy  # noqa: PLC0415

        keep_w = np.flatnonzero(self.segment_of_window != k)
        keep_r = np.isin(self.window_of_row, keep_w)
        out = copy.copy(self)
        out.windows = [self.windows[j] for j in keep_w]
        renumber = np.full(self.n_windows, -1, dtype=np.int64)
        renumber[keep_w] = np.arange(len(keep_w))
        out.window_of_row = renumber[self.window_of_row[keep_r]]
        out.segment_of_window = self.segment_of_window[keep_w]
        out.n_windows = len(keep_w)
        base = list(range(len(self.BASE))) + [len(self.BASE) + j for j in keep_w]  # the dropped windows' momenta go
        out.X, out.Y, out.S = self.X[keep_r][:, base], self.Y[keep_r], self.S[keep_r]
        scale = np.sqrt(np.mean(out.X**2, axis=0))
        out.scale = np.where(scale > 0, scale, 1.0)
        out.Q, _ = np.linalg.qr(out.X / out.scale)
        out.Yp = out.Y - out.Q @ (out.Q.T @ out.Y)
        return out

    def stretch_kinds(self) -> list[tuple[str, int]]:
        """Each stretch of free motion's kind: its record's kind (:func:`_record_kind`) and its place among that
        record's stretches (a reverse run's first is the stroke after the release from the hold, its second the
        stroke after the brake lets go at rest). Stretches of one kind are repeats of one measurement."""
        return list(self._stretch_kinds)

    @property
    def segment_of_row(self) -> np.ndarray:
        """The stretch of free motion each equation row is in (the clusters of A66(inf)'s evidence)."""
        return self.segment_of_window[self.window_of_row]

    @property
    def n_segments(self) -> int:
        """How many stretches of free motion (starts from rest) the rows come from."""
        return int(self.segment_of_window.max()) + 1

    def clustered_covariance(self, X: np.ndarray, resid: np.ndarray, clusters: np.ndarray | None = None) -> np.ndarray:
        """Coefficient covariance with the residuals clustered by window (sandwich form); ``clusters``: another
        cluster index per row (the stretches of free motion, :attr:`segment_of_row`)."""
        sc = np.sqrt(np.mean(X**2, axis=0))
        sc = np.where(sc > 0, sc, 1.0)
        rows_c = self.window_of_row if clusters is None else clusters
        return _cluster_sandwich(X / sc, resid, rows_c) / np.outer(sc, sc)


def bilinear(num, den, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """The Tustin (bilinear) discretisation of ``num(s)/den(s)`` at sampling rate ``fs``: the same
    as :func:`scipy.signal.bilinear` (``s = 2 fs (z - 1)/(z + 1)``), without its polynomial-class overhead
    (the memory fit calls it thousands of times)."""
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))
    n = len(den) - 1
    num = np.r_[np.zeros(n + 1 - len(num)), num]
    c = 2.0 * fs
    b, a = np.zeros(n + 1), np.zeros(n + 1)
    for m in range(n + 1):  # the s^m term: c^m (z - 1)^m (z + 1)^(n - m) over (z + 1)^n
        term = np.polymul(np.poly(np.ones(m)), np.poly(-np.ones(n - m))) * c**m
        b += num[n - m] * term
        a += den[n - m] * term
    return b / a[0], a / a[0]


def _feedthrough_index(sections: list[tuple]) -> list[int]:
    """The basis functions whose ``s G_i(s)`` tends to a constant as s grows (``1/(s + a)`` and ``s/D``): the
    kernel's instantaneous part ``K(inf) = B66(inf)`` is the sum of their coefficients."""
    out, k = [], 0
    for sec in sections:
        out.append(k if sec[0] == "r" else k + 1)
        k += 1 if sec[0] == "r" else 2
    return out


def _kernel_map(sections: list[tuple], strict: bool) -> np.ndarray:
    """``theta = T c``: the basis coefficients from the free ones ``c``. Without ``strict`` every
    coefficient is free (``T = I``). With ``strict`` the kernel has no instantaneous part,
    ``K(inf) = B66(inf) = 0``: the first feedthrough coefficient is minus the sum of the others.

    Why a family needs that variant: an instantaneous part of the kernel is a damping ``B66(inf) w``,
    the same term as the drag's linear ``b1 w``; the records tell them apart only through the kernel's
    shape (``K(0) = 0``), i.e. by how the acceleration right after a release bends in the first tens of
    milliseconds, which the encoder barely resolves (one count is 5e-5 rad: a hull released at 0.3
    rad/s^2 moves one count in 18 ms). A free kernel then trades a large ``B66(inf)`` against a low
    ``A66(inf)`` at almost the same residual (measured: docs/RADIATION_MEMORY.md). Potential-flow
    radiation at a free surface has ``B66(w) -> 0`` as ``w -> inf`` (the kernel ``K(t) = (2/pi) int B66
    cos(w t) dw`` is a bounded function; Ogilvie 1964, Newman 1977 section 6.16); another water (a mass
    behind a damper) need not, so both variants are fitted and the simpler that fits is reported."""
    n = sum(1 if sec[0] == "r" else 2 for sec in sections)
    T = np.eye(n)
    ft = _feedthrough_index(sections)
    if not strict or not ft:
        return T
    T[ft[0], :] = 0.0
    T[ft[0], ft[1:]] = -1.0
    return np.delete(T, ft[0], axis=1)


def _section_tfs(sections: list[tuple]):
    for sec in sections:
        if sec[0] == "r":
            yield [1.0], [1.0, sec[1]]
        else:
            wn, z = sec[1], sec[2]
            den = [1.0, 2.0 * z * wn, wn * wn]
            yield [1.0], den
            yield [1.0, 0.0], den


def _basis(sections: list[tuple], s: complex | np.ndarray) -> np.ndarray:
    """The basis G_i(s), stacked along the last axis."""
    s = np.asarray(s, dtype=complex)
    out = []
    for sec in sections:
        if sec[0] == "r":
            out.append(1.0 / (s + sec[1]))
        else:
            wn, z = sec[1], sec[2]
            D = s * s + 2.0 * z * wn * s + wn * wn
            out += [1.0 / D, s / D]
    return np.stack(out, axis=-1) if out else np.zeros(s.shape + (0,))


def _unpack(kinds: tuple[str, ...], x: np.ndarray) -> list[tuple]:
    out, i = [], 0
    for k in kinds:
        if k == "r":
            out.append(("r", float(np.exp(x[i]))))
            i += 1
        else:
            out.append(("c", float(np.exp(x[i])), float(1.0 / (1.0 + np.exp(-x[i + 1])))))
            i += 2
    return out


def _starts(kinds: tuple[str, ...]) -> list[np.ndarray]:
    options = {"r": [(math.log(3.0),), (math.log(10.0),)],
               "c": [(math.log(3.0), 0.0), (math.log(8.0), -0.5)]}
    out = []
    for combo in itertools.product(*(options[k] for k in kinds)):
        x = np.array([v for part in combo for v in part])
        out.append(x)
    if len(kinds) == 1:
        return out
    return out[1:-1][:MAX_STARTS]  # one section slow and one fast, both ways round (equal poles are degenerate)


# --- one family's fit ---------------------------------------------------------------------
@dataclass
class FamilyFit:
    """One passive-model family fitted to the records (kg m^2, rad/s)."""

    family: str
    sections: list[tuple]
    rss: float
    A_inf: float
    A_zero: float
    A_swing: float
    sigma: dict[str, float]  # 1-sigma of A_inf, A_zero, A_swing (clustered + pole positions; A_inf's by stretch)
    passive: bool
    min_re_K: float
    theta: np.ndarray = field(repr=False)  # memory coefficients (kg m^2 x section units)
    b1: float = 0.0
    b2: float = 0.0
    cov_theta: np.ndarray | None = field(default=None, repr=False)  # covariance of ``theta`` (clustered)
    strict: bool = False  # without an instantaneous part: B66(inf) = 0 (:func:`_kernel_map`)
    x: np.ndarray | None = field(default=None, repr=False)  # the packed pole parameters (a start for the variant)
    pole_sigma: np.ndarray | None = field(default=None, repr=False)  # 1-sigma of ``x`` (clustered; None: poles fixed)

    @property
    def n_params(self) -> int:
        """Pole parameters plus free memory coefficients: the fit's size (the simplest that fits is reported)."""
        n_basis = sum(1 if sec[0] == "r" else 2 for sec in self.sections)
        return n_basis + n_basis - (1 if self.strict else 0)

    @property
    def B_inf(self) -> float:
        """The kernel's instantaneous part ``K(inf) = B66(inf)``, N m s (0 for a strictly proper family)."""
        return float(sum(self.theta[k] for k in _feedthrough_index(self.sections)))

    def added_inertia(self, omega) -> np.ndarray:
        """A66(omega), kg m^2."""
        omega = np.atleast_1d(np.asarray(omega, float))
        return self.A_inf + np.real(_basis(self.sections, 1j * omega) @ self.theta)

    def memory_moment(self, rate: np.ndarray, dt: float) -> np.ndarray:
        """mu(t) (N m) for the hull rate ``rate`` (rad/s, uniform step ``dt``, from rest):
        ``mu = s (sum theta_i G_i(s)) w``."""
        from scipy import signal  # noqa: PLC0415

        mu = np.zeros_like(rate)
        k = 0
        for num, den in _section_tfs(self.sections):
            num = np.polymul(num, [1.0, 0.0])  # s G_i(s): proper
            bd, ad = signal.bilinear(num, den, 1.0 / dt)
            mu += self.theta[k] * signal.lfilter(bd, ad, rate)
            k += 1
        return mu

    def summary(self) -> dict[str, Any]:
        """This family's fit as JSON: its poles (1/s, real and imaginary parts), coefficients and residual."""
        poles = []
        for sec in self.sections:
            if sec[0] == "r":
                poles.append({"re": -sec[1], "im": 0.0})
            else:
                wn, z = sec[1], sec[2]
                poles.append({"re": -z * wn, "im": wn * math.sqrt(max(1.0 - z * z, 0.0))})
        return {"family": self.family, "order": sum(1 if s[0] == "r" else 2 for s in self.sections),
                "poles_1_per_s": poles, "A66_inf": self.A_inf, "A66_zero": self.A_zero,
                "A66_swing": self.A_swing, "B66_inf_N_m_s": self.B_inf, "strictly_proper": self.strict,
                "passive": self.passive, "rss": self.rss}


def _quantities(sections, coef, swing_omega, strict: bool = False) -> np.ndarray:
    """Linear maps from the coefficients (the memory's free ones first) to (A_inf, A_zero, A_swing)."""
    m = len(coef)
    T = _kernel_map(sections, strict)
    g0 = np.real(_basis(sections, 0.0)) @ T if sections else np.zeros(0)
    gs = np.real(_basis(sections, 1j * swing_omega)) @ T if sections else np.zeros(0)
    n_mem = len(g0)
    rows = np.zeros((3, m))
    rows[:, n_mem] = 1.0  # A_inf
    rows[1, :n_mem] = g0
    rows[2, :n_mem] = gs
    return rows


def fit_family(data: MemoryData, name: str, kinds: tuple[str, ...], swing_omega: float,
               strict: bool | None = None, start: np.ndarray | None = None, fixed: bool = False) -> FamilyFit:
    """The best fit of one family (pole positions searched from a few starts, or from ``start``: the
    poles of the same family with an instantaneous part). ``strict`` (default: the name ends in
    :data:`STRICT_SUFFIX`): the kernel without an instantaneous part (:func:`_kernel_map`). ``fixed``: the
    poles stay at ``start`` (packed as :func:`pack_sections` does; a prior's poles), only the coefficients fitted."""
    from scipy.optimize import least_squares  # noqa: PLC0415

    strict = name.endswith(STRICT_SUFFIX) if strict is None else strict
    if strict and len(kinds) == 1 and kinds[0] == "r":
        raise MemoryNotIdentifiable(f"family {name}: one real pole without an instantaneous part has no memory left")
    lb, ub = _bounds(kinds)
    best = None
    starts = [np.clip(start, lb, ub)] if start is not None else _starts(kinds)
    if fixed:
        from types import SimpleNamespace  # noqa: PLC0415

        best, starts = SimpleNamespace(x=np.asarray(start, float), jac=None), []
    for x0 in starts:
        try:
            r = least_squares(lambda x: data.projected_residual(_unpack(kinds, x), strict), x0, bounds=(lb, ub),
                              **POLE_SEARCH)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best is None or r.cost < best.cost:
            best = r
    if best is None:
        raise MemoryNotIdentifiable(f"family {name}: no fit converged")
    sections = _unpack(kinds, best.x)
    coef, resid, X = data.solve(sections, strict)
    V = data.clustered_covariance(X, resid)
    rows = _quantities(sections, coef, swing_omega, strict)
    values = rows @ coef
    var = np.einsum("ij,jk,ik->i", rows, V, rows)
    # A66(inf) is carried by the first instants after each start from rest, so its independent pieces of evidence
    # are the stretches of free motion, not the windows: its variance is clustered by stretch (and its interval
    # takes Student's t with one fewer degree of freedom than there are stretches, identify_memory)
    seg = data.segment_of_row
    var_inf = float(rows[0] @ data.clustered_covariance(X, resid, seg) @ rows[0])
    # the pole positions' share: the quantities' change along the poles' own covariance
    pole_sigma = None
    try:
        J = best.jac
        if J is None:
            raise ValueError("fixed poles: no share of their positions")
        Vx = _clustered_pole_covariance(data, J, resid)
        pole_sigma = np.sqrt(np.maximum(np.diag(Vx), 0.0))
        grads = []
        for j in range(len(best.x)):
            h = 1e-4
            xp = best.x.copy()
            xp[j] += h
            sp = _unpack(kinds, xp)
            cp, _, _ = data.solve(sp, strict)
            grads.append((_quantities(sp, cp, swing_omega, strict) @ cp - values) / h)
        G = np.array(grads).T  # 3 x n_x
        var = var + np.einsum("ij,jk,ik->i", G, Vx, G)
        var_inf += float(G[0] @ _clustered_pole_covariance(data, J, resid, seg) @ G[0])
    except (np.linalg.LinAlgError, ValueError):
        pass
    n_mem = rows.shape[1] - data.X.shape[1]
    T = _kernel_map(sections, strict)
    theta = T @ coef[:n_mem]
    ReK = np.real(1j * OMEGA_GRID * (_basis(sections, 1j * OMEGA_GRID) @ theta))
    scale = max(float(np.max(np.abs(ReK))), 1e-12)
    passive = bool(np.min(ReK) >= -PASSIVITY_TOLERANCE * scale and values[1] > values[0] and values[0] > 0.0)
    sig = np.sqrt(np.maximum(var, 0.0))
    sig_window = float(sig[0])
    sig[0] = max(sig[0], math.sqrt(max(var_inf, 0.0)))  # the wider of the two clusterings
    return FamilyFit(name, sections, float(resid @ resid), float(values[0]), float(values[1]), float(values[2]),
                     {"A66_inf": float(sig[0]), "A66_zero": float(sig[1]), "A66_swing": float(sig[2]),
                      "A66_inf_by_window": sig_window},
                     passive, float(np.min(ReK)), theta, float(coef[n_mem + 1]), float(coef[n_mem + 2]),
                     T @ V[:n_mem, :n_mem] @ T.T, strict, best.x.copy(), pole_sigma)


def jackknife_refits(data: MemoryData, fit: FamilyFit, swing_omega: float = 1.0) -> dict[int, np.ndarray]:
    """``fit``'s family refitted without each stretch of free motion in turn (its poles searched again from its
    own): ``{stretch: (A66(inf), A66(0), A66 at swing_omega)}`` for every stretch whose refit converged (none with
    fewer than 3 stretches)."""
    from scipy.optimize import least_squares  # noqa: PLC0415

    g = data.n_segments
    if g < 3 or fit.x is None:
        return {}
    kinds = tuple(sec[0] for sec in fit.sections)
    lb, ub = _bounds(kinds)
    out = {}
    for k in range(g):
        sub_data = data.without_segment(k)
        if sub_data.n_windows < 2:
            continue
        try:
            r = least_squares(lambda x: sub_data.projected_residual(_unpack(kinds, x), fit.strict),
                              np.clip(fit.x, lb, ub), bounds=(lb, ub), **POLE_SEARCH)
            sections = _unpack(kinds, r.x)
            coef, _, _ = sub_data.solve(sections, fit.strict)
        except (ValueError, np.linalg.LinAlgError):
            continue
        out[k] = _quantities(sections, coef, swing_omega, fit.strict) @ coef
    return out


def jackknife_a_inf(data: MemoryData, fit: FamilyFit, refits: dict[int, np.ndarray] | None = None) -> float:
    """The jackknife standard deviation of ``fit``'s A66(inf) over the stretches of free motion (each left out in
    turn, the family's poles searched again from its own): A66(inf) is carried by the instants after each start from
    rest, and a bias the noise leaves in the pole positions moves with the stretches; nan with fewer than 3.
    ``refits``: :func:`jackknife_refits`' (computed when not given)."""
    refits = jackknife_refits(data, fit) if refits is None else refits
    if len(refits) < 3:
        return math.nan
    v = np.array([q[0] for q in refits.values()])  # A66(inf)
    return float(math.sqrt((len(v) - 1) / len(v) * np.sum((v - v.mean()) ** 2)))


def jackknife_a_zero(data: MemoryData, refits: dict[int, np.ndarray]) -> tuple[float, int]:
    """The stratified jackknife standard deviation of A66(0) over the stretches of free motion and its degrees of
    freedom (:func:`~addedinertia_env.identify.cluster_jackknife.stratified_jackknife`): each stretch's stratum is
    its kind (:meth:`MemoryData.stretch_kinds`), since only stretches of one kind are repeats of one measurement;
    ``(nan, 0)`` where no kind has two stretches refitted."""
    from addedinertia_env.identify.cluster_jackknife import stratified_jackknife  # noqa: PLC0415

    kinds = data.stretch_kinds()
    ks = sorted(refits)
    if len(ks) < 2:
        return math.nan, 0
    return stratified_jackknife([float(refits[k][1]) for k in ks], [kinds[k] for k in ks])


def _refit_rss(data: MemoryData, fit: FamilyFit) -> float:
    """The residual of ``fit``'s family on ``data`` (other rows or columns), its poles searched from ``fit``'s."""
    from scipy.optimize import least_squares  # noqa: PLC0415

    kinds = tuple(sec[0] for sec in fit.sections)
    _, x0 = pack_sections(fit.sections)
    lb, ub = _bounds(kinds)
    try:
        r = least_squares(lambda x: data.projected_residual(_unpack(kinds, x), fit.strict), np.clip(x0, lb, ub),
                          bounds=(lb, ub), **POLE_SEARCH)
    except (ValueError, np.linalg.LinAlgError):
        res = data.projected_residual(fit.sections, fit.strict)
        return float(res @ res)
    return float(2.0 * r.cost)


def pack_sections(sections: list[tuple]) -> tuple[tuple[str, ...], np.ndarray]:
    """The kinds and packed pole parameters of ``sections`` (the inverse of :func:`_unpack`)."""
    kinds, x = [], []
    for sec in sections:
        kinds.append(sec[0])
        if sec[0] == "r":
            x.append(math.log(sec[1]))
        else:
            z = min(max(sec[2], 1e-6), 1.0 - 1e-6)
            x += [math.log(sec[1]), math.log(z / (1.0 - z))]
    return tuple(kinds), np.array(x)


def _bounds(kinds: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of the packed pole parameters: log magnitudes within :data:`POLE_RANGE`, damping logits within +-6."""
    lo, hi = (math.log(v) for v in POLE_RANGE)
    lb, ub = [], []
    for k in kinds:
        lb.append(lo)
        ub.append(hi)
        if k == "c":
            lb.append(-6.0)
            ub.append(6.0)
    return np.array(lb), np.array(ub)


def _clustered_pole_covariance(data: MemoryData, J: np.ndarray, resid: np.ndarray,
                               clusters: np.ndarray | None = None) -> np.ndarray:
    """Covariance of the packed pole parameters, clustered by window like the coefficients'
    (:meth:`MemoryData.clustered_covariance`): ``J`` is the Jacobian of the projected residual (rows x
    pole parameters) at the fit, whose residual is ``resid``. The integral form's rows within a window
    are strongly correlated (each is a double integral over the same samples), so a variance from
    ``s^2 (J'J)^-1`` would count every 20 ms row as new information and make the poles, and with them
    A66(inf), look several times surer than the records allow."""
    return _cluster_sandwich(J, resid, data.window_of_row if clusters is None else clusters)


def _cluster_sandwich(X: np.ndarray, resid: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """The cluster-robust (sandwich) covariance of a least-squares fit with regressors ``X`` (rows x
    parameters) and residual ``resid``, rows grouped by the integer ``clusters`` (0..g-1), with the
    small-sample factor g / (g - 1): ``B M B`` with ``B = pinv(X'X)`` and ``M`` the summed outer
    products of each cluster's score."""
    bread = np.linalg.pinv(X.T @ X)
    g = int(clusters.max()) + 1
    scores = np.zeros((g, X.shape[1]))
    np.add.at(scores, clusters, X * resid[:, None])
    meat = scores.T @ scores * (g / max(g - 1, 1))
    return bread @ meat @ bread


# --- the hull's memory -------------------------------------------------------------------
@dataclass(frozen=True)
class PriorKernel:
    """Poles of a memory kernel from outside the records (a BEM solve), for :func:`identify_memory`."""

    name: str  # "bem"
    sections: tuple  # ('r', a) / ('c', wn, z), rad/s
    strict: bool  # without an instantaneous part (a potential-flow kernel)
    source: str  # where it came from (the cache's path)


@dataclass
class MemoryIdentification:
    """What the records say about the water's memory (kg m^2, rad/s)."""

    status: str  # "identified", "none" (memory-free water) or "not identifiable: ..."
    swing_omega: float
    A_zero: float = math.nan
    A_inf: float = math.nan
    A_swing: float = math.nan
    ci95: dict[str, tuple[float, float]] = field(default_factory=dict)
    best: FamilyFit | None = None
    accepted: list[FamilyFit] = field(default_factory=list)
    fits: list[FamilyFit] = field(default_factory=list)
    rss_none: float = math.nan
    free_s: float = 0.0
    prior: str = "none"
    prior_note: str = ""  # with a prior: its source and whether the records accepted it
    rss_stiffening: float = math.nan  # memory-free with a stiffening rod (STIFFENING_POWERS), where memory was in question
    rss_memory_and_stiffening: float = math.nan  # the best memory model with the stiffening rod too
    weights: dict[str, float] = field(default_factory=dict)  # Akaike weight of each family in ``accepted``
    n_stretches: int = 0  # stretches of free motion (starts from rest, mostly) the equation's rows come from
    n_windows: int = 0  # the equation's windows: the independent pieces of evidence the weights count

    @property
    def identified(self) -> bool:
        """Whether a passive memory model was identified (status ``identified``)."""
        return self.status == "identified"

    def to_json(self) -> dict[str, Any]:
        """The identification for ``identify --json``: ``memory`` (the family, ``none`` or ``not identifiable:
        ...``) and, when identified, ``A66_swing``, ``A66_inf``, ``A66_zero_memory_fit`` (kg m^2) with their ci95."""
        out: dict[str, Any] = {"memory": self.status if self.status != "identified" else self.best.family}
        if self.identified:
            out["A66_swing"] = self.A_swing
            out["A66_swing_ci95"] = list(self.ci95["A66_swing"])
            out["A66_inf"] = self.A_inf
            out["A66_inf_ci95"] = list(self.ci95["A66_inf"])
            out["A66_zero_memory_fit"] = self.A_zero
            out["A66_zero_memory_fit_ci95"] = list(self.ci95["A66_zero"])
            out["memory_model"] = {
                "kind": "passive state-space radiation kernel K(s) = s sum theta_i G_i(s) (identify/memory.py)",
                "family": self.best.family, "swing_omega_rad_s": self.swing_omega,
                "families_kept": [f.family for f in self.accepted],
                "family_weights": {f.family: self.weights.get(f.family, math.nan) for f in self.accepted},
                "stretches_of_free_motion": self.n_stretches, "windows": self.n_windows,
                "fits": [f.summary() for f in self.fits], "rss_memory_free": self.rss_none,
                "prior": self.prior, "free_motion_s": self.free_s, **self._stiffening_json()}
            if "A66_zero_jackknife" in self.best.sigma:  # a check beside the interval, not in it (docs/INTERVALS.md)
                out["memory_model"]["A66_zero_jackknife_sd"] = self.best.sigma["A66_zero_jackknife"]
                out["memory_model"]["A66_zero_jackknife_dof"] = int(self.best.sigma["A66_zero_jackknife_dof"])
            if self.prior_note:
                out["memory_model"]["prior_note"] = self.prior_note
        else:
            out["memory_model"] = {"swing_omega_rad_s": self.swing_omega, "rss_memory_free": self.rss_none,
                                   "fits": [f.summary() for f in self.fits], "prior": self.prior,
                                   "free_motion_s": self.free_s, **self._stiffening_json()}
        return out

    def _stiffening_json(self) -> dict[str, Any]:
        if math.isnan(self.rss_stiffening):
            return {}
        return {"rss_stiffening_rod": self.rss_stiffening, "rss_memory_and_stiffening_rod": self.rss_memory_and_stiffening}


def swing_frequency(data: MemoryData) -> float:
    """The hull's swing frequency (rad/s) from the neutral crossings of its free motion."""
    halves = []
    for s in data.series:
        x = s.phi - s.phi_n
        for a, b in _free_segments(s.free):
            seg = x[a:b]
            k = np.nonzero((seg[:-1] < 0) != (seg[1:] < 0))[0]
            k = k[seg[k + 1] != seg[k]]
            if len(k) < 2:
                continue
            tc = s.t[a + k] - seg[k] * s.dt / (seg[k + 1] - seg[k])
            halves += list(np.diff(tc))
    if not halves:
        J = np.mean([s.J_h + s.J_f for s in data.series])
        return float(math.sqrt(np.mean([s.c for s in data.series]) / (2.0 * J)))
    return float(math.pi / np.median(halves))


def identify_memory(records: list[RunRecord], families: dict[str, tuple[str, ...]] | None = None,
                    prior: PriorKernel | None = None) -> MemoryIdentification:
    """The water's memory from a hull's records (free decays and reverse runs together). ``prior``: a
    kernel's poles from elsewhere (the BEM cache, ``identify --prior bem``): fitted as one more family with
    its poles fixed, and reported, with its own interval, where the records accept it (passive, within
    :data:`FAMILY_RSS_TOLERANCE` of the best residual); else the records alone, and the JSON says why."""
    families = FAMILIES if families is None else families
    try:
        data = MemoryData(records)
    except MemoryNotIdentifiable as e:
        return MemoryIdentification(f"not identifiable: {e}", math.nan)
    w_s = swing_frequency(data)
    if data.free_s < MIN_FREE_S:
        return MemoryIdentification(f"not identifiable: {data.free_s:.2f} s of unbraked motion; expected at least "
                                    f"{MIN_FREE_S:.0f} s (a free decay or reverse runs)", w_s, free_s=data.free_s)
    if data.releases < MIN_RELEASES:
        return MemoryIdentification("not identifiable: no start from rest (release or brake letting go) in the "
                                    "records; expected the transient that shows A66(inf)", w_s, free_s=data.free_s)
    rss_none = float(data.Yp @ data.Yp)
    fits = []
    plain = {n: k for n, k in families.items() if not n.endswith(STRICT_SUFFIX)}
    for name, kinds in plain.items():
        if len(kinds) > 1 and fits and min(f.rss for f in fits) >= MEMORY_RSS_RATIO * rss_none:
            break  # the one-section models explain nothing the memory-free one leaves: no memory (fast path)
        try:
            fits.append(fit_family(data, name, kinds, w_s))
        except MemoryNotIdentifiable:
            continue
    # Each family without its instantaneous part, started from its own poles; only where it could be kept: its
    # residual is at least the family's own, so a family already beyond the tolerance of the best passive one is
    # skipped (as are all when no one-section model explained anything: the fast path above).
    done = {f.family: f for f in fits}
    best_plain = min((f.rss for f in fits if f.passive), default=math.inf)
    if not fits or min(f.rss for f in fits) >= MEMORY_RSS_RATIO * rss_none:
        best_plain = -math.inf  # no memory in the records: no variant can show one
    for name, kinds in families.items():
        own = done.get(name[:-len(STRICT_SUFFIX)]) if name.endswith(STRICT_SUFFIX) else None
        if name in done or own is None or own.rss > FAMILY_RSS_TOLERANCE * best_plain:
            continue
        try:
            fits.append(fit_family(data, name, kinds, w_s, start=own.x))
        except MemoryNotIdentifiable:
            continue
    prior_fit = None
    if prior is not None and best_plain > -math.inf:
        kinds, x = pack_sections(list(prior.sections))
        try:
            prior_fit = fit_family(data, prior.name, kinds, w_s, strict=prior.strict, start=x, fixed=True)
            fits.append(prior_fit)
        except MemoryNotIdentifiable:
            prior_fit = None
    passive = [f for f in fits if f.passive]
    base = MemoryIdentification("none", w_s, fits=fits, rss_none=rss_none, free_s=data.free_s,
                                prior="none" if prior is None else prior.name,
                                prior_note="" if prior is None else f"{prior.source}: not used (no memory in the records)")
    if fits and min(f.rss for f in fits) < MEMORY_RSS_RATIO * rss_none:
        # memory is linear; a stiffening rod is amplitude-dependent and may look like memory in one run
        rival = min(passive or fits, key=lambda f: f.rss)
        rod = data.with_columns(data.S)
        base.rss_stiffening = float(rod.Yp @ rod.Yp)
        base.rss_memory_and_stiffening = _refit_rss(rod, rival)
        if base.rss_memory_and_stiffening >= MEMORY_RSS_RATIO * base.rss_stiffening:
            return base  # a nonlinear rod explains the records as well: no memory
    if not passive:
        if fits and min(f.rss for f in fits) < MEMORY_RSS_RATIO * rss_none:
            base.status = ("not identifiable: the records show memory but no passive low-order model fits "
                           f"({', '.join(f.family for f in fits)} tried)")
        return base
    best = min(passive, key=lambda f: f.rss)
    if best.rss >= MEMORY_RSS_RATIO * rss_none:
        return base  # the memory-free model explains the records about as well: no memory
    best_any = min(fits, key=lambda f: f.rss)
    if best.rss > PASSIVE_GAP * best_any.rss:
        base.status = (f"not identifiable: the best passive model ({best.family}) leaves {best.rss / best_any.rss:.1f} "
                       f"times the residual of a non-passive one ({best_any.family}); the records do not pin the "
                       "memory down (expected longer free motion: a free decay beside the reverse runs)")
        return base
    within = [f for f in passive if f.rss <= FAMILY_RSS_TOLERANCE * best.rss]
    # the one reported: the simplest of those that fit (fewest pole parameters and free coefficients, then the
    # smaller residual): a kernel without an instantaneous part where the records do not need one
    best = min(within, key=lambda f: (f.n_params, f.rss))
    # the interval: every passive family, by its Akaike weight (the windows are the independent evidence)
    weights = akaike_weights([f.rss for f in passive], [f.n_params for f in passive], data.n_windows)
    accepted = [f for f, w in zip(passive, weights) if w >= MIN_FAMILY_WEIGHT or f is best]
    weight = {f.family: float(w) for f, w in zip(passive, weights) if any(f is g for g in accepted)}
    note = ""
    if prior is not None:
        if prior_fit is not None and any(f is prior_fit for f in within):
            best, accepted = prior_fit, [prior_fit]  # the prior's shape, which the records accept, pins the family
            weight = {prior_fit.family: 1.0}
            note = (f"{prior.source}: its poles kept (residual {prior_fit.rss / min(f.rss for f in passive):.2f} "
                    "x the best passive family's); coefficients and A66 from the records")
        else:
            why = ("not passive with these records" if prior_fit is not None and not prior_fit.passive else
                   f"residual {prior_fit.rss / min(f.rss for f in passive):.2f} x the best passive family's, over "
                   f"{FAMILY_RSS_TOLERANCE}" if prior_fit is not None else "could not be fitted")
            note = f"{prior.source}: rejected by the records ({why}); the records alone"
    ci = family_intervals(best, accepted, weight, data.n_segments)
    # A66(inf) also within the reported family's jackknife over the starts from rest (t with g - 1 dof), on the
    # log scale as the families' mixture
    refits = jackknife_refits(data, best, w_s)
    jack = jackknife_a_inf(data, best, refits)
    # A66(0)'s stratified jackknife over the stretches of one kind: reported beside the interval, not in it. It
    # and the mixture's window-clustered covariance estimate the same sampling error; the union of the two was
    # biased wide by construction (a t(2) jackknife's calibrated median |z| is 0.37) and covered no run the
    # mixture missed (docs/INTERVALS.md, "Why about 1.4x per run"), so the estimate with more degrees of
    # freedom (20-30 windows against 2) sets the width
    jack0, dof0 = jackknife_a_zero(data, refits)
    if math.isfinite(jack0) and dof0 >= 1:
        best.sigma["A66_zero_jackknife"] = jack0
        best.sigma["A66_zero_jackknife_dof"] = float(dof0)
    res = RESOLUTION * abs(best.A_zero - best.A_inf)  # the fit's own resolution (noise-free records)
    lo, hi = ci["A66_zero"]
    ci["A66_zero"] = (min(lo, best.A_zero - res), max(hi, best.A_zero + res))
    if math.isfinite(jack):
        half = _t95(data.n_segments) * jack / best.A_inf
        lo, hi = ci["A66_inf"]
        ci["A66_inf"] = (min(lo, best.A_inf * math.exp(-half)), max(hi, best.A_inf * math.exp(half)))
        best.sigma["A66_inf_jackknife"] = jack
    return MemoryIdentification("identified", w_s, best.A_zero, best.A_inf, best.A_swing, ci, best, accepted, fits,
                                rss_none, data.free_s, "none" if prior is None else prior.name, note,
                                base.rss_stiffening, base.rss_memory_and_stiffening, weight, data.n_segments,
                                data.n_windows)


def family_intervals(best: FamilyFit, families: list[FamilyFit], weight: dict[str, float],
                     n_stretches: int) -> dict[str, tuple[float, float]]:
    """The 95 % intervals of A66(0), A66 at the swing and A66(inf) (kg m^2): the central 95 % of the mixture of
    ``families``' estimates, each normal with its own standard error and weighted by ``weight`` (Akaike,
    :mod:`~addedinertia_env.identify.model_average`), widened where needed to hold ``best``'s value (the one
    reported). A66(inf) on the log scale (a positive quantity; its interval never reaches zero), its standard
    errors scaled to Student's t with ``n_stretches - 1`` degrees of freedom (its variance is clustered by
    stretch of free motion)."""
    t = _t95(n_stretches) / Z95
    ci = {}
    for key in ("A66_zero", "A66_swing", "A66_inf"):
        if key == "A66_inf":  # passive families have A66(inf) > 0
            x = np.log([f.A_inf for f in families])
            s = np.array([t * f.sigma[key] / f.A_inf for f in families])
        else:
            x = np.array([getattr(f, _attr(key)) for f in families])
            s = np.array([f.sigma[key] for f in families])
        w = np.array([weight[f.family] for f in families])
        ok = np.isfinite(x) & np.isfinite(s) & (w > 0)  # a family whose covariance failed has no interval to give
        v = getattr(best, _attr(key))
        if not ok.any():
            ci[key] = (math.nan, math.nan)
            continue
        lo, hi = mixture_interval(x[ok], s[ok], w[ok])
        if key == "A66_inf":
            lo, hi = math.exp(lo), math.exp(hi)
        ci[key] = (float(min(lo, v)), float(max(hi, v)))
    return ci


def _t95(n_clusters: int) -> float:
    """The two-sided 95 % point for a variance clustered over ``n_clusters`` stretches of free motion: Student's t
    with ``n_clusters - 1`` degrees of freedom (a few starts from rest carry A66(inf)), the normal's past 30."""
    from addedinertia_env.identify.cluster_jackknife import t95  # noqa: PLC0415

    return Z95 if n_clusters > 30 else t95(max(n_clusters - 1, 1))


def _attr(key: str) -> str:
    return {"A66_inf": "A_inf", "A66_zero": "A_zero", "A66_swing": "A_swing"}[key]
