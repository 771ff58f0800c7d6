"""The motor's cogging, identified on the flywheel's own balance and booked in the energy method (issue 28).

A motor's cogging torque ``T(psi) = A sin(m psi) + B cos(m psi)`` (at the flywheel, ``psi`` its angle
relative to the hull, ``m = n N`` for ``n`` cycles per motor turn through the gear ratio ``N``) acts
between rotor and stator, like the winding's torque, but the current does not show it: the reaction
work the method books, ``-(s k_t i - M_f) dphi``, leaves out ``-T(psi) dphi``. Over an interval where
``phi`` and ``psi`` move linearly that is ``(dphi / dpsi) (U(psi_1) - U(psi_0))`` with the potential
``U = (A cos(m psi) - B sin(m psi)) / m``: a potential difference, so where the rotor turns through many
cycles it averages out, and what is left depends on where the plan leaves the rotor (docs/DRIVE.md).

The torque is fitted on the flywheel's twice-integrated balance
``J_f theta'' = s k_t i(t + lag) - M_f - loss + T(psi)`` (as :mod:`.energy_gear` fits the loss) over the
span the caller gives; the energy method gives it the whole record from the start of the free stroke to
the end of the reverse stroke (``energy_balance.COGGING_SPAN``): in the free stroke the motor is open and
the hull carries the flywheel through the cogging's detent and the gearhead's drag, which is where the
cogging's work on the hull is done on drive-v1 (docs/DRIVE.md, "drive-v1 with the cogging booked"). The
columns are the loss's (angle and rate at the span's start, current, mesh where both quadrants are seen,
drag) and ``sin, cos(m psi)``; the loss fitted beside the cogging is returned too (:attr:`Cogging.loss`),
and the method books it in place of the calibration-span one (``energy_balance.COGGING_LOSS``). ``n`` is
not in the rig block: it is searched over :data:`PERIODS` (as discovery's ``cogging`` word,
``discover/drive_flaws.py``), and the best ``n`` is booked only where the records show it (the evidence
discovery asks for, per record):

* its drop of the residual sum of squares stands out of the other periods' (their median, the null's
  scale: whatever colour the twice-integrated residual has lifts every period alike) by the chi-square
  (2 degrees of freedom) at family-wise false-alarm rate :data:`FALSE_ALARM`;
* its amplitude is clear of :data:`MIN_AMPLITUDE` by :data:`AMPLITUDE_SE` standard errors.

Where the rotor turns through a cycle in fewer than :data:`MIN_SAMPLES_PER_CYCLE` samples the sampled
angle aliases it; the columns taper it out there (the flywheel's inertia filters it anyway), and the
booked work takes the torque's exact mean over each sample interval (linear motion inside it), which
averages such cycles to nearly nothing, as the physics does.

Nothing is booked where no drive current flows (``zero``: as :mod:`.energy_gear` books no loss there).

The span holds 1.5-2 motor turns on drive-v1, so neighbouring periods fit nearly alike and the one found
may be off (the true 24 on 19 of 36 records tried); what the booked work needs is the torque near where
the flywheel sat. Its uncertainty, in the interval's common part: the coefficients' covariance
(white-residual formula inflated for the residual's correlation from sample to sample; the work is linear
in ``(A, B)``) plus the spread of the works the next :data:`ALTERNATIVES` periods would book (covered 26
of 36, docs/ENERGY_METHOD.md). Only the record's samples and its ``rig`` block are used, never ``truth``.
Records without a gearbox are not scanned (bit for bit as before, ``tests/test_energy_cogging.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from addedinertia_env.identify.cogging_periods import PeriodScan
from addedinertia_env.identify.energy_gear import GearLoss
from addedinertia_env.identify.rotor_friction import ROTOR_COULOMB_RATE_SCALE
from addedinertia_env.identify.series_kernels import calibration_target, twice_integrated

PERIODS = range(4, 121)  # cycles per motor turn searched (lcm of slots and poles: 6 to 72 on small motors)
FALSE_ALARM = 1e-4  # family-wise over PERIODS (discovery's COGGING_FALSE_ALARM)
MIN_AMPLITUDE = 0.005  # N m at the flywheel (discovery's MIN_COGGING: about 0.5 % of lambda66, docs/DRIVE.md)
AMPLITUDE_SE = 2.0  # the amplitude clear of MIN_AMPLITUDE by this many standard errors
MIN_CYCLES = 3.0  # the rotor must turn through this many (seen) cycles of a period for it to be judged
MIN_SAMPLES_PER_CYCLE = 8  # a cycle spanning fewer samples is tapered out of the columns (aliasing)
MIN_SPAN_SAMPLES = 400
ALTERNATIVES = 4  # the next best periods whose booked works' spread is the model's uncertainty
MIN_PERIODS_FOR_NULL = 20  # the null's scale needs this many other periods judged
GEAR_RATE_SCALE = 1e-2  # rad/s, the loss column's sign smoothing (as energy_gear.GEAR_RATE_SCALE)
MIN_CURRENT = 0.1  # A, a sample counts for a quadrant above this (as energy_gear)
MIN_CURRENT_SAMPLES = 50  # fewer samples with current: no drive current, nothing is booked (as energy_gear)
MIN_QUADRANT_FRACTION = 0.05


@dataclass(frozen=True)
class Cogging:
    """The cogging torque fitted on the flywheel's balance (see module doc)."""

    periods: int  # n, cycles per motor turn
    m: float  # rad^-1 at the flywheel, n * gear_ratio
    coef: np.ndarray  # (A, B), N m at the flywheel: T = A sin(m psi) + B cos(m psi)
    cov: np.ndarray  # their covariance, (N m)^2
    drop_ratio: float  # the best period's drop over the null's scale
    threshold: float  # what it had to exceed
    rms_rad: float  # the balance's residual with the cogging in it
    loss: GearLoss | None = None  # the gearhead's loss fitted beside it (None: its scale off by half or more)
    # the next best periods' torques, (m, (A, B)): where the rotor turns through a few motor turns only,
    # neighbouring periods fit nearly alike, and the spread of their booked works is the model's uncertainty
    alternatives: tuple[tuple[float, np.ndarray], ...] = ()

    def cumulative_work(self, psi: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """The hull's cumulative cogging work from the first sample (J), its basis (:meth:`cumulative_basis`,
        for the coefficients' covariance) and, per alternative period, its cumulative work minus this one's."""
        basis = self.cumulative_basis(psi, phi)
        work = self.coef @ basis
        alt = [coef @ replace(self, m=m).cumulative_basis(psi, phi) - work for m, coef in self.alternatives]
        return work, basis, alt

    @property
    def amplitude(self) -> float:
        """N m at the flywheel."""
        return float(np.hypot(*self.coef))

    def basis_steps(self, psi: np.ndarray, dphi: np.ndarray) -> np.ndarray:
        """The hull's work per sample interval for a unit ``A`` (row 0) and a unit ``B`` (row 1), J:
        ``-<sin, cos(m psi)> dphi``, ``<.>`` the exact mean over the interval for ``psi`` linear in it."""
        m = self.m
        p0, p1 = psi[:-1], psi[1:]
        d = p1 - p0
        x = m * d
        small = np.abs(x) < 1e-6
        safe = np.where(small, 1.0, x)
        mean_sin = np.where(small, np.sin(0.5 * m * (p0 + p1)), (np.cos(m * p0) - np.cos(m * p1)) / safe)
        mean_cos = np.where(small, np.cos(0.5 * m * (p0 + p1)), (np.sin(m * p1) - np.sin(m * p0)) / safe)
        return -np.vstack([mean_sin, mean_cos]) * dphi

    def cumulative_basis(self, psi: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """:meth:`basis_steps` summed from the first sample, (2, samples), J per N m."""
        steps = self.basis_steps(psi, np.diff(phi))
        return np.concatenate([np.zeros((2, 1)), np.cumsum(steps, axis=1)], axis=1)


def _seen(m: float, dpsi: np.ndarray) -> np.ndarray:
    """The taper of a cycle of ``m`` rad^-1 by how many samples it spans (1: well sampled, 0: aliased)."""
    return 1.0 / (1.0 + (m * dpsi * MIN_SAMPLES_PER_CYCLE / (2 * math.pi)) ** 8)


def _inflation(r: np.ndarray) -> float:
    """The standard errors' inflation for residuals correlated from sample to sample,
    ``sqrt((1 + rho) / (1 - rho))``."""
    rho = float(np.clip((r[1:] @ r[:-1]) / max(float(r @ r), 1e-300), 0.0, 0.99))
    return math.sqrt((1.0 + rho) / (1.0 - rho))



def drops_beside(columns: dict, y: np.ndarray, best) -> list[float]:
    """The residual-sum drop (units of ``y`` squared) each period's columns (``columns``: period -> its
    column pair) still gives once the ``best`` period's columns are projected out of them and of ``y``: what
    every other period fits of what the best one leaves, the null against which the best one must stand out.
    A real cogging leaks into every period (where the rotor creeps, every period's column is slow alike), so
    the null is taken with it removed. Discovery's cogging word uses it (discover/drive_flaws.py); the fit
below takes the same drops in one pass over every period (cogging_periods.PeriodScan.null_drops)."""
    Qb, _ = np.linalg.qr(columns[best])
    yb = y - Qb @ (Qb.T @ y)
    rest = []
    for n, C in columns.items():
        if n == best:
            continue
        C = C - Qb @ (Qb.T @ C)
        c, *_ = np.linalg.lstsq(C, yb, rcond=None)
        f = C @ c
        rest.append(float(f @ f))
    return rest

def cogging_fit(t: np.ndarray, theta: np.ndarray, psi_s: np.ndarray, i: np.ndarray, a: int, b: int, J_f: float,
                k_t: float, f_visc: float, f_coul: float, lag: float, gear_ratio: float) -> Cogging | None:
    """The cogging over samples ``a..b`` (see module doc), or None where the records do not show it."""
    from scipy.stats import chi2  # noqa: PLC0415

    if b - a < MIN_SPAN_SAMPLES or gear_ratio <= 0:
        return None
    tt = t[a:b + 1]
    target, half = calibration_target(tt, theta[a:b + 1], psi_s[a:b + 1], float(f_visc), float(f_coul), float(J_f),
                                      ROTOR_COULOMB_RATE_SCALE)
    psi = psi_s[a:b + 1]
    omega = np.gradient(psi_s, t)[a:b + 1]
    sg = np.tanh(omega / GEAR_RATE_SCALE)
    ii = np.interp(tt + lag, t, i)

    def twice(x):
        return twice_integrated(np.atleast_2d(np.asarray(x, float)), half).reshape(np.shape(x)) / J_f

    flows = np.abs(ii) > MIN_CURRENT
    if np.count_nonzero(flows) < MIN_CURRENT_SAMPLES:
        # no drive current (`zero`): nothing is booked, as energy_gear books no loss there. The cogging and the
        # gearhead's drag together hold a passive flywheel, and the drag alone is not read there (energy_gear);
        # the cogging booked without it left drive-v1's `zero` worse on 3 of 8 tuning scenarios (mean |e| 1.58 ->
        # 1.69 %, docs/DRIVE.md)
        return None
    driving = float(np.sum(np.abs(ii)[flows & (ii * omega > 0)]))
    braking = float(np.sum(np.abs(ii)[flows & (ii * omega < 0)]))
    both = driving + braking > 0 and min(driving, braking) >= MIN_QUADRANT_FRACTION * (driving + braking)
    one, ramp = np.ones_like(tt), tt - tt[0]
    cols = [one, ramp, k_t * twice(ii)] + ([-k_t * twice(np.abs(ii) * sg)] if both else []) + [-twice(sg)]
    base = np.column_stack(cols)
    Q, _ = np.linalg.qr(base / np.linalg.norm(base, axis=0).clip(1e-300))
    y = target - Q @ (Q.T @ target)
    dpsi = np.abs(np.diff(psi, append=psi[-1]))
    # every period in one pass (cogging_periods.py: a 2-column lstsq's drop per period, to rounding)
    scan = PeriodScan(psi, dpsi, half, J_f, Q, y, gear_ratio, PERIODS, MIN_CYCLES, MIN_SAMPLES_PER_CYCLE)
    drops = scan.drops
    if len(drops) < MIN_PERIODS_FOR_NULL:
        return None
    best = max(drops, key=drops.get)
    rest = scan.null_drops(best)
    null = float(np.median(rest)) / (2.0 * math.log(2.0))  # the median of chi-square 2 is 2 ln 2
    ratio = drops[best] / max(null, 1e-300)
    threshold = float(chi2.isf(FALSE_ALARM / len(drops), 2))
    if not ratio > threshold:
        return None
    # the joint fit: the loss's columns and the best period's, the coefficients' covariance
    m = best * gear_ratio
    A, As, norm, c, r = _joint(base, target, twice, psi, m, _seen(m, dpsi))
    ranked = sorted(drops, key=drops.get, reverse=True)[1:1 + ALTERNATIVES]
    alternatives = []
    for n in ranked:
        m_n = n * gear_ratio
        _, _, norm_n, c_n, _ = _joint(base, target, twice, psi, m_n, _seen(m_n, dpsi))
        alternatives.append((float(m_n), c_n[-2:] / norm_n[-2:]))
    dof = max(len(r) - A.shape[1], 1)
    cov = np.linalg.pinv(As.T @ As) * float(r @ r) / dof * _inflation(r) ** 2
    coef = c[-2:] / norm[-2:]
    cov2 = cov[-2:, -2:] / np.outer(norm[-2:], norm[-2:])
    amp = float(np.hypot(*coef))
    amp_se = float(math.sqrt(max(coef @ cov2 @ coef, 0.0)) / max(amp, 1e-300))
    if amp - AMPLITUDE_SE * amp_se < MIN_AMPLITUDE:
        return None
    full, se = c / norm, np.sqrt(np.maximum(np.diag(cov), 0.0)) / norm
    rms = math.sqrt(float(r @ r) / len(r))
    loss = None
    if 0.5 < full[2] < 2.0:  # the loss's columns as energy_gear fits them: scale, mesh (both quadrants), drag
        scale = float(full[2])
        mesh, mesh_se = (float(full[3]) / scale, float(se[3]) / abs(scale)) if both else (0.0, math.inf)
        loss = GearLoss(scale=scale, mesh=mesh, drag=float(full[-3]), mesh_se=mesh_se, drag_se=float(se[-3]),
                        rms_rad=rms, both_quadrants=both)
    return Cogging(periods=int(best), m=float(m), coef=coef, cov=cov2, drop_ratio=float(ratio),
                   threshold=threshold, rms_rad=rms, loss=loss, alternatives=tuple(alternatives))


def _joint(base, target, twice, psi, m, seen):
    """The least squares of ``target`` on ``base`` and the cogging columns at ``m``: the columns, their
    normalised form, the norms, the normalised coefficients and the residual."""
    A = np.column_stack([base, twice(seen * np.sin(m * psi)), twice(seen * np.cos(m * psi))])
    norm = np.linalg.norm(A, axis=0)
    norm[norm == 0] = 1.0
    As = A / norm
    c, *_ = np.linalg.lstsq(As, target, rcond=None)
    return A, As, norm, c, target - As @ c
