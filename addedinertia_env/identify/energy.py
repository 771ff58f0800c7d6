"""The energy method of patent RU 2627023, in the general form of physics.md section 4.

For a boundary angle ``phi1`` passed forward at ``t1`` and in reverse at ``t4`` (the hull
rests at ``t2``, end of the free stroke, and ``t3``, end of the hold)::

    (J_h + lambda66) (w1f^2 + w1r^2) / 2 =
        Pi(t2) - Pi(t1) + Pi(t3) - Pi(t4)            (spring, with measured angles)
      + (A_r + B_r) - (A_f + B_f)                     (motor work, rotor-bearing work)
      + K(t2) + K(t3) - K(t1) - K(t4)                 (flywheel energy 1/2 J_f (w + Omega)^2)
      + hull energy left at t2, t3                    (nearly zero: the hull rests)
      - dW                                            (dissipation mismatch, optional)

The hydrodynamic dissipation cancels if the reverse stroke retraces ``|w(phi)|``. What
the controller fails to retrace leaves ``dW = integral D'(|w|) (|w_r| - |w_f|) dphi``,
which is estimated from the record itself (a damping law fitted to the forward stroke)
and removed; half of it is kept as uncertainty.

Where the error comes from (docs/ENERGY_METHOD.md has the budget, term by term): the
hull's rates at the boundary instants. A 17-bit encoder leaves about 5e-4 of relative
error in a rate fitted around one instant, which is 0.1 to 1 % of lambda66 per boundary
angle. So, unless the record names its boundary angles, the balance is evaluated at a
dense set of angles between 25 % and 75 % of the stroke and averaged with smooth (Hann)
weights: the average of many overlapping rate fits weighted smoothly is the rate error
integrated against a smooth kernel, which is the angle noise times the kernel's slope,
about ten times smaller than one pointwise rate. The motor work is a cumulative sum
interpolated to the exact crossing instants (not to the nearest sample).

Motor work forms (``work=``):

* ``reaction`` (default): the work of the motor's reaction on the hull,
  ``-integral (k_t i - M_f) dphi``; the hull's own balance, no flywheel energy enters;
* ``current``: ``integral k_t i dpsi`` plus the flywheel energies at the four instants;
* ``electric``: electric energy minus ohmic and magnetic energy (the patent's wording),
  plus the flywheel energies.

The three are one identity in exact arithmetic (the flywheel's own balance), but the
``current`` and ``electric`` forms push the flywheel's tens of joules through the
balance of a hull that carries a fraction of a joule: every relative error of the
current gain, ``R`` or the flywheel rate is multiplied by that ratio. They are
diagnostics, and say so when used (:data:`DIAGNOSTIC_FORM_WARNING`).

The current-sensor offset is calibrated on the free stroke, where the motor is open
circuit and the true current is zero. The torque per logged ampere and the current
channel's lag are calibrated on the flywheel's own balance ``J_f (w + Omega)' = k_t i - M_f``
over the end of the hold and the reverse stroke (:func:`_flywheel_calibration`; physics.md
section 8): the flywheel's inertia, not the data-sheet ``k_t`` or the current sensor's gain,
then sets the scale of the motor's work, and a lagging current channel is shifted back. When
the current has too few fast changes to pin the lag (an ideal tracking controller's), the
rig block's ``k_t`` and the record's ``current_sampling`` are used as they stand. Only the record's samples and its ``rig`` block are
used; never ``truth``. ``rig.L`` may be 0 or absent: the reaction form does not need it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..metrics import current_at_limit
from ..record import MAX_GAP_PERIODS, RunRecord, current_sampling
from ..rig.known import KnownRigError
from ..scan_kernels import (block_starts, gap_counts, negative_step_ratios, reaction_work, relaxed_interval_means,
                            squared_step_sums, true_counts, value_change_starts)
from ..series_kernels import (accumulated_kernels, accumulated_windows, calibration_target, count_crossings,
                              lag_ranking, twice_integrated)
from ..series_stats import median_step
from .balance_kernels import angle_uncertainties, angle_values
from .common import (IdentificationError, Result, SharedSavgol, largest_gap, line_fit, local_fit, pooled_interval,
                     power_fit, savgol, smooth_angle, smooth_angles)
from .crossings import crossing_fits, first_crossings
from .fit_kernels import lstsq as rounded_lstsq
from .fit_kernels import line_basis, project_out_line

# Boundary angles as fractions of the way from the calibrated neutral to the stop phi2:
# the patent drops the nearly uniform middle of the stroke, and too near the stop the
# kinetic energy (the denominator) vanishes. ``DEFAULT_FRACTIONS`` spans the range; the
# balance is evaluated at ``DENSE_ANGLES`` angles across it and averaged with Hann weights.
DEFAULT_FRACTIONS = (0.25, 0.75)
DENSE_ANGLES = 41
FLYWHEEL_CALIBRATION = True  # calibrate the motor torque and the current's lag on the flywheel's balance
WORK_FORMS = ("reaction", "current", "electric")
CURRENT_GAIN_UNCERTAINTY = 0.005  # relative, current-sensor gain (physics.md section 7)
# relative, torque per ampere once calibrated on the flywheel: the fit's scatter between runs
# (~5e-4) and the flywheel inertia's own calibration, assumed 0.2 %
CALIBRATED_TORQUE_UNCERTAINTY = 0.002
MAX_LAG_S = 0.012  # s, the longest current-channel lag the flywheel calibration looks for
MAX_SATURATED_FRACTION = 0.02  # an angle is rejected when the current sat at its limit over more of k3..k4
MAX_SPEED_MISMATCH = 0.2  # ... or when its reverse speed differs from the forward speed by more than this
LAG_PRECISION = 0.02  # the current lag must be fitted to this fraction of a sample period to be used
RATE_HALF_WIDTH = 0.1  # s, window of the local quintic that gives crossing instants and rates
RATE_DEGREE = 5
REST_FIT_S = 0.08  # s, span of encoder steps before t2 and after t3 that give the rest angles
DAMPING_FIT_WINDOW_S = 0.1  # s, Savitzky-Golay window of the rates and accelerations of the damping fit
WORK_SMOOTHING_S = 0.2  # s, window of the quintic smoothing of the angles in the work sums
DIAGNOSTIC_FORM_WARNING = (
    "energy method, work={work!r}: a diagnostic form; it books the flywheel's energy (tens of J) "
    "against the hull's (under 1 J), so current-gain, R and flywheel-rate errors are multiplied "
    "about 100-fold: expect about 1 % of error with a calibrated current sensor and several % with "
    "a 0.5 % gain error (docs/ENERGY_METHOD.md). Use work='reaction' for the estimate.")


@dataclass
class BalanceTerms:
    """Every term of the energy balance at one boundary angle (J; s; rad/s; rad).

    :func:`inertia_from_terms` turns them into ``lambda66``; the error budget
    (:mod:`addedinertia_env.experiment.energy_budget`) swaps single terms for the
    simulator's truth to see what each one costs.
    """

    phi1: float
    t1: float
    t4: float
    w1f: float
    w1r: float
    spring: float
    A_f: float
    A_r: float
    B_f: float = 0.0
    B_r: float = 0.0
    K1: float = 0.0
    K2: float = 0.0
    K3: float = 0.0
    K4: float = 0.0
    hull_rest: float = 0.0
    dW: float = 0.0


def inertia_from_terms(terms: BalanceTerms, J_hull: float) -> float:
    """``lambda66`` (kg m^2) from the balance terms and the hull's inertia in air ``J_hull``."""
    T = terms
    numerator = (T.spring + (T.A_r + T.B_r) - (T.A_f + T.B_f) + T.K2 + T.K3 - T.K1 - T.K4
                 + T.hull_rest - T.dW)
    return numerator / (0.5 * (T.w1f**2 + T.w1r**2)) - J_hull


def hann_weights(fractions: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Smooth weights over boundary-angle fractions, zero at ``lo`` and ``hi``, peak in the middle."""
    x = (np.asarray(fractions, float) - lo) / (hi - lo)
    return np.where((x > 0) & (x < 1), np.sin(np.pi * np.clip(x, 0, 1)) ** 2, 0.0)


@dataclass
class Interval:
    """One boundary angle in one run."""

    run: str
    phi1: float
    lambda66: float
    sigma: float
    w1f: float
    w1r: float
    terms: dict[str, float] = field(default_factory=dict)
    rejected: str = ""
    sigma_independent: float = float("inf")  # noise and rate fits
    sigma_common: float = 0.0  # current-sensor gain and dissipation-mismatch model: shared by all angles
    weight: float = 1.0  # weight of this angle in its run's average


@dataclass
class _RunEstimate:
    value: float
    sigma: float
    intervals: list[Interval]
    counts: tuple[int, int] | None = None  # (usable, all) angles when ``intervals`` is not kept


def identify_energy(records: list[RunRecord], work: str = "reaction", fractions=DEFAULT_FRACTIONS,
                    asymmetry_correction: bool = True, interval_details: bool = True, checked=None) -> Result:
    """lambda66 (kg m^2) from one or more reverse-symmetric runs, with a 95 % interval.

    ``fractions``: the range ``(lo, hi)`` of boundary angles as fractions of the stroke
    (dense Hann-weighted average), or a list of three or more fractions to evaluate
    separately and pool by inverse variance. A record's own ``experiment.phi1`` list wins.
    ``interval_details=False``: the result's ``details`` leave out the per-angle ``intervals``
    (the same lambda66, interval and counts; a caller that only needs the numbers, such as
    the batched env scoring every episode, skips building a record per angle).
    ``checked``: per record, the :class:`~addedinertia_env.plausibility.Limits` its plausibility check
    returned (:func:`~addedinertia_env.identify.identify` passes them): the typed rig and phase blocks
    the check read are used instead of being derived again (None: derived here).
    """
    if work not in WORK_FORMS:
        raise ValueError(f"work={work!r}: expected one of {WORK_FORMS}")
    if work != "reaction":
        warnings.warn(DIAGNOSTIC_FORM_WARNING.format(work=work), stacklevel=2)
    checked = [None] * len(records) if checked is None else list(checked)
    if len(checked) != len(records):
        raise ValueError(f"checked: {len(checked)} check results for {len(records)} records; expected one per record")
    runs = [_run_estimate(rec, work, fractions, asymmetry_correction, interval_details, limits)
            for rec, limits in zip(records, checked)]
    intervals = [iv for r in runs for iv in r.intervals]
    good = [r for r in runs if np.isfinite(r.value)]
    if not good:
        reasons = "; ".join(sorted({iv.rejected for iv in intervals if iv.rejected})) or "no usable interval"
        names = ", ".join(sorted({rec.name for rec in records}))
        raise IdentificationError(f"energy method on {names}: every boundary-angle interval was rejected "
                                  f"({reasons}); expected a reverse-symmetric run whose strokes pass the boundary "
                                  "angles, sampled without gaps, current below its limit")
    value, lo, hi = pooled_interval(np.array([r.value for r in good]), np.array([r.sigma for r in good]))
    n_good = sum(1 for iv in intervals if not iv.rejected) + sum(r.counts[0] for r in runs if r.counts)
    n_all = len(intervals) + sum(r.counts[1] for r in runs if r.counts)
    details = {"work": work, "asymmetry_correction": asymmetry_correction, "n_runs": len(good),
               "per_run": [r.value for r in good], "per_run_sigma": [r.sigma for r in good],
               "rejected": n_all - n_good}
    if interval_details:
        details["intervals"] = [iv.__dict__ for iv in intervals]
    return Result(method="energy", lambda66=value, ci95=(lo, hi), n_intervals=n_good, details=details)


def _run_estimate(rec: RunRecord, work: str, fractions, asymmetry_correction: bool,
                  interval_details: bool = True, checked=None) -> _RunEstimate:
    balance, phi1_list, weights, first = prepared_balance(rec, work, fractions, asymmetry_correction,
                                                          first_value_only=True, checked=checked)
    if not np.isfinite(first.value):
        return first
    phi1 = np.asarray(phi1_list, dtype=float)
    if not interval_details and weights is not None:  # the numbers alone, from the angles' columns
        cols = balance.interval_columns(phi1)
        estimate = _dense_from_columns(balance, cols, weights)
        if np.isfinite(estimate.value):
            return estimate
    return _combine(balance, balance.intervals(phi1), weights)


def prepared_balance(rec: RunRecord, work: str = "reaction", fractions=DEFAULT_FRACTIONS,
                     asymmetry_correction: bool = True, first_value_only: bool = False, checked=None):
    """A record's :class:`RunBalance` after the first pass, its boundary angles (rad), their
    weights (None: pooled by inverse variance) and the first pass's estimate.

    The first pass (no dissipation-mismatch correction) gives the total inertia that the
    damping-law fit and the hull's energy at rest then use. ``first_value_only``: when the
    first estimate is finite, only its value is computed (its ``sigma`` is nan and it holds
    no intervals; the value is the same number); the full estimate otherwise. ``checked``: the
    record's plausibility check result (:class:`RunBalance`).
    """
    balance = RunBalance(rec, work, asymmetry_correction, checked)
    given = rec.experiment.get("phi1")
    dense = not given and len(fractions) == 2
    if given:
        phi1_list, weights = [float(x) for x in given], None
    elif dense:
        f, weights = _dense_fractions(fractions[0], fractions[1], DENSE_ANGLES)
        phi1_list = list(balance.phi_n + f * (balance.phi2 - balance.phi_n))
    else:
        phi1_list, weights = [balance.phi_n + x * (balance.phi2 - balance.phi_n) for x in fractions], None
    first = None
    if first_value_only and weights is not None:  # the Hann-weighted value alone (what the second pass needs)
        value = balance.weighted_value(np.asarray(phi1_list, dtype=float), weights)
        if np.isfinite(value):
            first = _RunEstimate(value, float("nan"), [])
    if first is None:
        first = _combine(balance, balance.intervals(np.asarray(phi1_list, dtype=float)), weights)
    if np.isfinite(first.value):
        balance.use_total_inertia(first.value + balance.J_h)
    return balance, phi1_list, weights, first


def _dense_fractions(lo, hi, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.linspace(lo, hi, n)`` and their :func:`hann_weights` over ``(lo, hi)``: kept (read-only) for
    float bounds, which give the same arrays every time; computed afresh for any other kind of number."""
    if type(lo) is float and type(hi) is float:
        return _dense_fractions_of_floats(lo, hi, n)
    f = np.linspace(lo, hi, n)
    return f, hann_weights(f, lo, hi)


@lru_cache(maxsize=16)
def _dense_fractions_of_floats(lo: float, hi: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    f = np.linspace(lo, hi, n)
    weights = hann_weights(f, lo, hi)
    for x in (f, weights):
        x.flags.writeable = False
    return f, weights


def _combine(balance: "RunBalance", intervals: list[Interval], weights) -> _RunEstimate:
    """One run's estimate from its boundary angles: Hann-weighted (dense) or inverse-variance pooled."""
    ok = [k for k, iv in enumerate(intervals) if not iv.rejected]
    if not ok:
        return _RunEstimate(float("nan"), float("inf"), intervals)
    lam = np.array([intervals[k].lambda66 for k in ok])
    if weights is None:  # separate angles, pooled by inverse variance (Birge-widened)
        s_ind = np.array([intervals[k].sigma_independent for k in ok])
        value, lo, _ = pooled_interval(lam, s_ind)
        s_common = float(np.median([intervals[k].sigma_common for k in ok]))
        for iv in intervals:
            iv.weight = 0.0 if iv.rejected else 1.0
        return _RunEstimate(value, float(np.hypot((value - lo) / 1.96, s_common)), intervals)
    g = np.array([weights[k] for k in ok])
    if g.sum() <= 0:
        return _RunEstimate(float("nan"), float("inf"), intervals)
    g = g / g.sum()
    for iv in intervals:
        iv.weight = 0.0
    for gk, k in zip(g, ok):
        intervals[k].weight = float(gk)
    used = [intervals[k] for k in ok]
    value, sigma = _dense_estimate(balance, g, lam, [iv.phi1 for iv in used], [iv.lambda66 for iv in used],
                                   [iv.w1f for iv in used], [iv.w1r for iv in used],
                                   [iv.terms["s_current"] for iv in used], [iv.sigma_common for iv in used],
                                   [iv.sigma_independent for iv in used],
                                   [iv.terms["rate_kernel_f"] for iv in used], [iv.terms["rate_kernel_r"] for iv in used])
    for iv in used:  # the kernels are bulky; keep the JSON small
        iv.terms.pop("rate_kernel_f", None)
        iv.terms.pop("rate_kernel_r", None)
    return _RunEstimate(value, sigma, intervals)


def _dense_from_columns(balance: "RunBalance", cols: dict, weights: np.ndarray) -> _RunEstimate:
    """:func:`_combine`'s Hann-weighted estimate from :meth:`RunBalance.interval_columns` (the same
    numbers, no :class:`Interval` records; nan when no angle is usable)."""
    good = cols["good"]
    if not len(good):
        return _RunEstimate(float("nan"), float("inf"), [], (0, len(cols["phi1"])))
    rows = np.nonzero(~cols["rejected"])[0]
    ok = good[rows].tolist()
    counts = (len(ok), len(cols["phi1"]))
    if not ok:
        return _RunEstimate(float("nan"), float("inf"), [], counts)
    if isinstance(weights, np.ndarray) and weights.dtype == np.float64 and weights.ndim == 1:
        g = weights[good[rows]]  # the same numbers as np.array([weights[k] for k in ok])
    else:
        g = np.array([weights[k] for k in ok])
    total = g.sum()
    if total <= 0:
        return _RunEstimate(float("nan"), float("inf"), [], counts)
    g = g / total
    lam = np.asarray(cols["lam"], dtype=float)[rows]
    lam_list = lam.tolist()  # the Python floats the Interval records hold

    def pick(name):
        return np.asarray(cols[name], dtype=float)[rows].tolist()

    fits = np.empty(2 * len(rows), dtype=np.int64)  # the used angles' forward and reverse fits, in turn
    fits[0::2], fits[1::2] = 2 * rows, 2 * rows + 1
    value, sigma = _dense_estimate(balance, g, lam, cols["phi1"][good[rows]].tolist(), lam_list,
                                   pick("w1f"), pick("w1r"), pick("s_current"), pick("s_common"),
                                   pick("s_independent"), None, None, (cols["windows"], fits))
    return _RunEstimate(value, sigma, [], counts)


def _dense_estimate(balance: "RunBalance", g: np.ndarray, lam: np.ndarray, phi1: list, lam_list: list,
                    w1f: list, w1r: list, s_current: list, s_common: list, s_independent: list,
                    kernels_f: list | None, kernels_r: list | None, windows=None) -> tuple[float, float]:
    """The Hann-weighted lambda66 of a run and its 1-sigma (kg m^2) from its usable angles: normalised
    weights ``g``, per-angle values ``lam`` (array) and, per angle, ``phi1``, ``lam_list`` (the same values
    as Python floats), rates, uncertainty parts and rate kernels ``(indices, weights)``; or, instead of
    the kernels' lists, ``windows``: ``(crossing_fits' windows, the used fits in order)``."""
    value = float(g @ lam)
    if windows is not None:
        s_rate = balance.rate_sigma_of_windows(g, lam_list, w1f, w1r, *windows)
    else:
        s_rate = balance.rate_sigma(g, lam_list, w1f, w1r, kernels_f, kernels_r)
    s_cur = float(g @ np.array(s_current))
    s_com = float(g @ np.array(s_common))
    # Angles further apart than the rate windows see independent noise: their scatter about
    # a smooth trend beyond what the rate noise allows is a sign of unmodelled structure,
    # and the interval is widened by it (a Birge ratio on the trend residuals).
    s_trend = _trend_excess(np.array(phi1), lam, np.array(s_independent), g)
    return value, float(np.sqrt(s_rate**2 + s_cur**2 + s_com**2 + s_trend**2))


def _trend_excess(phi1: np.ndarray, lam: np.ndarray, s: np.ndarray, g: np.ndarray) -> float:
    """Spread of the per-angle estimates ``lam`` (kg m^2, at angles ``phi1``, noise ``s``) about a straight
    line in phi1 beyond their own noise, kg m^2."""
    if len(lam) < 6:
        return 0.0
    coef = line_fit(phi1, lam)
    resid = lam - ((0.0 * phi1 + coef[0]) * phi1 + coef[1])  # np.polyval(coef, phi1), Horner from zero
    excess = float(np.sum(g * (resid**2 - s**2)))
    # The mean over the range equals the line's value at the weighted centre; a slope means
    # the estimate depends on where the boundary is taken: a quarter of the end-to-end change
    # is kept as uncertainty.
    slope_part = 0.25 * abs(coef[0]) * float(phi1.max() - phi1.min())  # np.ptp's two reductions
    return float(np.hypot(np.sqrt(max(excess, 0.0)) / np.sqrt(max(len(lam) / 8.0, 1.0)), slope_part))


_VALUE_TERMS = ("spring", "A_f", "A_r", "B_f", "B_r", "K1", "K2", "K3", "K4", "hull_rest", "dW", "w1f", "w1r")
_NO_COUNTS = np.zeros(0, dtype=np.int64)


class RunBalance:
    """The energy balance of one reverse-symmetric record, evaluated at any boundary angle.

    Everything that does not depend on the boundary angle (calibrated current, smoothed
    angles, cumulative motor work, damping law, speed profiles) is prepared once. ``checked``: the
    :class:`~addedinertia_env.plausibility.Limits` of the record's plausibility check, whose typed rig
    and phase blocks are then taken as read (the same the record gives).
    """

    def __init__(self, rec: RunRecord, work: str = "reaction", asymmetry_correction: bool = True, checked=None):
        known = getattr(checked, "known", None)
        rig = self.known = known if known is not None else rec.known
        self.rec, self.work = rec, work
        self.J_h, self.J_f, self.c = rig.J_hull, rig.J_flywheel, rig.c_torsion
        self.phi_n, self.k_t, self.R = rig.phi_neutral, rig.k_t, rig.R
        self.L = float(rig.L or 0.0)  # 0: neglected or unknown; only the electric form needs it
        self.current_sampling = current_sampling(rec.rig)[0]
        self.f_visc, self.f_coul = rig.friction_viscous, rig.friction_coulomb
        if rec.experiment.get("kind") != "reverse-symmetric":
            raise IdentificationError(f"{rec.name}: the energy method needs a reverse-symmetric run, "
                                      f"not {rec.experiment.get('kind')!r}")
        if work == "electric":
            try:
                self.L = rig.require_L("the energy method with work='electric'")
            except KnownRigError as e:
                raise IdentificationError(f"{rec.name}: {e}") from None
            if self.L <= 0.0:
                raise IdentificationError(f"{rec.name}: the energy method with work='electric' needs rig.L > 0 "
                                          f"(winding inductance, H); the record gives {self.L!r}; use work='reaction'")
        t, phi, psi = rec.t, rec["phi"], rec["psi"]
        self.t, self.phi, self.psi = t, phi, psi
        first_blocks, phase_starts = _first_blocks(rec, getattr(checked, "phase_blocks", None))
        free, hold, rev = first_blocks.get("free"), first_blocks.get("hold"), first_blocks.get("reverse")
        if free is None or rev is None:
            raise IdentificationError(f"{rec.name}: needs a 'free' and a 'reverse' phase")
        self.free, self.rev = free, rev
        self.hold_start = hold.start if hold is not None else free.start
        self.i_offset = float(np.mean(rec["i"][free]))  # open circuit on the free stroke: true i = 0
        self.i = rec["i"] - self.i_offset
        self.noise_i = float(np.std(rec["i"][free]))
        self.k2 = free.stop - 1  # last free sample: the brake is set (t2)
        self.k3 = (hold.stop - 1) if hold is not None else rev.start - 1  # last braked sample (t3)
        self.phi2 = float(phi[self.k2])
        self.direction = float(np.sign(self.phi2 - self.phi_n))
        # Smoothed angles for the work increments, smoothed phase by phase: a window across the
        # brake's release would leak the first milliseconds of the reverse stroke into t3.
        self.phi_s, self.psi_s = _smooth_by_phase(rec, phi, psi, cuts=phase_blocks(rec, phase_starts))
        self.phi_rest2, self.phi_rest3 = self._rest_angles(hold)  # also anchors phi_s at the release
        self.torque_scale, self.current_lag = 1.0, 0.0
        if work == "reaction" and FLYWHEEL_CALIBRATION:
            dt_median = float(median_step(t))
            start = max(self.k3 - _n_samples(dt_median, 1.0), hold.start if hold is not None else self.k3) + 1
            # The fit stays inside the reverse stroke with its lag grid (the record may end there).
            end = rev.stop - 1 - _n_samples(dt_median, MAX_LAG_S) - 2
            calib = _flywheel_calibration(t, phi + psi, self.psi_s, self.i, start, end, self.J_f, self.k_t,
                                          self.f_visc, self.f_coul)
            if calib is not None:
                self.torque_scale, self.current_lag = calib
        self.work_cum = self._cumulative_work()
        self.bearing_cum = self._cumulative_bearing_work() if work != "reaction" else np.zeros(t.shape, t.dtype)
        self.asymmetry_correction = asymmetry_correction
        self._fits: dict = {}
        self._dsq_cum: np.ndarray | None = None
        self.law: dict | None = None
        self.dW_of = None  # set by use_total_inertia once a first estimate exists
        sat = None
        if "i_cmd" in rec.samples and np.isfinite(rig.current_limit):
            sat = current_at_limit(rec["i_cmd"], rig.current_limit)
        self.saturated = sat
        self._sat_count: np.ndarray | None = None  # cumulative count of saturated samples (built once)
        w2 = (_power_series(_power_series_derivative(self._fit_before), 0.0) if self._fit_before is not None
              else self._rest_rate(self.k2, free.start))
        w3 = w2 if hold is None else self._rest_rate(self.k3, hold.start)
        self.rest_w2, self.rest_w3 = float(w2), float(w3)  # hull rates at t2 and t3, rad/s
        self.rest_rates_sq = float(w2**2 + w3**2)
        self.hull_rest = 0.5 * 2.0 * self.J_h * self.rest_rates_sq  # refined by use_total_inertia
        self.quantum = _quantum(phi, rig.phi_counts)

    def use_total_inertia(self, J_total: float) -> None:
        """Refine with a first estimate of ``J_hull + lambda66`` (kg m^2): the hull's energy at
        rest, and the damping law (fitted with the inertia known, so the noise of the
        acceleration does not dilute it) behind the dissipation-mismatch correction."""
        self.hull_rest = 0.5 * J_total * self.rest_rates_sq
        if self.asymmetry_correction:
            rates = SharedSavgol(self.phi)  # the free stroke's rate filter: both fits see the same windows
            self.law = _forward_damping_law(self.rec, self.free, self.k2, J_total, self.c, self.phi_n, rates)
            self.dW_of = (_DissipationMismatch(self.t, self.phi, self.free, self.k2, self.k3, self.rev, self.law,
                                               self.direction, rates) if self.law else None)

    # --- per boundary angle ----------------------------------------------------------
    def terms(self, phi1: float) -> tuple[BalanceTerms, dict] | str:
        """The balance terms at ``phi1`` and fit details, or the reason the angle cannot be used."""
        got = self.terms_many(np.array([float(phi1)]))
        if got["reason"][0]:
            return got["reason"][0]
        T = BalanceTerms(**{name: float(getattr(got["terms"], name)[0]) for name in BalanceTerms.__dataclass_fields__})
        fit = got["fits"]
        return T, {"fit_f": {key: fit["f"][key][0] for key in fit["f"]},
                   "fit_r": {key: fit["r"][key][0] for key in fit["r"]},
                   "s_dW": float(got["s_dW"][0]), "k1": int(got["k1s"][0]), "k4": int(got["k4s"][0])}

    def _fits_at(self, phi1: np.ndarray) -> dict:
        """Crossing samples, rejections and crossing fits at the angles ``phi1`` (the second pass reuses the first's)."""
        key = phi1.tobytes()
        if key in self._fits:
            return self._fits[key]
        t, phi = self.t, self.phi
        k1 = first_crossings(phi, self.free.start, self.k2, phi1, self.direction)
        k4 = first_crossings(phi, self.rev.start, self.rev.stop - 1, phi1, -self.direction)
        passed = (k1 >= 0) & (k4 >= 0)
        reason = ["" if p else "boundary angle not passed on both strokes" for p in passed.tolist()]
        # the work sums and rate fits assume the stroke was sampled throughout
        period = 1.0 / float(self.rec.rig["sample_rate"])
        big = gap_counts(t, MAX_GAP_PERIODS * period * (1 + 1e-6))  # long gaps before each sample
        gapped = passed & (((big[self.k2] - big[k1]) != 0) | ((big[k4] - big[self.k3]) != 0))
        for j in np.nonzero(gapped)[0].tolist():  # a long gap: the message names it
            gap = largest_gap(self.rec, int(k1[j]), self.k2) or largest_gap(self.rec, self.k3, int(k4[j]))
            reason[j] = (f"a gap of {gap[1]:.4g} s in 't' after t = {gap[0]:.4f} s inside the integrated "
                         f"stroke ({MAX_GAP_PERIODS:g} sample periods allowed)")
        ok = np.array([not r for r in reason], dtype=bool)
        good = np.nonzero(ok)[0]
        # forward and reverse fit of each angle in turn (the first short window raises, as angle by angle)
        both = crossing_fits(t, phi, np.stack([k1[good], k4[good]], axis=1).ravel(), np.repeat(phi1[good], 2),
                             RATE_HALF_WIDTH, RATE_DEGREE)
        fits = {side: {"t": both["t"][j::2], "rate": both["rate"][j::2], "sigma_rate": both["sigma_rate"][j::2],
                       "kernel": both["kernel"][j::2]} for j, side in enumerate("fr")}
        self._fits[key] = got = {"ok": ok, "reason": reason, "good": good, "fits": fits, "windows": both["windows"]}
        return got

    def terms_many(self, phi1: np.ndarray) -> dict:
        """The balance terms at every angle of ``phi1`` (rad) that both strokes pass: a
        :class:`BalanceTerms` of arrays over the usable angles ``good`` (indices into
        ``phi1``), their fits (``fits["f"]``, ``fits["r"]``: crossing time, rate, its sigma,
        kernel), ``s_dW``, ``k1s``, ``k4s``; ``reason`` says why each other angle cannot be used; ``windows``:
        the fits' kernels as :func:`~.crossings.crossing_fits` gives them (forward and reverse fit of each
        usable angle in turn)."""
        phi1 = np.asarray(phi1, dtype=float)
        got = self._fits_at(phi1)
        good, fits = got["good"], got["fits"]
        t = self.t
        t1, w1f, t4, w1r = fits["f"]["t"], fits["f"]["rate"], fits["r"]["t"], fits["r"]["rate"]
        if "fixed" not in got:  # what the total inertia does not change (the second pass gets copies)
            p = phi1[good]
            t2, t3 = t[self.k2], t[self.k3]
            # the cumulative works at t2, t3, every t1 and every t4, each interpolated in one call
            at = np.concatenate([[t2, t3], t1, t4])
            n1 = len(t1)
            W, B = np.interp(at, t, self.work_cum), np.interp(at, t, self.bearing_cum)
            A_f, A_r = W[0] - W[2:2 + n1], W[2 + n1:] - W[1]
            B_f, B_r = B[0] - B[2:2 + n1], B[2 + n1:] - B[1]
            c, n, p2, p3 = self.c, self.phi_n, self.phi_rest2, self.phi_rest3
            spring = 0.5 * c * ((p2 - n) ** 2 - (p - n) ** 2 + (p3 - n) ** 2 - (p - n) ** 2)
            got["fixed"] = (p, spring, A_f, A_r, B_f, B_r, np.searchsorted(t, t1), np.searchsorted(t, t4))
        p, spring, A_f, A_r, B_f, B_r, k1s, k4s = (x.copy() for x in got["fixed"])
        zero = np.zeros(len(good))
        T = BalanceTerms(phi1=p, t1=t1, t4=t4, w1f=w1f, w1r=w1r, spring=spring, A_f=A_f, A_r=A_r, B_f=B_f,
                         B_r=B_r, K1=zero.copy(), K2=zero.copy(), K3=zero.copy(), K4=zero.copy(),
                         hull_rest=np.full(len(good), float(self.hull_rest)), dW=zero.copy())
        if self.work != "reaction":
            T.K1 = np.array([self._flywheel_energy_at(a, b) for a, b in zip(t1, w1f)])
            T.K4 = np.array([self._flywheel_energy_at(a, b) for a, b in zip(t4, w1r)])
            # At t2 and t3 the brake is set and released and the motor's torque jumps: the
            # flywheel's rate there comes from the samples before each instant only.
            omega2 = self._rest_rate(self.k2, self.free.start, RATE_HALF_WIDTH, self.psi)
            omega3 = self._rest_rate(self.k3, self.hold_start if self.k3 != self.k2 else self.free.start,
                                     RATE_HALF_WIDTH, self.psi)
            T.K2[:] = 0.5 * self.J_f * (omega2 + self.rest_w2) ** 2
            T.K3[:] = 0.5 * self.J_f * (omega3 + self.rest_w3) ** 2
        s_dW = zero.copy()
        if self.dW_of is not None:
            T.dW, s_dW = self.dW_of(p)
        return {"terms": T, "fits": fits, "good": good, "reason": got["reason"], "s_dW": s_dW,
                "k1s": k1s, "k4s": k4s, "windows": got["windows"]}

    def interval(self, phi1: float) -> Interval:
        """One boundary angle's estimate with its uncertainty parts, or a rejected interval."""
        return self.intervals(np.array([float(phi1)]))[0]

    def interval_columns(self, phi1: np.ndarray) -> dict:
        """What :meth:`intervals` reports, as arrays over the angles both strokes pass (``good``,
        indices into ``phi1``): ``lam``, ``w1f``, ``w1r`` and the uncertainty parts ``s_independent``,
        ``s_common``, ``sigma``, ``s_current`` (kg m^2), the rejection tests' ``sat`` and ``mismatch`` and
        ``rejected`` (bool), the ``terms``, ``fits`` and ``windows`` of :meth:`terms_many`; ``reason`` per angle of
        ``phi1`` why it cannot be used ('' when both strokes pass it)."""
        phi1 = np.asarray(phi1, dtype=float)
        got = self.terms_many(phi1)
        good = got["good"]
        cols = {"phi1": phi1, "reason": got["reason"], "good": good, "terms": got["terms"], "fits": got["fits"],
                "windows": got["windows"]}
        if not len(good):
            return cols
        T, fit = got["terms"], got["fits"]
        k1s, k4s = got["k1s"], got["k4s"]
        lam, sat, mismatch = self._values(T, k4s)
        if self._dsq_cum is None:  # sum of the squared angle increments from the first sample
            self._dsq_cum = squared_step_sums(self.phi_s if self.work == "reaction" else self.psi_s)
        gain_u = CALIBRATED_TORQUE_UNCERTAINTY if self.calibrated else CURRENT_GAIN_UNCERTAINTY
        # the motor work's noise over k1..k2 and k3..k4, the rates' sigmas, the gain's and the dissipation
        # model's parts, each over the kinetic denominator (the numpy expressions, compiled)
        contiguous = [np.ascontiguousarray(x, dtype=float) for x in (T.A_f, T.A_r, T.w1f, T.w1r, fit["f"]["sigma_rate"],
                                                                      fit["r"]["sigma_rate"], got["s_dW"])]
        s_independent, s_common, sigma, s_current = angle_uncertainties(
            lam, *contiguous, np.asarray(k1s, dtype=np.int64), np.asarray(k4s, dtype=np.int64), self.k2, self.k3,
            self._dsq_cum, self.k_t * self.noise_i, gain_u, self.J_h)
        cols.update(lam=lam, w1f=T.w1f, w1r=T.w1r, s_independent=s_independent, s_common=s_common, sigma=sigma,
                    s_current=s_current, sat=sat, mismatch=mismatch,
                    rejected=(sat > MAX_SATURATED_FRACTION) | (mismatch > MAX_SPEED_MISMATCH))
        return cols

    def intervals(self, phi1: np.ndarray) -> list[Interval]:
        """Each boundary angle's estimate with its uncertainty parts, or a rejected interval."""
        cols = self.interval_columns(phi1)
        name = self.rec.name
        out = [Interval(run=name, phi1=float(x), lambda66=float("nan"), sigma=float("inf"), w1f=0.0, w1r=0.0,
                        rejected=why) for x, why in zip(cols["phi1"], cols["reason"])]
        good = cols["good"]
        if not len(good):
            return out
        T, fit = cols["terms"], cols["fits"]
        lam, s_independent, s_common, sigma = cols["lam"], cols["s_independent"], cols["s_common"], cols["sigma"]
        s_current, sat, mismatch = cols["s_current"], cols["sat"], cols["mismatch"]
        names = list(BalanceTerms.__dataclass_fields__)
        columns = [np.asarray(getattr(T, name), dtype=float).tolist() for name in names]  # Python floats, as float()
        # per-row Python floats (tolist: the numbers float() gives), then one pass over the rows
        rows = zip(good.tolist(), zip(*columns), np.asarray(lam, dtype=float).tolist(), T.w1f.tolist(),
                   T.w1r.tolist(), s_independent.tolist(), s_common.tolist(), sigma.tolist(),
                   np.asarray(sat, dtype=float).tolist(), s_current.tolist(), mismatch.tolist(),
                   fit["f"]["kernel"], fit["r"]["kernel"])
        for j, values, lam_j, w1f, w1r, s_ind, s_com, sig, sat_j, s_cur, mis, kern_f, kern_r in rows:
            iv = out[j]
            iv.lambda66, iv.w1f, iv.w1r = lam_j, w1f, w1r
            iv.sigma_independent, iv.sigma_common, iv.sigma = s_ind, s_com, sig
            terms = dict(zip(names, values))
            terms.update(saturated_frac=sat_j, s_current=s_cur, rate_kernel_f=kern_f, rate_kernel_r=kern_r,
                         speed_mismatch=mis)
            iv.terms = terms
            if sat_j > MAX_SATURATED_FRACTION:
                iv.rejected = f"current at its limit for {sat_j:.0%} of the reverse stroke"
            elif mis > MAX_SPEED_MISMATCH:
                iv.rejected = f"reverse speed at phi1 differs by {mis:.0%} from the forward speed"
        return out

    def _values(self, T: BalanceTerms, k4s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per usable angle: lambda66 (:func:`inertia_from_terms`, kg m^2), the fraction of samples k3..k4
        with the current at its limit, and the relative difference of the reverse and forward speeds at
        the angle (the rejection tests)."""
        if self.saturated is not None and self._sat_count is None:  # cumulative count of samples at the limit
            self._sat_count = true_counts(self.saturated)
        count = self._sat_count if self.saturated is not None else _NO_COUNTS
        f = [np.ascontiguousarray(getattr(T, name), dtype=float) for name in _VALUE_TERMS]
        return angle_values(*f, float(self.J_h), count, len(self.saturated) if self.saturated is not None else 0,
                            self.k3, np.asarray(k4s, dtype=np.int64))

    def weighted_value(self, phi1: np.ndarray, weights: np.ndarray) -> float:
        """The Hann-weighted lambda66 (kg m^2) over the usable angles ``phi1`` (weights ``weights``),
        the same number as :func:`_combine` of :meth:`intervals` gives, without the
        uncertainty parts or the per-angle records (nan when no angle is usable)."""
        got = self.terms_many(np.asarray(phi1, dtype=float))
        good = got["good"]
        if not len(good):
            return float("nan")
        lam, sat, mismatch = self._values(got["terms"], got["k4s"])
        keep = ~((sat > MAX_SATURATED_FRACTION) | (mismatch > MAX_SPEED_MISMATCH))  # not rejected by intervals()
        if not keep.any():
            return float("nan")
        g = np.asarray(weights, dtype=float)[good[keep]]
        if g.sum() <= 0:
            return float("nan")
        g = g / g.sum()
        return float(g @ np.asarray(lam, dtype=float)[keep])

    def averaged_rate_sigma(self, ivs: list[Interval], g: np.ndarray) -> float:
        """1-sigma of the weighted average's rate part, kg m^2, from the fits' linear kernels.

        Every rate is a linear combination of angle samples; the weighted average of
        lambda66 over the angles is, to first order, one combination of them, whose noise
        is the angle noise times the combined kernel's norm.
        """
        sigma = self.rate_sigma(g, [iv.lambda66 for iv in ivs], [iv.w1f for iv in ivs], [iv.w1r for iv in ivs],
                                [iv.terms["rate_kernel_f"] for iv in ivs], [iv.terms["rate_kernel_r"] for iv in ivs])
        for iv in ivs:  # the kernels are bulky; keep the JSON small
            iv.terms.pop("rate_kernel_f", None)
            iv.terms.pop("rate_kernel_r", None)
        return sigma

    def rate_sigma(self, g: np.ndarray, lam: list, w1f: list, w1r: list, kernels_f: list, kernels_r: list) -> float:
        """:meth:`averaged_rate_sigma` from per-angle lists: weights ``g``, lambda66 (kg m^2), forward and
        reverse rates (rad/s) and their fits' kernels ``(indices, weights)``; kg m^2."""
        factors = self._rate_factors(g, lam, w1f, w1r)
        kernels = [k for pair in zip(kernels_f, kernels_r) for k in pair][:len(factors)]
        # summed sample by sample in the order above (as adding the kernels one after another)
        if kernels:
            idx, kern = zip(*kernels)
            combined = accumulated_kernels(np.concatenate(idx).astype(np.int64, copy=False), np.concatenate(kern),
                                           np.array([len(k) for k in kern], dtype=np.int64),
                                           np.array(factors, dtype=float), len(self.t))
        else:
            combined = np.zeros(len(self.t))
        return self.angle_noise * float(np.linalg.norm(combined))

    def rate_sigma_of_windows(self, g: np.ndarray, lam: list, w1f: list, w1r: list, windows: tuple,
                              fits: np.ndarray) -> float:
        """:meth:`rate_sigma` (kg m^2, the same number) with the kernels given as :func:`~.crossings.crossing_fits`'
        ``windows`` (kernels over consecutive samples) and the fits used, in order (angle ``k``'s forward and
        reverse fit: ``fits[2k]``, ``fits[2k + 1]``)."""
        factors = self._rate_factors(g, lam, w1f, w1r)
        first, sizes, offsets, weights = windows
        used = np.asarray(fits, dtype=np.int64)[:len(factors)]
        combined = accumulated_windows(first, sizes, offsets, weights, used, np.array(factors, dtype=float),
                                       len(self.t))
        return self.angle_noise * float(np.linalg.norm(combined))

    def _rate_factors(self, g: np.ndarray, lam: list, w1f: list, w1r: list) -> list:
        """Each rate kernel's weight in :meth:`rate_sigma`: per angle, ``g_k (-J_total w / denom)`` for its
        forward and its reverse rate (``denom = (w1f^2 + w1r^2) / 2``, ``J_total = lambda66 + J_hull``)."""
        weights = g.tolist() if isinstance(g, np.ndarray) and g.dtype == np.float64 and g.ndim == 1 else g
        factors = []  # (a float64 array's elements as Python floats: the same products)
        for gk, lam_k, wf, wr in zip(weights, lam, w1f, w1r):
            denom = 0.5 * (wf**2 + wr**2)
            J_total = lam_k + self.J_h
            factors += [gk * (-J_total * wf / denom), gk * (-J_total * wr / denom)]
        return factors

    @property
    def angle_noise(self) -> float:
        """Hull-angle noise per sample, rad: the quantisation floor or the fits' residual scatter."""
        return self.quantum / np.sqrt(12.0) if self.quantum > 0 else 1e-7

    # --- helpers ------------------------------------------------------------------------
    def _rest_angles(self, hold: slice | None) -> tuple[float, float]:
        """Hull angles at t2 and t3, rad: the spring term's rests.

        A braked hull reads one constant encoder count, up to half a count (2.4e-5 rad for
        17 bits) from the truth; that is 0.05 to 0.15 % of lambda66 in the spring term. The
        count changes just before the stop and just after the release carry more: where the
        reading steps, the angle crosses the midpoint of the two readings, at a time known to
        half a sample while the hull moves slowly. A quadratic in time through those crossings
        over :data:`REST_FIT_S` on each side gives the rest angle to about 0.1 count. When the
        brake held the hull (the same count at t2 and t3 +- 1), both rests are one angle and
        the two sides' fits are averaged.
        """
        phi, k2, k3 = self.phi, self.k2, self.k3
        self._fit_before = None
        if not self.known.phi_counts:  # an encoder without stated counts: take the readings
            return float(phi[k2]), float(phi[k3])
        q = 2.0 * np.pi / self.known.phi_counts
        fit_before = _crossings_fit(self.t, phi, k2, -REST_FIT_S, q)
        fit_after = _crossings_fit(self.t, phi, k3, REST_FIT_S, q)
        self._fit_before = fit_before
        before = _power_series(fit_before, 0.0) if fit_before is not None else None
        after = _power_series(fit_after, 0.0) if fit_after is not None else None
        r2 = before if before is not None else float(phi[k2])
        r3 = after if after is not None else float(phi[k3])
        held = hold is not None and abs(phi[k3] - phi[k2]) <= 1.5 * q
        if held and before is not None and after is not None:
            r2 = r3 = 0.5 * (before + after)
        if fit_after is not None:
            self._anchor_reverse_start(fit_after, r3)
        return float(r2), float(r3)

    def _anchor_reverse_start(self, fit: np.ndarray, rest: float) -> None:
        """Replace the smoothed angle over the reverse stroke's first :data:`REST_FIT_S` by the
        rest-angle fit (blended out over its second half).

        At the brake's release the smoothing has only one side to work with, and its angle
        is off by up to half a count there, just where the motor pushes hardest: that offset
        times the starting torque is 0.02-0.03 % of lambda66 in the reverse work."""
        t, k3 = self.t, self.k3
        end = int(np.searchsorted(t, t[k3] + REST_FIT_S, side="right"))
        tau = t[k3:end] - t[k3]
        blend = np.clip(2.0 - 2.0 * tau / REST_FIT_S, 0.0, 1.0)
        curve = _power_series(fit, tau) - _power_series(fit, 0.0) + rest
        self.phi_s[k3:end] = blend * curve + (1.0 - blend) * self.phi_s[k3:end]

    def _rest_rate(self, k: int, start: int, window_s: float = 0.05, angle: np.ndarray | None = None) -> float:
        """Hull rate at sample ``k`` from a quadratic over the samples before it in its own phase, rad/s.

        At t2 the brake is set and at t3 released: a window reaching past either instant
        would see motion that belongs to the next phase.
        """
        t = self.t
        a = max(start, int(np.searchsorted(t, t[k] - window_s)))
        if k - a < 5:
            return 0.0
        s = t[a:k + 1] - t[k]
        coef = power_fit(s, (self.phi if angle is None else angle)[a:k + 1], 2)
        return float(coef[1])

    def _flywheel_energy_at(self, tc: float, hull_rate: float) -> float:
        omega = float(local_fit(self.t, self.psi, tc, half_width=RATE_HALF_WIDTH, degree=RATE_DEGREE)[1])
        return 0.5 * self.J_f * (hull_rate + omega) ** 2

    def _cumulative_work(self) -> np.ndarray:
        """Motor work from the first sample to each sample, J (the form chosen by ``work``)."""
        t, i = self.t, self.i
        if self.work == "reaction":  # work of the motor's reaction on the hull: -(k_t i - M_f) dphi
            return reaction_work(t, self.interval_current(i), self.torque_scale, self.phi_s, self.psi_s, self.k_t,
                                 self.f_visc, self.f_coul)
        i_mid = self.torque_scale * self.interval_current(i)
        dpsi = np.diff(self.psi_s)
        if self.work == "current":
            steps = self.k_t * i_mid * dpsi
        else:
            u_offset = _voltage_offset(t[self.free], self.psi[self.free], self.rec["u"][self.free])
            steps = _electric_work_steps(t, self.rec["u"] - u_offset, i, self.R, self.L)
        return np.concatenate([[0.0], np.cumsum(steps)])

    def interval_current(self, i: np.ndarray) -> np.ndarray:
        """Mean current over each sample interval (A) from a current series on the record's grid.

        When the flywheel's balance measured the current channel's lag (see
        :func:`_flywheel_calibration`), the series is shifted by it and the trapezoid is the
        rule (the lag also takes up how the DAQ sampled the current); otherwise the record's
        ``current_sampling`` and ``L`` decide (:func:`interval_mean_current`).
        """
        t = self.t
        if self.calibrated:
            shifted = np.interp(t + self.current_lag, t, i)
            return 0.5 * (shifted[1:] + shifted[:-1])
        return interval_mean_current(t, i, self.R, self.L, self.current_sampling)

    @property
    def calibrated(self) -> bool:
        """Whether the torque and the current's lag come from the flywheel's balance."""
        return self.torque_scale != 1.0 or self.current_lag != 0.0

    def _cumulative_bearing_work(self) -> np.ndarray:
        """Work of the rotor-bearing friction on the flywheel from the first sample, J."""
        omega = np.gradient(self.psi, self.t)
        steps = -(self.f_visc * omega[:-1] + self.f_coul * np.sign(omega[:-1])) * np.diff(self.psi)
        return np.concatenate([[0.0], np.cumsum(steps)])


def interval_mean_current(t: np.ndarray, i: np.ndarray, R: float, L: float,
                          sampling: str = "instant") -> np.ndarray:
    """Mean current over each sample interval, A, from the logged current samples.

    ``sampling`` is the record's ``rig.current_sampling``: ``held-previous`` (a sample is the
    value over the interval before it) and ``held-next`` (over the interval after it) say
    it outright. For ``instant`` samples (the default), a drive holds its voltage over a sample, so inside it the current relaxes exponentially
    with ``tau = L / R`` (physics.md section 2). Its mean is then
    ``i_ss + (i0 - i1) tau / h`` with ``i_ss = (i1 - a i0) / (1 - a)``, ``a = exp(-h / tau)``:
    0.42 i0 + 0.58 i1 for ``tau = h``, not the trapezoid's 0.5 / 0.5 (the trapezoid leaves
    about 0.01 % of lambda66 in the reaction work). With ``L`` unknown (0) the trapezoid
    is used: it assumes nothing about the drive.
    """
    if sampling == "held-previous":
        return i[1:].astype(float)
    if sampling == "held-next":
        return i[:-1].astype(float)
    if not L > 0.0:
        return 0.5 * (i[1:] + i[:-1])
    tau = L / R
    t, i = np.asarray(t, dtype=float), np.asarray(i, dtype=float)
    if t.ndim != 1 or i.shape != t.shape:  # numpy's broadcasting (and errors) for anything but two series
        h = np.diff(t)
        a = np.exp(-h / tau)
        i_ss = (i[1:] - a * i[:-1]) / (1.0 - a)
        return i_ss + (i[:-1] - i[1:]) * tau / h
    decay = negative_step_ratios(t, tau)  # -h / tau, then exp(-h / tau) in place (numpy's exp)
    np.exp(decay, out=decay)
    return relaxed_interval_means(t, i, decay, tau)


def _smooth_by_phase(rec: RunRecord, *angles: np.ndarray, cuts: np.ndarray | None = None) -> list[np.ndarray]:
    """Encoder angles smoothed within each contiguous block of one phase and brake state.

    The work sum ``sum(torque_k * dphi_k)`` is biased where the torque reacts to the same
    quantisation errors as the increments (a controller's feedback does): the smoothing
    must reject the quantisation's high frequencies well. A quintic over 0.2 s leaves
    about 1e-6 J of that correlation on the reverse stroke (a cubic over 40 ms: 3e-5 J,
    0.03 % of lambda66), while following the stroke itself (period 3-6 s) exactly. ``cuts``: the
    record's :func:`phase_blocks` when already known.
    """
    if cuts is None:
        cuts = phase_blocks(rec)
    out = [np.empty(len(angle), dtype=float) for angle in angles]
    for a, b in zip(cuts[:-1], cuts[1:]):
        smoothed = smooth_angles(rec.t[a:b], [angle[a:b] for angle in angles], window_s=WORK_SMOOTHING_S, degree=5)
        for o, x in zip(out, smoothed):
            o[a:b] = x
    return out


def phase_blocks(rec: RunRecord, starts: np.ndarray | None = None) -> np.ndarray:
    """Boundaries of the record's contiguous blocks of one phase and one brake state: sample
    indices ``[0, ..., len]`` (block ``j`` is ``cuts[j]:cuts[j + 1]``). ``starts``: the first sample of
    each phase block (:func:`~addedinertia_env.scan_kernels.block_starts` of ``phase``) when known."""
    n = len(rec.phase)
    if starts is None:
        starts = block_starts(rec.phase)
    inner = np.asarray(starts, dtype=np.int64)[1:]
    if "brake" in rec.samples:
        b = np.asarray(rec["brake"], dtype=float)
        if b.ndim != 1 or len(b) != n:  # numpy's broadcasting (and its error) as the masks compared it
            change = np.zeros(max(n - 1, 0), dtype=bool)
            change[inner - 1] = True
            change |= (b[1:] != b[:-1]) & ~(np.isnan(b[1:]) & np.isnan(b[:-1]))
            inner = np.nonzero(change)[0] + 1
        else:
            inner = np.union1d(inner, value_change_starts(b))
    return np.concatenate([[0], inner, [n]]).astype(np.int64)


def _first_blocks(rec: RunRecord, blocks=None) -> tuple[dict[str, slice], np.ndarray]:
    """The first contiguous block of each phase (what :func:`~.common.segment` gives, for every
    phase from one scan), and every phase block's first sample (:func:`phase_blocks` takes them).
    ``blocks``: the blocks' first samples and labels when already known (the plausibility check's)."""
    phase = np.asarray(rec.phase)
    if blocks is None:
        starts = block_starts(phase)
        labels = phase[starts].tolist()
    else:
        starts, labels = np.array(blocks[0], dtype=np.int64), blocks[1]
    first: dict[str, slice] = {}
    bounds = starts.tolist() + [len(phase)]
    for a, b, label in zip(bounds, bounds[1:], labels):
        first.setdefault(str(label), slice(a, b))
    return first, starts


def _n_samples(dt_median: float, span_s: float) -> int:
    """Samples in ``span_s`` seconds at the record's median sample interval ``dt_median`` (s)."""
    return int(round(span_s / dt_median))


def _flywheel_calibration(t, theta, psi, i, a: int, b: int, J_f: float, k_t: float, f_visc: float,
                          f_coul: float) -> tuple[float, float] | None:
    """Torque per logged ampere relative to ``k_t`` (scale) and the current channel's lag (s),
    from the flywheel's own balance ``J_f theta'' = s k_t i(t - lag) - M_f`` (physics.md s8).

    ``theta = phi + psi`` is the flywheel's absolute angle; over samples ``a..b`` (the end of
    the hold and the reverse stroke, where the motor drives) it is fitted, twice integrated,
    by least squares for each lag on a 0.25 ms grid (refined by a parabola). ``J_f`` and the
    rotor friction come from the rig block: the flywheel's inertia is what calibrates the
    torque, so a current-sensor gain error or a torque constant off its data sheet, and a
    current channel that lags the encoders, no longer enter the motor's work. None when the
    span is too short, the fit is poor (residual over 1e-3 rad rms: friction or offset not
    as stated over a long hold), or the lag is not pinned to :data:`LAG_PRECISION` of a
    sample: a current without fast changes (an ideal tracking controller's) lets a lag
    and a scale trade off, and the fit then lands a few ms and half a percent off.
    """
    if b - a < 200:
        return None
    tt, th = t[a:b + 1], theta[a:b + 1]
    # the angle the fit explains (kept for the final fit): th + the friction's torque (from psi, already
    # smoothed phase by phase) twice integrated over J_f; and the half sample intervals
    target, half_dtt = calibration_target(tt, th, psi[a:b + 1], float(f_visc), float(f_coul), float(J_f))
    y = target

    def twice(x):  # trapezoid integral of the integral, from 0, along the last axis
        return twice_integrated(np.atleast_2d(x), half_dtt).reshape(np.shape(x))

    lags = np.arange(-2e-3, MAX_LAG_S + 1e-9, 2.5e-4)
    # Least squares on (1, t - t_a, the lagged current's column), every lag at once: the first two
    # columns are shared, so they are projected out (twice, for orthogonality to rounding;
    # fit_kernels.project_out_line) and each lag's column is then a one-column fit.

    Q = line_basis(tt)

    def projected(x):  # the rows with the first two columns projected out
        return project_out_line(np.atleast_2d(x), Q).reshape(np.shape(x))

    y = projected(y)
    rss = _lag_rss(t, i, a, b, lags, twice, projected, Q, y)  # k_t / J_f leaves the residuals
    j = int(np.argmin(rss))
    if not 0 < j < len(lags) - 1 or np.sqrt(rss[j] / len(tt)) > 1e-3:
        return None
    den = rss[j - 1] - 2 * rss[j] + rss[j + 1]
    step = lags[1] - lags[0]
    sigma_lag = float(np.sqrt(2.0 * rss[j] / (len(tt) - 3) * step**2 / den)) if den > 0 else np.inf
    if sigma_lag > LAG_PRECISION * float(median_step(tt)):
        return None  # a smooth current: lag and scale trade off against each other
    frac = 0.5 * (rss[j - 1] - rss[j + 1]) / den if den > 0 else 0.0
    lag = float(lags[j] + frac * (lags[1] - lags[0]))
    # the third coefficient of the fit on (1, t - t_a, z) by the projection theorem (y is projected already)
    z = projected(k_t * twice(np.interp(tt + lag, t, i)) / J_f)
    scale = float((z @ y) / (z @ z))
    if not 0.5 < scale < 2.0:
        return None
    return scale, lag


def _lag_rss(t, i, a, b, lags, twice, projected, Q, y):
    """Residual sum of squares of the one-column fit ``y ~ c z_lag`` for every lag, where
    ``z_lag = projected(twice(np.interp(t[a:b + 1] + lag, t, i)))`` (the calibration's lagged current,
    twice integrated and projected; ``y`` projected already); the residuals of the lags that can be
    the best one or its neighbours are formed explicitly (no cancellation), the others only bounded.

    On an evenly sampled stretch each lag's row blends two whole-sample shifts (:func:`_lagged_twice`),
    so the ~16 shifts ``B`` are twice integrated but not projected: with ``P = I - Q Q^T`` (``Q``: the
    projection's :func:`~.fit_kernels.line_basis`), ``z.y`` and ``z.z`` follow for every lag from ``B y`` and
    ``B B^T - (B Q)(B Q)^T``, ``|y|^2 - (z.y)^2 / z.z`` ranks the lags, and the rows within rounding of
    the smallest (and their neighbours) are formed, projected and summed. Otherwise (or if the ranking
    is not clear-cut) every row is formed."""
    blended = _lagged_twice(t, i, a, b, lags, twice, blend=False)
    if blended is None:
        return _explicit_rss(_lagged_twice(t, i, a, b, lags, lambda x: projected(twice(x))), y)
    base, k, frac = blended
    BQ = base @ Q
    rss, rows = lag_ranking(base @ y, base @ base.T - BQ @ BQ.T, k, frac, float(y @ y))
    g = 1.0 - frac
    Z = projected(g[rows, None] * base[k[rows]] + frac[rows, None] * base[k[rows] + 1])
    rss[rows] = _explicit_rss(Z, y)
    j = int(np.argmin(rss))
    formed = set(rows.tolist())
    if all(r in formed for r in (max(j - 1, 0), j, min(j + 1, len(lags) - 1))):
        return rss
    return _explicit_rss(_lagged_twice(t, i, a, b, lags, lambda x: projected(twice(x))), y)


def _explicit_rss(Z: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per row of ``Z``: the residual sum of squares of ``y ~ c z`` (least squares), residuals formed explicitly."""
    zz = np.einsum("ij,ij->i", Z, Z)
    coef = (Z @ y) / np.where(zz > 0, zz, np.inf)
    r = y[None, :] - coef[:, None] * Z
    return np.einsum("ij,ij->i", r, r)


def _lagged_twice(t: np.ndarray, i: np.ndarray, a: int, b: int, lags: np.ndarray, linear, blend: bool = True):
    """``linear(np.interp(t[a:b + 1] + lag, t, i))`` for every lag (rows), for a map ``linear``
    acting row by row (the calibration's double integral and projection).

    On an evenly sampled stretch (intervals equal to 1e-9), the current at ``t + lag`` is the
    blend ``(1 - f) i[k + n] + f i[k + n + 1]`` of two whole-sample shifts, and the map is
    linear: so only the ~16 whole-sample shifts are mapped and each lag blends two of them
    (equal to interpolating first, to float rounding). Otherwise every lag is interpolated.
    With ``blend=False``: the shifts' rows ``B``, each lag's first row ``k`` and weight ``f`` (row
    ``(1 - f) B[k] + f B[k + 1]``) on an evenly sampled stretch, None otherwise.
    """
    m = b + 1 - a
    dt = (t[b] - t[a]) / max(m - 1, 1)
    steps = lags / dt
    n = np.floor(steps + 1e-9).astype(np.int64)
    frac = np.clip(steps - n, 0.0, 1.0)
    lo, hi = a + int(n.min()), b + int(n.max()) + 1
    if lo >= 0 and hi < len(t) and m > 1:
        d = np.diff(t[lo:hi + 1])
        if np.max(np.abs(d - dt)) <= 1e-9 * dt:
            shifts = np.arange(int(n.min()), int(n.max()) + 2)
            # the shifted copies as one strided view: row r is i[a + shifts[r]:a + shifts[r] + m]
            base = linear(np.lib.stride_tricks.sliding_window_view(i[a + shifts[0]:a + shifts[-1] + m], m))
            k = n - shifts[0]
            if not blend:
                return base, k, frac
            return (1.0 - frac)[:, None] * base[k] + frac[:, None] * base[k + 1]
    if not blend:
        return None
    return linear(np.interp(t[a:b + 1][None, :] + lags[:, None], t, i))


def _power_series(coef: np.ndarray, x):
    """``sum(coef[j] x**j)`` at ``x`` (float or array) by Horner's rule, as ``np.polynomial.Polynomial(coef)(x)``
    computes it (``coef[-1] + x * 0``, then ``coef[j] + y * x``), the same numbers."""
    y = coef[-1] + x * 0
    for c in coef[-2::-1]:
        y = c + y * x
    return y


def _power_series_derivative(coef: np.ndarray) -> np.ndarray:
    """Coefficients of the derivative of the power series ``coef`` (``Polynomial(coef).deriv().coef``)."""
    if len(coef) < 2:
        return coef[:1] * 0
    return np.array([j * coef[j] for j in range(1, len(coef))])


def _crossings_fit(t: np.ndarray, phi: np.ndarray, k: int, span_s: float, q: float):
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


def _quantum(angle: np.ndarray, counts: int) -> float:
    """Encoder step, rad: from the counts per turn, or the smallest step seen when not given."""
    if counts:
        return 2.0 * np.pi / float(counts)
    steps = np.abs(np.diff(angle))
    steps = steps[steps > 0]
    return float(np.min(steps)) if len(steps) else 0.0


def _forward_damping_law(rec: RunRecord, free: slice, k2: int, J_total: float, c: float,
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
    return {"J": J_total, "d1": max(d1, 0.0), "d2": d2}


class _DissipationMismatch:
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

    def __call__(self, phi1):
        """(dW, sigma) at the angle(s) ``phi1``, J: floats for a float, arrays for an array."""
        dW = self.direction * (np.interp(self.phi2, self.grid, self.cum) - np.interp(phi1, self.grid, self.cum))
        if np.ndim(dW) == 0:
            return float(dW), 0.5 * abs(float(dW))
        return dW, 0.5 * np.abs(dW)


def _voltage_offset(t: np.ndarray, psi: np.ndarray, u: np.ndarray) -> float:
    """Intercept of the terminal voltage against the flywheel rate on an open-circuit stroke, V."""
    omega = np.gradient(smooth_angle(t, psi), t)
    X = np.column_stack([np.ones_like(omega), omega])
    coef, *_ = np.linalg.lstsq(X, u, rcond=None)
    return float(coef[0])


def _electric_work_steps(t: np.ndarray, u: np.ndarray, i: np.ndarray, R: float, L: float) -> np.ndarray:
    """Electric energy minus ohmic loss and the change of magnetic energy per sample, J (the patent's form).

    A drive holds its terminal voltage over each sample, so the current inside a sample is
    the exponential ``L di/dt = u - R i - k_e Omega`` with ``tau = L / R``; trapezoids on
    ``u i`` and ``R i^2`` are off by percents when ``tau`` is near the sample period. Here each
    sample's exponential is rebuilt from its two end currents, and the voltage recorded at
    a sample's end is taken as the one held over it.
    """
    h = np.diff(t)
    tau = L / R
    a = np.exp(-h / tau)
    i0, i1 = i[:-1], i[1:]
    i_ss = (i1 - a * i0) / (1.0 - a)
    d = i0 - i_ss
    mean = i_ss + d * tau / h * (1.0 - a)
    mean_sq = i_ss**2 + 2.0 * i_ss * d * tau / h * (1.0 - a) + d**2 * tau / (2.0 * h) * (1.0 - a * a)
    return u[1:] * mean * h - R * mean_sq * h - 0.5 * L * (i1**2 - i0**2)
