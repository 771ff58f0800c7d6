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
over the end of the hold and the reverse stroke (:func:`~.energy_calibration.flywheel_calibration`; physics.md
section 8): the flywheel's inertia, not the data-sheet ``k_t`` or the current sensor's gain,
then sets the scale of the motor's work, and a lagging current channel is shifted back. When
the current has too few fast changes to pin the lag (an ideal tracking controller's), the
rig block's ``k_t`` and the record's ``current_sampling`` are used as they stand. Only the record's samples and its ``rig`` block are
used; never ``truth``. ``rig.L`` may be 0 or absent: the reaction form does not need it.

The method's parts, one subject each: :mod:`.energy_balance` (the terms at a boundary angle,
:class:`RunBalance`), :mod:`.energy_pooling` (many angles to one run's value), :mod:`.energy_work`
(the motor work), :mod:`.energy_calibration` (torque and current lag on the flywheel),
:mod:`.energy_rest` (the rest angles at t2 and t3) and :mod:`.energy_dissipation` (the damping
law and the dissipation mismatch); this module pools the runs.
"""

from __future__ import annotations

import warnings

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.identify.common import IdentificationError, Result, pooled_interval
# The balance, its motor work, calibration, rest angles, dissipation law and pooling are modules of
# their own (identify/energy_*.py); the names other modules and tests use are importable from here too.
from addedinertia_env.identify.energy_balance import (  # noqa: F401
    CALIBRATED_TORQUE_UNCERTAINTY,
    CURRENT_GAIN_UNCERTAINTY,
    MAX_SATURATED_FRACTION,
    MAX_SPEED_MISMATCH,
    RATE_DEGREE,
    RATE_HALF_WIDTH,
    BalanceTerms,
    Interval,
    RunBalance,
    inertia_from_terms,
)
from addedinertia_env.identify.energy_calibration import LAG_PRECISION, MAX_LAG_S  # noqa: F401
from addedinertia_env.identify.energy_dissipation import DAMPING_FIT_WINDOW_S  # noqa: F401
from addedinertia_env.identify.energy_pooling import (
    DEFAULT_FRACTIONS,
    DENSE_ANGLES,
    run_estimate,
    hann_weights,
    prepared_balance,
)  # noqa: F401
from addedinertia_env.identify.energy_rest import REST_FIT_S  # noqa: F401
from addedinertia_env.identify.energy_work import WORK_SMOOTHING_S, interval_mean_current, phase_blocks  # noqa: F401

WORK_FORMS = ("reaction", "current", "electric")
DIAGNOSTIC_FORM_WARNING = (
    "energy method, work={work!r}: a diagnostic form; it books the flywheel's energy (tens of J) "
    "against the hull's (under 1 J), so current-gain, R and flywheel-rate errors are multiplied "
    "about 100-fold: expect about 1 % of error with a calibrated current sensor and several % with "
    "a 0.5 % gain error (docs/ENERGY_METHOD.md). Use work='reaction' for the estimate.")


def identify_energy(records: list[RunRecord], work: str = "reaction", fractions=DEFAULT_FRACTIONS,
                    asymmetry_correction: bool = True, interval_details: bool = True) -> Result:
    """lambda66 (kg m^2) from one or more reverse-symmetric runs, with a 95 % interval.

    ``fractions``: the range ``(lo, hi)`` of boundary angles as fractions of the stroke
    (dense Hann-weighted average), or a list of three or more fractions to evaluate
    separately and pool by inverse variance. A record's own ``experiment.phi1`` list wins.
    ``interval_details=False``: the result's ``details`` leave out the per-angle ``intervals``
    (the same lambda66, interval and counts; a caller that only needs the numbers, such as
    the batched env scoring every episode, skips building a record per angle).
    Each record's typed rig and phase blocks are its views (``record.views``), derived once.
    """
    if work not in WORK_FORMS:
        raise ValueError(f"work={work!r}: expected one of {WORK_FORMS}")
    if work != "reaction":
        warnings.warn(DIAGNOSTIC_FORM_WARNING.format(work=work), stacklevel=2)
    runs = [run_estimate(rec, work, fractions, asymmetry_correction, interval_details) for rec in records]
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
               "per_run_sigma_parts": [r.parts for r in good],
               "per_run_torque_scale": [r.torque_scale for r in good],
               "rejected": n_all - n_good}
    if interval_details:
        details["intervals"] = [iv.__dict__ for iv in intervals]
    return Result(method="energy", lambda66=value, ci95=(lo, hi), n_intervals=n_good, details=details)
