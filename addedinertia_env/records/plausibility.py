"""Is a run record physically possible for its own rig? Checked after reading, before any method.

The reader (:mod:`addedinertia_env.records.record`) checks the *form* of a record: columns,
numbers, increasing ``t``, known phases. This module checks that the samples are
something the rig described in the record's own ``rig`` block could have produced, so
that a current logged in mA, a voltage in mV, a spike of 1e6 A or an angle of 1e15 rad
is refused instead of turning into a confident, wrong lambda66. Every limit is derived
from the ``rig`` block and the record's other channels (general physics of a DC motor
on a torsion rod), never from a list of known bad cases:

* **current** ``|i|``: at most :data:`LIMIT_MARGIN` x ``i_max`` when the rig states it
  (the board's own overcurrent trip is at 1.25 ``i_max``), and never more than the
  largest terminal voltage and back-EMF in the record can drive through the winding,
  ``MARGIN x (max|u| + k_t max|Omega|) / R`` (the current through an inductance
  cannot overshoot what its voltage drives; ``L`` is not needed);
* **voltage** ``|u|``: at most :data:`LIMIT_MARGIN` x the larger of ``u_max`` and the
  back-EMF the flywheel's own speed makes (an open-circuit motor shows its back-EMF);
  without ``u_max``, what ``R i_max`` and the back-EMF allow when ``i_max`` is known;
* **angles**: ``phi`` within 2 pi (the reader); ``psi`` (unwrapped, any number of turns)
  small enough that a float64 still resolves a tenth of an encoder count;
* **rates** (sample-to-sample steps, so jittered or gapped ``t`` is fine): the hull
  cannot move faster than the spring's energy at the record's largest twist plus the
  motor's reaction work allow, ``w_max = sqrt((c A^2 + 4 k_t I A) / J_hull)``; the
  flywheel cannot spin faster than the supply drives it, ``(U + R I) / k_t``, plus the
  hull's own rate. Each step may exceed ``MARGIN x rate x dt`` by the encoder's
  quantisation and the channel's own noise (from the median of its second differences);
  the hull rate is not checked in ``idle`` (an operator may twist the rod by hand);
* **phases** appear in the order the spec gives for the experiment's kind, each as one
  block (``idle``, ``free``, optional ``hold``, ``reverse``, optional ``idle`` for a
  reverse-symmetric run; ``idle``, ``free``, optional ``idle`` for a free decay).

A refusal is a :class:`~addedinertia_env.records.record.RecordError` naming the file, the
column, the line of the CSV, the value and the limit (with how it was derived).
Records the reader accepts for their form (``L`` of 0 or absent, columns in any order,
CRLF, non-uniform ``t``, gaps) are not refused here for that form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from addedinertia_env.records.record_error import RecordError
from addedinertia_env.records.scan_kernels import (
    abs_max,
    abs_rates,
    first_beyond,
    first_step_beyond,
    median_abs_deviation_sorted,
    second_differences,
)
from addedinertia_env.records.series_stats import median, quantile, sorted_median

MARGIN = 1.5  # how far a measured value may exceed a limit derived from physics (sensor gain, noise)
LIMIT_MARGIN = 2.0  # how far |i| or |u| may exceed the rig's stated i_max / u_max
PSI_RESOLUTION_FRACTION = 0.1  # float64 spacing of |psi| must stay below this fraction of a count
NOISE_SIGMAS = 8.0  # a step may exceed the rate limit by this many noise sigmas of its channel
QUANT_STEPS = 4.0  # ... and by this many encoder counts (quantisation on both ends, jitter)
# Order of phase blocks per experiment kind (spec/run-record.md); None: not constrained.
PHASE_ORDER = {
    "reverse-symmetric": ("idle", "free", "hold", "reverse", "idle"),
    "free-decay": ("idle", "free", "idle"),
    "forced-oscillation": None,
}


class _Record(Protocol):
    """What the check reads of a :class:`~addedinertia_env.records.run_record.RunRecord` (which imports this
    module: its views run the check)."""

    name: str
    phase: np.ndarray
    experiment: dict[str, Any]
    views: Any  # RecordViews: the typed rig block and the phase blocks

    def __getitem__(self, column: str) -> np.ndarray: ...


@dataclass(frozen=True)
class Limits:
    """Limits of one record, SI units; ``why_*`` say how each was derived (for messages). A record
    keeps them in its views (``record.views.limits``), beside the typed ``rig`` block and the phase
    blocks the check read from there."""

    i_max: float
    why_i: str
    u_max: float
    why_u: str
    hull_rate: float
    flywheel_rate: float
    psi_abs: float


def check_plausible(rec: _Record) -> Limits:
    """Refuse a record its own rig could not have produced (:class:`RecordError`); returns the limits used.
    ``record.views.limits`` runs it once per record and keeps the result."""
    name = rec.name
    try:
        known = rec.views.known
    except ValueError as e:  # KnownRigError: the rig block itself is unusable
        raise RecordError(f"{name}: rig block: {e}") from None
    blocks = rec.views.phase_blocks
    starts, labels = blocks.starts.tolist(), list(blocks.labels)
    _check_phase_order(rec, starts, labels)
    t, phi, psi, u, i = (np.asarray(rec[c], dtype=float) for c in ("t", "phi", "psi", "u", "i"))
    k_t, R, c, J_h, phi_n = known.k_t, known.R, known.c_torsion, known.J_hull, known.phi_neutral
    i_max_rig, u_max_rig = _positive_or_none(known.i_max), _positive_or_none(known.u_max)
    q_phi, q_psi = _count_step(known.phi_counts), _count_step(known.psi_counts)

    # Angles first: a psi of 1e15 rad would make every rate below meaningless.
    psi_abs = max(q_psi if q_psi > 0 else 2 * math.pi / 2**24, 1e-9) * PSI_RESOLUTION_FRACTION / np.finfo(float).eps
    _refuse_above(name, "psi", psi, psi_abs,
                  f"{psi_abs:.3g} rad (beyond it a float64 cannot resolve a tenth of an encoder count; "
                  "radians, not counts?)")

    dt = t[1:] - t[:-1]
    # Flywheel rate, robustly: a single bad sample must not raise the limits it is tested by.
    omega = _robust_max_rate(t, psi, dt)
    hull_amp = float(_abs_max(phi, phi_n))

    # Voltage.
    if u_max_rig is not None:
        u_lim = LIMIT_MARGIN * max(u_max_rig, k_t * omega)
        why_u = f"{LIMIT_MARGIN:g} x max(rig.u_max {u_max_rig:g} V, back-EMF k_t |Omega| {k_t * omega:.3g} V)"
    elif i_max_rig is not None:
        u_lim = LIMIT_MARGIN * (R * i_max_rig + k_t * omega)
        why_u = (f"{LIMIT_MARGIN:g} x (R i_max {R * i_max_rig:.3g} V + back-EMF {k_t * omega:.3g} V; "
                 "no rig.u_max given)")
    else:
        u_lim, why_u = math.inf, "no rig.u_max or rig.i_max given"
    _refuse_above(name, "u", u, u_lim, f"{u_lim:.4g} V = {why_u}")

    # Current: the rig's limit, and what the record's own voltages can drive.
    u_seen = float(_abs_max(u, 0.0))
    i_ohm = MARGIN * (u_seen + k_t * omega) / R + _noise(i)
    i_lim, why_i = i_ohm, (f"{MARGIN:g} x (max|u| {u_seen:.3g} V + k_t |Omega| {k_t * omega:.3g} V) / R {R:g} ohm "
                           "+ the channel's noise: the most the terminal voltage can drive")
    if i_max_rig is not None and LIMIT_MARGIN * i_max_rig < i_lim:
        i_lim, why_i = LIMIT_MARGIN * i_max_rig, f"{LIMIT_MARGIN:g} x rig.i_max {i_max_rig:g} A"
    _refuse_above(name, "i", i, i_lim, f"{i_lim:.4g} A = {why_i}")

    # Rates: step by step, so non-uniform t and gaps are fine.
    i_top = i_max_rig if i_max_rig is not None else float(_abs_max(i, 0.0))
    u_top = u_max_rig if u_max_rig is not None else u_seen
    hull_rate = math.sqrt((c * hull_amp**2 + 4.0 * k_t * i_top * hull_amp) / J_h)
    fly_rate = (u_top + R * i_top) / k_t + hull_rate
    phase = rec.phase  # an operator may twist the rod by hand while idle (a phase column not an array: as compared)
    moving = _not_idle_steps(len(phase), starts, labels) if isinstance(phase, np.ndarray) else phase[1:] != "idle"
    _refuse_steps(name, "phi", phi, dt, MARGIN * hull_rate, q_phi, mask=moving,
                  why=f"hull rate {MARGIN:g} x sqrt((c A^2 + 4 k_t i_max A) / J_hull) = {MARGIN * hull_rate:.3g} "
                      f"rad/s with A = {hull_amp:.3g} rad (spring energy + motor work)")
    _refuse_steps(name, "psi", psi, dt, MARGIN * fly_rate, q_psi, mask=None,
                  why=f"flywheel rate {MARGIN:g} x ((u_max + R i_max) / k_t + hull rate) = {MARGIN * fly_rate:.3g} rad/s")
    return Limits(i_lim, why_i, u_lim, why_u, hull_rate, fly_rate, psi_abs)


# --- helpers ---------------------------------------------------------------------------

def _positive_or_none(v) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        return None
    return float(v)


def _count_step(counts) -> float:
    """Encoder step, rad (0 when unknown or exact)."""
    if isinstance(counts, bool) or not isinstance(counts, (int, float)) or not math.isfinite(counts) or counts <= 0:
        return 0.0
    return 2 * math.pi / float(counts)


def _noise(x: np.ndarray) -> float:
    """Robust sigma of a channel's sample-to-sample noise (second differences; one spike does not count):
    ``1.4826 median(|d2 - median(d2)|) / sqrt(6)``, ``d2 = np.diff(x, 2)``, with one sort."""
    if x.size < 3:
        return 0.0
    s = np.sort(second_differences(x) if _series(x) else np.diff(x, 2))
    m = sorted_median(s)
    if math.isfinite(m):  # else nan or inf: the elementwise form (nan either way)
        mad = float(median_abs_deviation_sorted(s, m))
    else:
        mad = median(np.abs(s - m))
    return float(1.4826 * mad / math.sqrt(6.0))


def _abs_max(x: np.ndarray, center: float) -> float:
    """``np.max(np.abs(x - center))`` (numpy's error for no samples)."""
    return abs_max(x, center) if _series(x) and len(x) else np.max(np.abs(x - center))


def _series(x: np.ndarray, steps: np.ndarray | None = None, mask: np.ndarray | None = None) -> bool:
    """Whether the compiled scans apply: ``x`` a 1-D float64 array, ``steps`` and ``mask`` (when given)
    1-D with one element per step of ``x`` (otherwise the numpy expressions run, with numpy's own
    broadcasting and errors)."""
    ok = x.ndim == 1 and x.dtype == np.float64
    for other in (steps, mask):
        ok = ok and (other is None or (isinstance(other, np.ndarray) and other.ndim == 1 and len(other) == len(x) - 1))
    return ok


def _robust_max_rate(t: np.ndarray, x: np.ndarray, dt: np.ndarray | None = None) -> float:
    """A high quantile of ``|dx/dt|`` that a few bad samples cannot raise (rad/s); ``dt``: ``np.diff(t)``
    when already computed."""
    if x.size < 2:
        return 0.0
    dt = np.diff(t) if dt is None else dt
    rate = abs_rates(x, dt) if _series(x, dt) else np.abs(np.diff(x) / dt)
    return quantile(rate, 0.99) if rate.size >= 100 else median(rate)


def _line(k: int) -> int:
    """CSV line of sample ``k`` (line 1 is the header)."""
    return int(k) + 2


def _refuse_above(name: str, column: str, values: np.ndarray, limit: float, why: str) -> None:
    if _series(values):
        k = first_beyond(values, limit)
    else:
        bad = np.abs(values) > limit
        k = int(np.argmax(bad)) if bad.any() else -1
    if k >= 0:
        raise RecordError(f"{name}: line {_line(k)}, column '{column}': {float(values[k])!r} is beyond what the rig allows, "
                          f"|{column}| <= {why}; wrong units or a bad sample?")


_NO_MASK = np.zeros(0, dtype=bool)


def _refuse_steps(name: str, column: str, x, dt, rate: float, q: float, mask, why: str) -> None:
    """Refuse the first step ``|x[k+1] - x[k]|`` beyond ``rate dt[k]`` plus quantisation and noise where
    ``mask[k]`` (every step when ``mask`` is None)."""
    if x.size < 2:
        return
    quant, noise = QUANT_STEPS * q, NOISE_SIGMAS * _noise(x)
    if _series(x, dt, mask) and dt.dtype == np.float64:
        k = first_step_beyond(x, dt, rate, quant, noise, _NO_MASK if mask is None else mask)
    else:
        bad = np.abs(np.diff(x)) > rate * dt + quant + noise
        if mask is not None:
            bad &= mask
        k = int(np.argmax(bad)) if bad.any() else -1
    if k >= 0:
        step, tol = abs(x[k + 1] - x[k]), rate * dt[k] + quant + noise  # the numbers the scan compared
        raise RecordError(f"{name}: line {_line(k + 1)}, column '{column}': {float(x[k + 1])!r} after {float(x[k])!r} "
                          f"({dt[k]:.3g} s earlier) is a step of {step:.4g} rad; expected at most {tol:.4g} rad "
                          f"from the {why} plus encoder quantisation and noise")


def _not_idle_steps(n: int, starts: list[int], labels: list[str]) -> np.ndarray:
    """Per step ``k`` (samples ``k``, ``k + 1``; ``n`` samples): sample ``k + 1`` is not ``idle``
    (``phase[1:] != 'idle'``), from the phase blocks."""
    moving = np.ones(max(n - 1, 0), dtype=bool)
    for a, b, label in zip(starts, starts[1:] + [n], labels):
        if label == "idle":
            moving[max(a - 1, 0):b - 1] = False
    return moving


def _check_phase_order(rec: _Record, starts: list[int], labels: list[str]) -> None:
    kind = rec.experiment.get("kind")
    order = PHASE_ORDER.get(kind)
    if order is None:
        return
    bad = _first_out_of_order(starts, labels, order)
    if bad is None:
        return
    k, label = bad
    after = f" after {str(rec.phase[k - 1])!r}" if k else " first"
    fits = [other for other, o in PHASE_ORDER.items() if o is not None and _first_out_of_order(starts, labels, o) is None]
    hint = f"; the phases fit a {' or '.join(fits)} run: is experiment.kind right?" if fits else ""
    raise RecordError(f"{rec.name}: line {_line(k)}, column 'phase': {label!r}{after}; expected the phases of a "
                      f"{kind} run in the order {' -> '.join(order)} (each once; hold and idle optional){hint}")


def _first_out_of_order(starts: list[int], labels: list[str], order: tuple[str, ...]) -> tuple[int, str] | None:
    """(sample index, label) of the first phase block (``starts``, ``labels``) that breaks ``order``, or None."""
    pos = -1
    for k, label in zip(starts, labels):
        nxt = next((p for p in range(pos + 1, len(order)) if order[p] == label), None)
        if nxt is None:
            return k, label
        pos = nxt
    return None
