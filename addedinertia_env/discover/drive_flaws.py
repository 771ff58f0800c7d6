"""Discovery's words for the drive's flaws (issue 28), judged on the flywheel's own balance.

The flywheel's balance ``J_f theta'' = s k_t i(t - lag) - M_f + T_drive`` (``theta = phi + psi``,
``M_f`` the rig block's rotor friction) holds no water, so whatever the hull does, a drive
torque the current does not show leaves its own fingerprint there (docs/DISCOVERY.md,
"The drive's flaws"). Over the end of the hold and the reverse stroke of every
reverse-symmetric run (where the motor drives) the balance is fitted, twice integrated (the
residual is then the encoders' own noise, in rad), with columns for

* ``mesh_loss``: a gearhead's mesh friction ``-c |k_t i| sgn(Omega)``, Coulomb friction that
  grows with the transmitted torque (``c = 1 - efficiency``). It takes torque when the motor
  drives the flywheel and gives it when the motor brakes it, so it is told from a torque
  constant off its data sheet (which scales both alike) only where the run has both; a plan
  with one quadrant leaves ``c`` with a large standard error, and nothing is named;
* ``gear_drag``: a drag ``-d sgn(Omega)`` beyond the rig block's rotor friction (a gearhead's
  no-load running torque);
* ``supply_limit`` (:mod:`.supply_limit`): the driver's voltage pinned at the record's supply
  with the back-EMF eating into it (judged on the voltage, not the balance);
* ``cogging``: a torque ``A sin(m psi + phase)`` periodic in the rotor's angle, ``m = n N``
  for ``n`` cycles per motor turn (integer, the lcm of slots and poles) through the record's
  gear ratio ``N``; absent from the current. It is searched over ``n`` =
  :data:`COGGING_PERIODS` with the slow part of the balance (whatever does not repeat with
  the rotor's angle) taken out by a cubic spline in time with knots every
  :data:`SPLINE_KNOT_S`; named where the best ``n``'s fit, summed over the runs, stands
  above the residual noise by a chi-square test at family-wise false-alarm rate
  :data:`COGGING_FALSE_ALARM`.

A word is named where every run that can judge it agrees (the same sign, clear of its
smallest size and of its standard error; for cogging, the runs together). Never reads
``truth``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from addedinertia_env.identify.energy_cogging import drops_beside
from addedinertia_env.records.record import RunRecord

NAMES = ("mesh_loss", "gear_drag", "cogging", "backlash", "supply_limit")

# Smallest sizes named (docs/DISCOVERY.md says why; docs/DRIVE.md gives the bias each causes).
MIN_MESH = 0.03  # -, 1 - mesh efficiency: a precision planetary stage loses at most about 3 %
MIN_DRAG = 0.004  # N m at the flywheel beyond the rig block's rotor friction (2 x wigley-2m's stated 2 mN m)
MAX_LOSS_RMS = 1e-3  # rad: a balance the losses leave worse than this is not theirs (as the energy calibration's)
MIN_Z = 5.0  # size / its standard error (inflated for the residuals' correlation)
COGGING_PERIODS = range(4, 121)  # cycles per motor turn searched (lcm of slots and poles: 6 to 72 on small motors)
MIN_COGGING = 0.005  # N m at the flywheel: the cogging amplitude named (about 0.5 % of lambda66, docs/DRIVE.md)
COGGING_SE = 2.0  # and the amplitude must be clear of it by this many standard errors
COGGING_FALSE_ALARM = 1e-4  # family-wise, over every n searched, with the residuals white after the spline
WHITENING_ORDER = 20  # lags of the autoregressive model whose prediction error whitens the residuals
SPLINE_KNOT_S = 0.1  # s, the knot spacing of the slow part taken out before the cogging search
MIN_COGGING_CYCLES = 3.0  # the rotor must turn through this many cycles of a period for it to be judged
MIN_SAMPLES_PER_CYCLE = 8  # a cogging cycle is judged only where it spans this many samples
HOLD_SPAN_S = 2.0  # s of the hold before the release that the balance covers (a pre-spin lives there)
MIN_BACKLASH = math.radians(0.2)  # rad at the flywheel: "reduced backlash" heads have 0.15-0.5 deg (docs/DRIVE.md)
BACKLASH_SPREAD = 3.0  # the reversals' robust spread, at most this many times their typical standard error
BACKLASH_AGREE = 2.0 / 3.0  # the share of reversals whose rotor travels forward (a gap), at least
WINDING_TOLERANCE = 0.25  # the fitted k_e within 25 % of the rig block's k_t, R within 50 %: else the voltage is not read
BACKLASH_Z = 3.0  # the width / its standard error (a gap is never negative: one-sided)
REVERSAL_HOLD_S = 0.02  # s the current keeps one sign on each side of a reversal that is judged
REVERSAL_MIN_CURRENT = 0.05  # A above the current's noise (3 sigma) for a sign to count
REVERSAL_WINDOW_S = 0.05  # s after the new sign is held over which the crossing's back-EMF is summed
REVERSAL_PRE_S = 0.01  # s before the old sign's last held sample where the sum starts
RATE_WINDOW = 11  # samples of the Savitzky-Golay rate of the flywheel for the back-EMF
LAGS_S = np.arange(-2e-3, 12e-3 + 1e-9, 5e-4)  # the current channel's lag grid (as the energy calibration's)


@dataclass
class Span:
    """One run's flywheel balance over the end of the hold and the reverse stroke."""

    name: str
    t: np.ndarray  # s
    target: np.ndarray  # rad: theta + the stated rotor friction twice integrated over J_f
    psi: np.ndarray  # rad, smoothed flywheel angle relative to the hull
    omega: np.ndarray  # rad/s
    i_full: np.ndarray  # A, the whole record's current (offset removed), for the lag
    t_full: np.ndarray  # s
    half_dt: np.ndarray
    J_f: float
    k_t: float  # N m/A at the flywheel
    gear_ratio: float

    def twice(self, x: np.ndarray) -> np.ndarray:
        """``x`` (rows along the last axis) integrated twice from the span's start, over ``J_f``."""
        from addedinertia_env.identify.series_kernels import twice_integrated  # noqa: PLC0415

        return twice_integrated(np.atleast_2d(np.asarray(x, float)), self.half_dt).reshape(np.shape(x)) / self.J_f

    def current(self, lag: float) -> np.ndarray:
        """The logged current at ``t + lag``, A."""
        return np.interp(self.t + lag, self.t_full, self.i_full)


def span(rec: RunRecord) -> Span | str:
    """The flywheel balance of ``rec`` (a reverse-symmetric run), or why there is none."""
    from addedinertia_env.identify.common import IdentificationError  # noqa: PLC0415
    from addedinertia_env.identify.energy_balance import RunBalance  # noqa: PLC0415
    from addedinertia_env.identify.series_kernels import calibration_target  # noqa: PLC0415
    from addedinertia_env.records.series_stats import median_step  # noqa: PLC0415
    from addedinertia_env.sim.friction import ROTOR_FRICTION_RATE_SCALE  # noqa: PLC0415

    if rec.experiment.get("kind") != "reverse-symmetric":
        return "not a reverse-symmetric run"
    try:
        b = RunBalance(rec.without_truth(), "reaction", False)
    except (IdentificationError, ValueError) as e:
        return f"no flywheel balance: {e}"
    dt = float(median_step(b.t))
    a = max(b.k3 - int(round(HOLD_SPAN_S / dt)), b.hold_start) + 1
    e = b.rev.stop - 1 - int(math.ceil(LAGS_S[-1] / dt)) - 2
    if e - a < 400:
        return f"{e - a + 1} samples of hold and reverse stroke: too few to judge the drive"
    tt = b.t[a:e + 1]
    psi_s = b.psi_s[a:e + 1]
    target, half = calibration_target(tt, (b.phi + b.psi)[a:e + 1], psi_s, float(b.f_visc), float(b.f_coul),
                                      float(b.J_f), ROTOR_FRICTION_RATE_SCALE)
    omega = np.gradient(b.psi_s, b.t)[a:e + 1]
    return Span(name=rec.name, t=tt, target=target, psi=psi_s, omega=omega, i_full=b.i, t_full=b.t,
                half_dt=half, J_f=float(b.J_f), k_t=float(b.k_t), gear_ratio=float(rec.known.gear_ratio))


def _sign(omega: np.ndarray) -> np.ndarray:
    from addedinertia_env.sim.friction import ROTOR_FRICTION_RATE_SCALE  # noqa: PLC0415

    return np.tanh(omega / ROTOR_FRICTION_RATE_SCALE)


def _inflation(r: np.ndarray) -> float:
    """The standard errors' inflation for residuals correlated from sample to sample, ``sqrt((1 + rho) / (1 - rho))``."""
    rho = float(np.clip((r[1:] @ r[:-1]) / max(float(r @ r), 1e-300), 0.0, 0.99))
    return math.sqrt((1.0 + rho) / (1.0 - rho))


def _lstsq(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients, residuals and the coefficients' standard errors (white residuals, inflated)."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    As = A / scale
    c, *_ = np.linalg.lstsq(As, y, rcond=None)
    r = y - As @ c
    dof = max(len(y) - A.shape[1], 1)
    s2 = float(r @ r) / dof
    try:
        cov = np.linalg.pinv(As.T @ As)
    except np.linalg.LinAlgError:
        cov = np.full((A.shape[1], A.shape[1]), np.inf)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0) * s2) * _inflation(r)
    return c / scale, r, se / scale


def loss_fit(s: Span, cogging: tuple[float, ...] = ()) -> dict[str, Any]:
    """The balance fitted with a torque scale, the current's lag (grid), ``mesh_loss`` and
    ``gear_drag`` (and, where given, cogging at the spatial frequencies ``cogging`` rad^-1)."""
    sg = _sign(s.omega)
    drag_col = -s.twice(sg)
    extra = []
    for m in cogging:
        extra += [s.twice(np.sin(m * s.psi)), s.twice(np.cos(m * s.psi))]
    one, ramp = np.ones_like(s.t), s.t - s.t[0]
    best = None
    for lag in LAGS_S:
        i = s.current(lag)
        A = np.column_stack([one, ramp, s.k_t * s.twice(i), -s.k_t * s.twice(np.abs(i) * sg), drag_col, *extra])
        c, r, se = _lstsq(A, s.target)
        rss = float(r @ r)
        if best is None or rss < best[0]:
            best = (rss, lag, c, se, r)
    rss, lag, c, se, r = best
    # the mesh and drag columns by themselves tell whether both quadrants were seen: the quadrant
    # where the current drives the flywheel and the one where it brakes it
    i = s.current(lag)
    drive = np.mean(i * s.omega > 0)
    return {"run": s.name, "lag_s": float(lag), "torque_scale": float(c[2]), "mesh": float(c[3]), "mesh_se": float(se[3]),
            "drag": float(c[4]), "drag_se": float(se[4]), "rms_rad": math.sqrt(rss / len(r)),
            "driving_fraction": float(drive)}


def _spline_basis(t: np.ndarray, knot: float) -> np.ndarray:
    from scipy.interpolate import BSpline  # noqa: PLC0415

    n = max(1, int(math.ceil((t[-1] - t[0]) / knot)))
    k = np.linspace(t[0], t[-1], n + 1)
    k = np.concatenate([[k[0]] * 3, k, [k[-1]] * 3])
    return BSpline.design_matrix(np.clip(t, k[0], k[-1]), k, 3).toarray()


def _whitener(r: np.ndarray, order: int):
    """The prediction-error filter of an autoregressive model of ``r`` (Yule-Walker, ``order`` lags):
    applied to the residuals and to every column, it makes the least squares generalised."""
    from scipy.linalg import solve_toeplitz  # noqa: PLC0415
    from scipy.signal import lfilter  # noqa: PLC0415

    r = r - r.mean()
    n = len(r)
    acf = np.array([r[: n - k] @ r[k:] for k in range(order + 1)]) / n
    if acf[0] <= 0:
        return lambda x: x
    a = solve_toeplitz(acf[:-1], acf[1:])
    filt = np.concatenate([[1.0], -a])
    return lambda x: lfilter(filt, [1.0], x, axis=0)[order:]


def cogging_scan(s: Span, lag: float) -> dict[str, Any]:
    """For every ``n`` of :data:`COGGING_PERIODS`: the drop of the residual sum of squares when
    ``sin, cos(n N psi)`` join the slow part (a spline in time), the scale and the losses, in
    units of the residual variance, so chi-square with 2 degrees of freedom where there is no
    cogging; and the fitted amplitude and its standard error (N m at the flywheel).

    The residuals are not white (a controller's chatter that the current channel does not quite
    show, the encoders' quantisation at a slow rate): every column and the residual are first
    passed through the prediction-error filter of an autoregressive model of the residual
    (order :data:`WHITENING_ORDER`), so the test is a generalised least squares one; without
    it a broad excess of the residual at 5-20 Hz reads as cogging at every high ``n``."""
    i = s.current(lag)
    sg = _sign(s.omega)
    base = np.column_stack([_spline_basis(s.t, SPLINE_KNOT_S), s.k_t * s.twice(i),
                            -s.k_t * s.twice(np.abs(i) * sg), -s.twice(sg)])
    Q, _ = np.linalg.qr(base / np.linalg.norm(base, axis=0).clip(1e-300))
    y0 = s.target - Q @ (Q.T @ s.target)
    white = _whitener(y0, WHITENING_ORDER)
    Bw = white(base)
    Qw, _ = np.linalg.qr(Bw / np.linalg.norm(Bw, axis=0).clip(1e-300))
    yw = white(s.target)
    y = yw - Qw @ (Qw.T @ yw)
    n_dof = len(y) - base.shape[1] - 2
    s2 = float(y @ y) / n_dof
    turns = float(np.ptp(s.psi)) * s.gear_ratio / (2 * math.pi)  # motor turns covered
    dt = np.gradient(s.t)
    dpsi = np.abs(s.omega) * dt
    cols, raw, amp = {}, {}, {}
    for n in COGGING_PERIODS:
        m = n * s.gear_ratio
        # only where a cycle spans MIN_SAMPLES_PER_CYCLE samples: faster, the sampled angle
        # aliases the cycle (and the flywheel's inertia filters the torque away anyway)
        # (a smooth taper, so that its edges are no transient of their own)
        seen = 1.0 / (1.0 + (m * dpsi * MIN_SAMPLES_PER_CYCLE / (2 * math.pi)) ** 8)
        if float(np.sum(m * dpsi * seen)) / (2 * math.pi) < MIN_COGGING_CYCLES:
            continue
        C = white(np.column_stack([s.twice(seen * np.sin(m * s.psi)), s.twice(seen * np.cos(m * s.psi))]))
        C = C - Qw @ (Qw.T @ C)
        G = C.T @ C
        try:
            c = np.linalg.solve(G, C.T @ y)
            var = float(np.trace(np.linalg.inv(G))) / 2.0 * s2
        except np.linalg.LinAlgError:
            continue
        fitted = C @ c
        cols[float(n)] = C
        raw[float(n)] = float(fitted @ fitted) / s2
        amp[float(n)] = (float(np.hypot(*c)), math.sqrt(max(var, 0.0)))
    # the null's own scale: the median drop over every period searched, over the median of chi-square 2
    # (2 ln 2); never below the white one. What the whitening leaves of the residuals' colour and of their transients
    # lifts every period alike, and is taken out here.
    # The median is taken with the strongest period's fit taken out of the residuals: a real cogging
    # leaks into every period (where the rotor creeps, every period's column is slow alike).
    excess = 1.0
    if len(raw) >= 20:
        top = max(raw, key=raw.get)
        rest = [d / s2 for d in drops_beside(cols, y, top)]
        excess = max(1.0, float(np.median(rest)) / (2.0 * math.log(2.0)))
    drops = {n: raw[float(n)] / excess for n in COGGING_PERIODS if float(n) in raw}
    amps = {n: (amp[float(n)][0], amp[float(n)][1] * math.sqrt(excess)) for n in drops}
    return {"run": s.name, "drops": drops, "amplitudes": amps, "motor_turns": turns, "noise_excess": excess}


def backlash_fit(rec: RunRecord) -> dict[str, Any] | str:
    """The gearbox's gap crossed at each torque reversal of ``rec``, read from the motor's voltage.

    While the rotor crosses the gap it turns relative to the flywheel, so the winding's back-EMF
    is ``k_t (Omega + gap')``, not ``k_t Omega``: the voltage's residual from
    ``u = R i + L i' + k_t Omega + offset`` (coefficients fitted on the hold and reverse stroke
    away from the reversals, so a resistance or inductance off the rig block does not enter; with
    ``Omega`` taken at the lag that fits best, for a voltage channel that lags the encoders),
    integrated over a reversal and divided by ``k_t``, is the angle the rotor travelled in the
    gap: the gap's width, signed with the new torque. A reversal is a change of sign of the
    current held for :data:`REVERSAL_HOLD_S` on both sides (the plan's crossings; chatter within
    that time moves the rotor back and forth and is not counted). Returns the per-reversal
    widths (rad at the flywheel) with their standard errors, or why the run cannot tell."""
    from addedinertia_env.identify.common import IdentificationError  # noqa: PLC0415
    from addedinertia_env.identify.energy_balance import RunBalance  # noqa: PLC0415

    if rec.experiment.get("kind") != "reverse-symmetric":
        return "not a reverse-symmetric run"
    if rec.known.gear_ratio <= 1.0:
        # the gap is the gearbox's (run-record.md: a gearbox shows as rig.gear_ratio); on a direct drive a
        # voltage residual at the reversals is the DAQ's (a current logged held-previous at 250 Hz made one)
        return "no gearbox (rig.gear_ratio 1): no gear gap to cross"
    if "u" not in rec.samples:
        return "no voltage channel"
    try:
        b = RunBalance(rec.without_truth(), "reaction", False)
    except (IdentificationError, ValueError) as e:
        return f"no flywheel balance: {e}"
    a, e = b.hold_start, b.rev.stop
    t, i, u = b.t[a:e], b.i[a:e], np.asarray(rec["u"][a:e], float)
    if len(t) < 200:
        return "too short a hold and reverse stroke"
    dt = float(np.median(np.diff(t)))
    # the flywheel's rate from the raw angle, lightly smoothed across the phases (the energy method's
    # angles are smoothed phase by phase, whose cut at the release is a reversal's neighbour)
    from scipy.signal import savgol_filter  # noqa: PLC0415

    psi_raw = np.asarray(rec["psi"][a:e], float)
    om = savgol_filter(psi_raw, RATE_WINDOW, 2, deriv=1, delta=float(np.median(np.diff(t))))
    di = np.gradient(i, t)
    w = max(3, int(round(REVERSAL_HOLD_S / dt)))
    im = np.convolve(i, np.ones(w) / w, mode="same")
    thr = 3.0 * b.noise_i + REVERSAL_MIN_CURRENT
    sgn = np.where(im > thr, 1, np.where(im < -thr, -1, 0))
    held, start = [], 0  # (first, last + 1, sign) of each stretch held for w samples
    for j in range(1, len(sgn) + 1):
        if j == len(sgn) or sgn[j] != sgn[start]:
            if sgn[start] != 0 and j - start >= w:
                held.append((start, j, int(sgn[start])))
            start = j
    pre, post = int(round(REVERSAL_PRE_S / dt)), int(round(REVERSAL_WINDOW_S / dt))
    windows = [(max(e0 - pre, 0), min(s1 + post, len(t)), g1)
               for (s0, e0, g0), (s1, e1, g1) in zip(held, held[1:]) if g0 != g1]
    if not windows:
        return "no torque reversal held on both sides: the gap is never crossed"
    keep = np.ones(len(t), bool)
    for c0, c1, _ in windows:
        keep[c0:c1] = False
    u_max = rec.known.u_max
    if u_max:
        keep &= np.abs(u) < 0.98 * u_max  # at the supply, the voltage is not the winding's
    if keep.sum() < 100:
        return "too few samples away from the reversals to fit the winding"
    # a voltage channel that lags the encoders by d (sensor_delay) reads k_t Omega(t - d): the lag is
    # fitted on the grid LAGS_S (else k_t (Omega(t - d) - Omega(t)) changes sign with the torque, as
    # the gap's travel does)
    # The inductance as the rig block states it where it does (L > 0): fitted away from the reversals,
    # where the current hardly changes, it is ill determined, and its error times the current's jump
    # across a reversal reads as a gap (0.5 deg for 0.25 mH and 10 A at 0.25 N m/A)
    L_known = float(b.L or 0.0)
    # Where the rig block states L and the current is sampled at instants (the drive holds its voltage
    # over each sample, the current relaxes with tau = L / R inside it, as the energy method's
    # interval_mean_current has it), the winding's law holds exactly per interval: the voltage held
    # over (t_k-1, t_k] is R i_ss,k + k_t Omega (the interval's mean rate), with the current it was
    # relaxing to i_ss,k = (i_k - a i_k-1) / (1 - a), a = exp(-h / tau). The law with the end
    # current and a central-difference L i' mis-weights the inductive term by the current's jump
    # across every reversal (about 0.4 L dI: read as a gap) and, fitted away from the reversals,
    # reads k_e 3 % low, whose error drifts the sum after a crossing: together 0.25 deg low on a
    # 1 deg gap (docs/DISCOVERY.md, "Why the backlash width read low").
    exact = L_known > 0 and float(b.R) > 0 and getattr(b, "current_sampling", "instant") == "instant"
    if exact:
        decay = math.exp(-dt * float(b.R) / L_known)
        i_fit, om_fit = i.copy(), om.copy()
        i_fit[1:] = (i[1:] - decay * i[:-1]) / (1.0 - decay)
        om_fit[1:] = 0.5 * (om[1:] + om[:-1])
        target = u
    else:
        i_fit, om_fit = i, om
        target = u - L_known * di if L_known > 0 else u
    best = None
    for lag in LAGS_S[LAGS_S >= 0.0]:  # a channel lags, never leads
        cols = [i_fit] + ([] if L_known > 0 else [di]) + [np.interp(t - lag, t, om_fit), np.ones_like(t)]
        A = np.column_stack(cols)
        coef, *_ = np.linalg.lstsq(A[keep], target[keep], rcond=None)
        rk = target[keep] - A[keep] @ coef
        if best is None or float(rk @ rk) < best[0]:
            best = (float(rk @ rk), lag, A, coef)
    _, lag, A, coef = best
    if L_known > 0:  # the same layout either way: R, L, k_e, offset (the exact law holds L in i_ss)
        coef = np.array([coef[0], L_known, coef[1], coef[2]])
        A = np.column_stack([A[:, 0], np.zeros_like(di) if exact else di, A[:, 1], A[:, 2]])
    k_t = float(b.k_t)
    if not (abs(coef[2] / k_t - 1) <= WINDING_TOLERANCE and abs(coef[0] / float(b.R) - 1) <= 2 * WINDING_TOLERANCE):
        return (f"the voltage does not follow the winding's law u = R i + L i' + k_t Omega (fitted R {coef[0]:.3g} "
                f"ohm, k_e {coef[2]:.3g} V s/rad, lag {lag * 1e3:.1f} ms; the rig block: R {float(b.R):.3g}, k_t "
                f"{k_t:.3g}): the back-EMF cannot be read")
    r = u - A @ coef
    sr = float(np.std(r[keep])) * _inflation(r[keep])
    widths = [float(g * np.sum(r[c0:c1]) * dt / k_t) for c0, c1, g in windows]
    ses = [sr * math.sqrt(c1 - c0) * dt / k_t for c0, c1, _ in windows]
    return {"run": rec.name, "widths_rad": widths, "se_rad": ses, "winding": {"R": float(coef[0]), "L": float(coef[1]),
            "k_e": float(coef[2]), "lag_s": float(lag)}}


def candidate(records: list[RunRecord]) -> dict[str, Any]:
    """The drive's words on ``records``: ``named`` (a list, maybe empty), the evidence per run and word."""
    from scipy.stats import chi2  # noqa: PLC0415

    spans, skipped = [], []
    for rec in records:
        s = span(rec)
        (skipped.append({"run": rec.name, "why": s}) if isinstance(s, str) else spans.append(s))
    out: dict[str, Any] = {"named": [], "runs": [], "skipped": skipped, "why": {}}
    if not spans:
        out["why"] = {w: "no reverse-symmetric run with a flywheel balance" for w in NAMES}
        return out  # (a run without a flywheel balance has no controlled phase for supply_limit either)
    losses = [loss_fit(s) for s in spans]
    scans = [cogging_scan(s, f["lag_s"]) for s, f in zip(spans, losses)]

    # cogging: the runs' drops summed per n (chi-square with 2 K degrees of freedom without cogging)
    ns = sorted(set().union(*(sc["drops"] for sc in scans)))
    cog: dict[str, Any] = {"named": False}
    if ns:
        total = {n: sum(sc["drops"].get(n, 0.0) for sc in scans) for n in ns}
        k = {n: sum(1 for sc in scans if n in sc["drops"]) for n in ns}
        p = {n: float(chi2.sf(total[n], 2 * k[n])) * len(ns) for n in ns}
        n_best = min(ns, key=lambda n: p[n])
        # the runs' amplitudes at the best n, weighted by their variances
        a_se = np.array([sc["amplitudes"][n_best] for sc in scans if n_best in sc["amplitudes"]])
        w = 1.0 / np.maximum(a_se[:, 1], 1e-300) ** 2
        amp, amp_se = float(np.sum(w * a_se[:, 0]) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w)))
        cog.update(periods_per_motor_turn=n_best, p_family=min(1.0, p[n_best]), chi2=total[n_best],
                   runs=k[n_best], amplitude_flywheel_Nm=amp, amplitude_se_Nm=amp_se,
                   amplitude_motor_Nm=amp / spans[0].gear_ratio)
        clear = amp - COGGING_SE * amp_se
        # the same period is the run's own strongest (within the run's resolution, 1 / motor turns)
        # in at least half the runs: a transient of one run, or an excess spread over many periods,
        # lifts many periods a little, a cogging lifts its own in every run that turns enough
        agree = [sc for sc in scans if n_best in sc["drops"] and
                 abs(max(sc["drops"], key=sc["drops"].get) - n_best) <= max(1.0, 1.0 / max(sc["motor_turns"], 1e-9))]
        cog["runs_agreeing"] = len(agree)
        consistent = 2 * len(agree) >= k[n_best]
        cog["named"] = bool(p[n_best] < COGGING_FALSE_ALARM and clear >= MIN_COGGING and consistent)
        if cog["named"]:
            cog["why"] = (f"a torque periodic in the rotor angle, {n_best} cycles per motor turn, "
                          f"{amp * 1e3:.1f} +- {amp_se * 1e3:.1f} mN m at the flywheel (family-wise p = {p[n_best]:.1e})")
        elif p[n_best] < COGGING_FALSE_ALARM and not consistent:
            cog["why"] = (f"{n_best} cycles per motor turn stand out together (p = {p[n_best]:.1e}), but are the "
                          f"strongest period in only {len(agree)} of {k[n_best]} runs: no cogging (a transient, or "
                          "an excess spread over many periods)")
        elif p[n_best] >= COGGING_FALSE_ALARM:
            cog["why"] = (f"no torque periodic in the rotor angle stands out of the noise (best: {n_best} per motor "
                          f"turn, family-wise p = {min(1.0, p[n_best]):.2g} >= {COGGING_FALSE_ALARM:g})")
        else:
            cog["why"] = (f"{n_best} cycles per motor turn stand out (p = {p[n_best]:.1e}), but "
                          f"{amp * 1e3:.1f} +- {amp_se * 1e3:.1f} mN m is not clear of {MIN_COGGING * 1e3:g} mN m "
                          f"by {COGGING_SE:g} standard errors")
    else:
        cog["why"] = f"the rotor turned through fewer than {MIN_COGGING_CYCLES:g} cycles of any period searched"
    if cog["named"]:  # the losses are fitted again with the cogging in the balance
        m = cog["periods_per_motor_turn"] * spans[0].gear_ratio
        losses = [loss_fit(s, (m,)) for s in spans]

    words = {"cogging": cog}
    for word, key, min_size, unit in (("mesh_loss", "mesh", MIN_MESH, ""), ("gear_drag", "drag", MIN_DRAG, " N m")):
        sizes = np.array([f[key] for f in losses])
        z = sizes / np.array([max(f[key + "_se"], 1e-300) for f in losses])
        rms = max(f["rms_rad"] for f in losses)
        named = bool(np.all(sizes >= min_size) and np.all(z >= MIN_Z) and rms <= MAX_LOSS_RMS)
        ev = {"named": named, "sizes": sizes.tolist(), "z": z.tolist(), "min_size": min_size, "rms_rad": rms}
        if named:
            ev["why"] = f"every run: {key} {sizes.min():.4g}..{sizes.max():.4g}{unit} >= {min_size:g}, z >= {z.min():.0f}"
        elif rms > MAX_LOSS_RMS:
            ev["why"] = (f"the losses leave {rms:.2g} rad rms of the flywheel's balance (over {MAX_LOSS_RMS:g}): "
                         "something else acts on the flywheel, so their sizes are not read")
        else:
            ev["why"] = (f"{key} {sizes.min():.4g}..{sizes.max():.4g}{unit} (z {z.min():.1f}..{z.max():.1f}): "
                         f"not every run clear of {min_size:g} and of {MIN_Z:g} standard errors")
        words[word] = ev
    fits = [backlash_fit(r) for r in records]
    widths = [(w, se) for f in fits if isinstance(f, dict) for w, se in zip(f["widths_rad"], f["se_rad"])]
    bl: dict[str, Any] = {"named": False, "reversals": len(widths),
                          "runs": [f if isinstance(f, dict) else {"why": f} for f in fits]}
    if widths:
        x = np.array(widths)
        wgt = 1.0 / np.maximum(x[:, 1], 1e-12) ** 2
        # the median over the reversals (a reversal where the winding's law misses, at a phase's
        # start, is an outlier of either sign), its standard error that of the mean times 1.25
        width = float(np.median(x[:, 0]))
        se = 1.2533 * float(1.0 / math.sqrt(np.sum(wgt)))
        positive = float(np.mean(x[:, 0] > 0))
        bl.update(width_rad=width, width_deg=math.degrees(width), se_rad=se, positive_fraction=positive,
                  widths_deg=np.degrees(x[:, 0]).round(3).tolist())
        # one gap: the reversals' robust spread (1.4826 MAD) within BACKLASH_SPREAD of their own errors
        spread = 1.4826 * float(np.median(np.abs(x[:, 0] - width)))
        typical = float(np.median(x[:, 1]))
        one_gap = len(x) < 3 or spread <= BACKLASH_SPREAD * typical
        bl.update(spread_rad=spread)
        bl["named"] = bool(width >= MIN_BACKLASH and width >= BACKLASH_Z * se and positive >= BACKLASH_AGREE
                           and one_gap)
        if bl["named"]:
            bl["why"] = (f"the rotor crosses a gap of {math.degrees(width):.2f} +- {math.degrees(se):.2f} deg at the "
                         f"flywheel (median of {len(widths)} torque reversals; the back-EMF of its travel)")
        elif not one_gap and width >= MIN_BACKLASH:
            bl["why"] = (f"the reversals cross different widths (spread {math.degrees(spread):.2f} deg against their "
                         f"errors of {math.degrees(typical):.2f} deg): not one gap")
        elif positive < BACKLASH_AGREE:
            bl["why"] = (f"only {positive:.0%} of {len(widths)} reversals cross forward (a gap: at least "
                         f"{BACKLASH_AGREE:.0%}); median {math.degrees(width):.2f} deg")
        else:
            bl["why"] = (f"gap {math.degrees(width):.2f} +- {math.degrees(se):.2f} deg (median of {len(widths)} "
                         f"reversals): not clear of {math.degrees(MIN_BACKLASH):g} deg and of {BACKLASH_Z:g} standard errors")
    else:
        bl["why"] = "no run can tell: " + "; ".join(sorted({f for f in fits if isinstance(f, str)}))
    words["backlash"] = bl
    from addedinertia_env.discover.supply_limit import judge as judge_supply  # noqa: PLC0415

    words["supply_limit"] = judge_supply(records)
    out["runs"] = losses
    out["words"] = words
    out["named"] = [w for w in NAMES if words[w]["named"]]
    out["why"] = {w: words[w]["why"] for w in NAMES}
    return out


def merge(cause: str, causes: list[str], evidence: dict[str, Any] | None) -> tuple[str, list[str]]:
    """The verdict with the drive's words added after the others (the hull's effects and the water's
    memory move lambda66 through the hull's own equation; the drive's through the motor's work). Where
    nothing else was named (``none``, ``unexplained``), the first drive word becomes the cause.

    A gearhead's loss takes a share of the motor's torque, which the gray-box model (no drive in
    it) reads as a torque constant off its data sheet, or as a lag: where ``mesh_loss`` or
    ``gear_drag`` is named, ``torque_constant`` and ``sensor_delay`` are kept only where the
    flywheel's balance *with the drive's losses in it* still says so (:func:`flywheel_words`)."""
    words = [w for w in (evidence or {}).get("named", []) if w not in causes]
    if not words:
        return cause, causes
    kept = list(causes)
    if {"mesh_loss", "gear_drag"} & set(words):
        confirmed = flywheel_words(evidence)
        kept = [c for c in kept if c not in ("torque_constant", "sensor_delay") or c in confirmed]
    if cause not in kept:
        cause = kept[0] if kept else "none"
    if cause in ("none", "unexplained") or not kept:
        return words[0], kept + words
    return cause, kept + words


def flywheel_words(evidence: dict[str, Any]) -> list[str]:
    """``torque_constant`` where every run's torque scale fitted beside the drive's losses is off 1
    by the effect's smallest size on the same side, ``sensor_delay`` likewise for the current's lag
    (as :func:`.radiation_memory.flywheel_effects`, with the losses in the balance)."""
    from addedinertia_env.sim.effects import registry  # noqa: PLC0415

    runs = evidence.get("runs") or []
    out = []
    for word, key, neutral in (("torque_constant", "torque_scale", 1.0), ("sensor_delay", "lag_s", 0.0)):
        if word not in registry.effect_names() or not runs:
            continue
        off = np.array([r[key] for r in runs]) - neutral
        if np.all(np.abs(off) >= registry.get(word).min_size) and (np.all(off > 0) or np.all(off < 0)):
            out.append(word)
    return out
