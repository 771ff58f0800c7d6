"""The energy method's gearhead loss, identified on the flywheel's own balance (issue 28).

Through a gearbox (the record's ``rig.gear_ratio`` > 1) part of the motor's torque never
reaches the flywheel: the mesh friction ``c |k_t i| sgn(Omega)`` (``c = 1 - efficiency``) and
the no-load drag ``d sgn(Omega)`` (``Omega`` the flywheel's rate relative to the hull). Both are
friction between the hull (which carries the gearhead's housing) and the flywheel, so the hull
receives ``-(s k_t i - M_f - (c |k_t i| + d) sgn(Omega))``, not the ``-(s k_t i - M_f)`` the
method books without them: the loss's work on the hull is left out, and the torque scale ``s``
calibrated on the flywheel's balance (:mod:`.energy_calibration`) takes up the loss of the
quadrant the span holds most of (docs/DRIVE.md, docs/ENERGY_METHOD.md "The drive's flaws").

Here the flywheel's balance ``J_f theta'' = s k_t i(t + lag) - M_f - (c k_t |i| + d) sgn(Omega)``
(``theta = phi + psi``; the lag the calibration found) is fitted, twice integrated, over the
calibration's span (the last second of the hold and the reverse stroke), with the columns
``(1, t)`` (the angle and rate at the span's start), the current, the mesh column and the drag column, by least squares. The energy method
then books the scale ``s`` and the loss torque in its reaction work
(:meth:`.energy_balance.RunBalance._cumulative_work`). Where the span holds one quadrant only
(the current drives the flywheel, or only brakes it), ``c`` and ``s`` cannot be told apart: the
mesh column is dropped and the net torque ``s' k_t i`` is what the span shows, which is what
the work over that span needs. Where no current flows (``zero``) nothing is booked
(:data:`MIN_CURRENT_SAMPLES`).

Only the record's samples and its ``rig`` block are used, never ``truth``. Records without a
gearbox (``gear_ratio`` absent or 1) are not touched: the method's numbers on them are the same,
bit for bit (``tests/test_energy_gear.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addedinertia_env.identify.rotor_friction import ROTOR_COULOMB_RATE_SCALE
from addedinertia_env.identify.series_kernels import calibration_target, twice_integrated

# rad/s: the loss's sign is the flywheel's rate's, smoothed over this rate. Not the rotor bearing's 1e-4
# (rotor_friction.py): a flywheel at rest through a hold reads rates of order 1e-3 rad/s from its 14-bit
# encoder, whose sign a dry friction at rest does not follow (it sticks); at 1e-2 that noise gives it
# under a tenth of its torque, and the stroke's rates (1-20 rad/s) the whole of it.
GEAR_RATE_SCALE = 1e-2
MIN_QUADRANT_FRACTION = 0.05  # each quadrant (current driving, braking) must hold this share of the span's |current|
# rad: a balance the losses leave worse than this is not read. Ten times the calibration's 1e-3: the motor's
# cogging, which the fit does not model, leaves up to 4e-3 rad where a plan without pre-spin turns the flywheel
# slowly through its cycles (drive-v1's tuning split, `oracle`), and the loss fitted beside it is still the loss.
MAX_FIT_RMS = 1e-2
MIN_CURRENT = 0.1  # A: a sample counts for a quadrant where the current exceeds this (sensor noise: a few mA)
MIN_CURRENT_SAMPLES = 50  # fewer samples with current: no drive current, nothing is booked
MIN_SPAN_SAMPLES = 400


@dataclass(frozen=True)
class GearLoss:
    """The gearhead's loss fitted on the flywheel's balance (see module doc)."""

    scale: float  # torque per logged ampere relative to the rig block's k_t (the calibration's, refitted beside the loss)
    mesh: float  # c = 1 - mesh efficiency (0 where the span cannot tell it from the scale)
    drag: float  # N m at the flywheel
    mesh_se: float
    drag_se: float
    rms_rad: float
    both_quadrants: bool

    def torque(self, k_t: float, i_mean: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """The loss torque on the flywheel (N m, against its rate relative to the hull) for the
        interval currents ``i_mean`` (A) and rates ``omega`` (rad/s)."""
        return -(self.mesh * k_t * np.abs(self.scale * i_mean) + self.drag) * np.tanh(omega / GEAR_RATE_SCALE)


def gear_loss_fit(t: np.ndarray, theta: np.ndarray, psi_s: np.ndarray, i: np.ndarray, a: int, b: int,
                  J_f: float, k_t: float, f_visc: float, f_coul: float, lag: float,
                  fixed_scale: float = 1.0) -> GearLoss | None:
    """The gearhead's loss over samples ``a..b`` (see module doc), or None when the span is too short
    or the balance with the loss in it still leaves more than :data:`MAX_FIT_RMS` rad rms."""
    if b - a < MIN_SPAN_SAMPLES:
        return None
    tt = t[a:b + 1]
    target, half = calibration_target(tt, theta[a:b + 1], psi_s[a:b + 1], float(f_visc), float(f_coul), float(J_f),
                                      ROTOR_COULOMB_RATE_SCALE)
    omega = np.gradient(psi_s, t)[a:b + 1]
    sg = np.tanh(omega / GEAR_RATE_SCALE)
    ii = np.interp(tt + lag, t, i)

    def twice(x):
        return twice_integrated(np.atleast_2d(np.asarray(x, float)), half).reshape(np.shape(x)) / J_f

    cur, mesh, drag = k_t * twice(ii), -k_t * twice(np.abs(ii) * sg), -twice(sg)
    flows = np.abs(ii) > MIN_CURRENT  # the sensor's noise (mA) is no quadrant
    driving = float(np.sum(np.abs(ii)[flows & (ii * omega > 0)]))
    braking = float(np.sum(np.abs(ii)[flows & (ii * omega < 0)]))
    total = driving + braking
    both = total > 0 and min(driving, braking) >= MIN_QUADRANT_FRACTION * total
    if np.count_nonzero(flows) < MIN_CURRENT_SAMPLES:
        # no drive current (`zero`): no mesh loss, and the drag alone is not read. On a passive flywheel
        # the relative rate is the hull's, slow near the strokes' ends, where the motor's cogging (not
        # modelled here) dominates its balance: on drive-v1's 16 tuning scenarios the drag fitted so came
        # out 0.7-4 times the true one (rms 1e-3 .. 9e-3 rad), worse than leaving it out.
        return None
    one, ramp = np.ones_like(tt), tt - tt[0]
    fit = _fit(target, [one, ramp, cur] + ([mesh] if both else []) + [drag])
    if fit is not None and 0.5 < fit[0][2] < 2.0:
        coef, se, rms = fit
        scale = float(coef[2])
        m, m_se = (float(coef[3]), float(se[3])) if both else (0.0, math.inf)
        d, d_se = float(coef[-1]), float(se[-1])
    else:
        # the current does not pin its own scale (too little of it, or a scale off by half): the scale is
        # held at ``fixed_scale`` (the calibration's, or the rig block's 1) and the drag (with the mesh
        # where both quadrants are seen) is what the balance tells
        scale = float(fixed_scale)
        fit = _fit(target - scale * cur, [one, ramp] + ([mesh] if both else []) + [drag])
        if fit is None:
            return None
        coef, se, rms = fit
        m, m_se = (float(coef[2]) / scale, float(se[2]) / scale) if both else (0.0, math.inf)
        d, d_se = float(coef[-1]), float(se[-1])
        return GearLoss(scale=scale, mesh=m, drag=d, mesh_se=m_se, drag_se=d_se, rms_rad=rms, both_quadrants=both)
    # the mesh coefficient is relative to the scaled current (c |s k_t i|)
    return GearLoss(scale=scale, mesh=m / scale, drag=d, mesh_se=m_se / abs(scale), drag_se=d_se, rms_rad=rms,
                    both_quadrants=both)


def _fit(target: np.ndarray, cols: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Least squares of ``target`` on ``cols``: coefficients, their standard errors (white residuals) and
    the residual's rms (rad); None where the rms exceeds :data:`MAX_FIT_RMS`."""
    A = np.column_stack(cols)
    norm = np.linalg.norm(A, axis=0)
    norm[norm == 0] = 1.0
    As = A / norm
    c, *_ = np.linalg.lstsq(As, target, rcond=None)
    r = target - As @ c
    rms = math.sqrt(float(r @ r) / len(r))
    if not rms <= MAX_FIT_RMS:
        return None
    dof = max(len(r) - A.shape[1], 1)
    cov = np.linalg.pinv(As.T @ As) * float(r @ r) / dof
    se = np.sqrt(np.maximum(np.diag(cov), 0.0)) / norm
    return c / norm, se, rms
