"""The energy method of patent RU 2627023, in the general form of physics.md section 4.

For a boundary angle ``phi1`` passed forward at ``t1`` and in reverse at ``t4`` (the hull
rests at ``t2``, end of the free stroke, and ``t3``, end of the hold)::

    (J_h + lambda66) (w1f^2 + w1r^2) / 2 =
        Pi(t2) - Pi(t1) + Pi(t3) - Pi(t4)            (spring, with measured angles)
      + (A_r + B_r) - (A_f + B_f)                     (motor work, rotor-bearing work)
      + K(t2) + K(t3) - K(t1) - K(t4)                 (flywheel energy 1/2 J_f (w + Omega)^2)
      - dW                                            (dissipation mismatch, optional)

The hydrodynamic dissipation cancels if the reverse stroke retraces ``|w(phi)|``. What
the controller fails to retrace leaves ``dW = integral D'(|w|) (|w_r| - |w_f|) dphi``,
which is estimated from the record itself (a damping law fitted to the forward stroke)
and removed; half of it is kept as uncertainty.

Motor work: ``A = sum k_t i dpsi`` (current and flywheel encoder; default) or, as the
patent does, electric energy minus ohmic and magnetic energy
``int u i dt - R int i^2 dt - [L i^2 / 2]``. The current-sensor offset is calibrated on
the free stroke, where the motor is open-circuit and the true current is zero.

Only the record's samples and its ``rig`` block are used; never ``truth``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..record import RunRecord
from ..record import MAX_GAP_PERIODS
from ..rig.known import KnownRigError
from .common import IdentificationError, Result, largest_gap, local_fit, pooled_interval, segment, smooth_angle

# Boundary angles as fractions of the way from the calibrated neutral to the stop phi2:
# the patent drops the nearly uniform middle of the stroke, and too near the stop the
# kinetic energy (the denominator) vanishes.
DEFAULT_FRACTIONS = (0.3, 0.4, 0.5, 0.6, 0.7)
WORK_FORMS = ("reaction", "current", "electric")
CURRENT_GAIN_UNCERTAINTY = 0.005  # relative, current-sensor gain (physics.md section 7)


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
    sigma_independent: float = float("inf")  # noise and rate fits: independent between boundary angles
    sigma_common: float = 0.0  # current-sensor gain and dissipation-mismatch model: shared by all angles


def identify_energy(records: list[RunRecord], work: str = "reaction", fractions=DEFAULT_FRACTIONS,
                    asymmetry_correction: bool = True) -> Result:
    """lambda66 from one or more reverse-symmetric runs, with a 95 % interval."""
    if work not in WORK_FORMS:
        raise ValueError(f"work={work!r}: expected one of {WORK_FORMS}")
    intervals: list[Interval] = []
    for rec in records:
        intervals += _run_intervals(rec, work, fractions, asymmetry_correction)
    good = [iv for iv in intervals if not iv.rejected]
    if not good:
        reasons = "; ".join(sorted({iv.rejected for iv in intervals})) or "no usable interval"
        names = ", ".join(sorted({rec.name for rec in records}))
        raise IdentificationError(f"energy method on {names}: every boundary-angle interval was rejected "
                                  f"({reasons}); expected a reverse-symmetric run whose strokes pass the boundary "
                                  "angles, sampled without gaps, current below its limit")
    by_run: dict[str, list[Interval]] = {}
    for iv in good:
        by_run.setdefault(iv.run, []).append(iv)
    # Within a run, the boundary angles lie ~100 ms apart, so their rate fits (+-30 ms) and
    # the current noise over their different stretches are independent: those parts average
    # down, widened by the Birge ratio when the angles scatter more than they allow. The
    # current-sensor gain and the dissipation-mismatch model act on every angle alike and
    # do not average down. Then runs are pooled.
    run_values, run_sigmas = [], []
    for ivs in by_run.values():
        lam = np.array([iv.lambda66 for iv in ivs])
        s_ind = np.array([iv.sigma_independent for iv in ivs])
        value, lo, _ = pooled_interval(lam, s_ind)
        s_common = float(np.median([iv.sigma_common for iv in ivs]))
        run_values.append(value)
        run_sigmas.append(float(np.hypot((value - lo) / 1.96, s_common)))
    value, lo, hi = pooled_interval(np.array(run_values), np.array(run_sigmas))
    return Result(method="energy", lambda66=value, ci95=(lo, hi), n_intervals=len(good),
                  details={"work": work, "asymmetry_correction": asymmetry_correction, "n_runs": len(by_run),
                           "per_run": run_values, "rejected": len(intervals) - len(good),
                           "intervals": [iv.__dict__ for iv in intervals]})


def _run_intervals(rec: RunRecord, work: str, fractions, asymmetry_correction: bool) -> list[Interval]:
    rig = rec.known
    J_h, J_f, c = rig.J_hull, rig.J_flywheel, rig.c_torsion
    phi_n, k_t, R = rig.phi_neutral, rig.k_t, rig.R
    f_visc, f_coul = rig.friction_viscous, rig.friction_coulomb
    L = 0.0
    if work == "electric":
        try:
            L = rig.require_L("the energy method with work='electric'")
        except KnownRigError as e:
            raise IdentificationError(f"{rec.name}: {e}") from None
    if rec.experiment.get("kind") != "reverse-symmetric":
        raise IdentificationError(f"{rec.name}: the energy method needs a reverse-symmetric run, "
                                  f"not {rec.experiment.get('kind')!r}")
    t, phi, psi = rec.t, rec["phi"], rec["psi"]
    free, hold, rev = segment(rec, "free"), segment(rec, "hold"), segment(rec, "reverse")
    if free is None or rev is None:
        raise IdentificationError(f"{rec.name}: needs a 'free' and a 'reverse' phase")
    i_offset = float(np.mean(rec["i"][free]))  # open circuit on the free stroke: true i = 0
    i = rec["i"] - i_offset
    # Voltage offset: on the open-circuit free stroke the terminals show the back-EMF,
    # u = k_e Omega + offset; the intercept of that line is the sensor's offset.
    u_offset = _voltage_offset(t[free], psi[free], rec["u"][free]) if work == "electric" else 0.0
    phi_s, psi_s = smooth_angle(t, phi), smooth_angle(t, psi)  # for work increments only
    k2 = free.stop - 1  # last free sample: the brake is set (t2)
    k3 = (hold.stop - 1) if hold is not None else rev.start - 1  # last braked sample (t3)
    phi2 = phi[k2]
    direction = np.sign(phi2 - phi_n)
    phi1_list = rec.experiment.get("phi1") or [phi_n + f * (phi2 - phi_n) for f in fractions]
    fwd_law = _forward_damping_law(rec, free, k2, J_h, c, phi_n, i)

    def rate(k: int, angle: np.ndarray) -> float:
        return local_fit(t, angle, t[k], half_width=0.03)[1]

    def flywheel_energy(k: int) -> float:
        return 0.5 * J_f * (rate(k, phi) + rate(k, psi)) ** 2

    def motor_work(a: int, b: int) -> tuple[float, float]:
        """Work on [t_a, t_b] (sample indices), and its 1-sigma noise from the current noise, J."""
        s = slice(a, b + 1)
        i_mid = 0.5 * (i[s][1:] + i[s][:-1])
        dpsi = np.diff(psi_s[s])
        if work == "reaction":
            # Work of the motor's reaction on the hull: -(k_t i - M_f) dphi.
            dphi = np.diff(phi_s[s])
            omega = dpsi / np.diff(t[s])
            torque = k_t * i_mid - (f_visc * omega + f_coul * np.sign(omega))
            A = -float(np.sum(torque * dphi))
            noise_i = float(np.std(rec["i"][free]))
            return A, k_t * noise_i * float(np.sqrt(np.sum(dphi**2) / 2.0))
        if work == "current":
            A = k_t * float(np.sum(i_mid * dpsi))
        else:
            A = _electric_work(t[s], rec["u"][s] - u_offset, i[s], R, L)
        noise_i = float(np.std(rec["i"][free]))
        return A, k_t * noise_i * float(np.sqrt(np.sum(dpsi**2) / 2.0))

    def bearing_work(a: int, b: int) -> float:
        s = slice(a, b + 1)
        omega = np.gradient(psi[s], t[s])
        return -float(np.sum((f_visc * omega[:-1] + f_coul * np.sign(omega[:-1])) * np.diff(psi[s])))

    out: list[Interval] = []
    for phi1 in phi1_list:
        iv = Interval(run=rec.name, phi1=float(phi1), lambda66=float("nan"), sigma=float("inf"), w1f=0.0, w1r=0.0)
        out.append(iv)
        k1 = _crossing(phi, free.start, k2, phi1, direction)
        k4 = _crossing(phi, rev.start, rev.stop - 1, phi1, -direction)
        if k1 is None or k4 is None:
            iv.rejected = "boundary angle not passed on both strokes"
            continue
        gap = largest_gap(rec, k1, k2) or largest_gap(rec, k3, k4)
        if gap is not None:  # the work sums and rate fits assume the stroke was sampled throughout
            iv.rejected = (f"a gap of {gap[1]:.4g} s in 't' after t = {gap[0]:.4f} s inside the integrated stroke "
                           f"({MAX_GAP_PERIODS:g} sample periods allowed)")
            continue
        # Refine the crossing instants and rates with local quadratic fits.
        t1, w1f, sw1f = _crossing_fit(t, phi, k1, phi1)
        t4, w1r, sw1r = _crossing_fit(t, phi, k4, phi1)
        k1, k4 = int(np.argmin(np.abs(t - t1))), int(np.argmin(np.abs(t - t4)))
        A_f, sA_f = motor_work(k1, k2)
        A_r, sA_r = motor_work(k3, k4)
        if work == "reaction":  # the hull's own balance: no flywheel energy, rotor friction inside A
            B_f = B_r = 0.0
            K1 = K2 = K3 = K4 = 0.0
        else:
            B_f, B_r = bearing_work(k1, k2), bearing_work(k3, k4)
            K1, K2, K3, K4 = (flywheel_energy(k) for k in (k1, k2, k3, k4))
        spring = 0.5 * c * ((phi[k2] - phi_n) ** 2 - (phi1 - phi_n) ** 2 + (phi[k3] - phi_n) ** 2 - (phi1 - phi_n) ** 2)
        # Hull kinetic energy left at t2, t3 (nearly zero; the brake holds the hull).
        J_guess = fwd_law["J"] if fwd_law else J_h
        hull_rest = 0.5 * J_guess * (rate(k2, phi) ** 2 + rate(k3, phi) ** 2)
        dW, s_dW = (_dissipation_mismatch(t, phi, k1, k2, k3, k4, fwd_law, direction)
                    if (asymmetry_correction and fwd_law) else (0.0, 0.0))
        numerator = spring + (A_r + B_r) - (A_f + B_f) + K2 + K3 - K1 - K4 + hull_rest - dW
        denom = 0.5 * (w1f**2 + w1r**2)
        J_total = numerator / denom
        lam = J_total - J_h
        # Uncertainty, split by what the boundary angles share (see identify_energy).
        s_gain = CURRENT_GAIN_UNCERTAINTY * float(np.hypot(A_f, A_r))
        s_den = float(np.sqrt((w1f * sw1f) ** 2 + (w1r * sw1r) ** 2))
        s_independent = float(np.hypot(np.hypot(sA_f, sA_r) / denom, J_total * s_den / denom))
        s_common = float(np.hypot(s_gain, s_dW)) / denom
        sigma = float(np.hypot(s_independent, s_common))
        sat = float(np.mean(np.abs(rec["i_cmd"][k3:k4 + 1]) >= 0.999 * rig.current_limit)) \
            if "i_cmd" in rec.samples else 0.0
        iv.lambda66, iv.sigma, iv.w1f, iv.w1r = float(lam), sigma, float(w1f), float(w1r)
        iv.sigma_independent, iv.sigma_common = s_independent, s_common
        iv.terms = {"spring": spring, "A_f": A_f, "A_r": A_r, "B_f": B_f, "B_r": B_r, "K1": K1, "K2": K2,
                    "K3": K3, "K4": K4, "hull_rest": hull_rest, "dW": dW, "saturated_frac": sat,
                    "t1": t1, "t4": t4, "speed_mismatch": abs(abs(w1r) - abs(w1f)) / max(abs(w1f), 1e-12)}
        if sat > 0.02:
            iv.rejected = f"current at its limit for {sat:.0%} of the reverse stroke"
        elif iv.terms["speed_mismatch"] > 0.2:
            iv.rejected = f"reverse speed at phi1 differs by {iv.terms['speed_mismatch']:.0%} from the forward speed"
    return out


def _crossing(phi: np.ndarray, a: int, b: int, level: float, direction: float) -> int | None:
    """First sample in [a, b) after which ``phi`` has crossed ``level`` moving in ``direction``."""
    seg = direction * (phi[a:b] - level)
    idx = np.nonzero((seg[:-1] < 0) & (seg[1:] >= 0))[0]
    return None if not len(idx) else int(a + idx[0] + 1)


def _crossing_fit(t: np.ndarray, phi: np.ndarray, k: int, level: float, half_width: float = 0.03):
    """Time where a local cubic through ``phi`` equals ``level``; rate there and its sigma."""
    tc = t[k]
    coef, cov, rms = local_fit(t, phi, tc, half_width=half_width, full=True)
    poly = np.polynomial.Polynomial(coef)  # phi ~ poly(s), s = t - tc
    dpoly = poly.deriv()
    s = 0.0
    for _ in range(6):  # Newton on poly(s) = level
        s -= (poly(s) - level) / dpoly(s)
    w = float(dpoly(s))
    grad = np.array([k * s ** (k - 1) if k else 0.0 for k in range(len(coef))])  # d(rate)/d(coef)
    sw = float(np.sqrt(grad @ cov @ grad))
    return float(tc + s), float(w), sw


def _forward_damping_law(rec: RunRecord, free: slice, k2: int, J_h: float, c: float, phi_n: float,
                         i: np.ndarray) -> dict | None:
    """Damping torque magnitude ``D(w) = d1 |w| + d2 w^2`` seen on the forward stroke.

    From ``J phi'' + c (phi - phi_n) = -D(w) sign(w)`` with ``J`` and the damping fitted
    jointly by least squares on smoothed derivatives of the free stroke's second half.
    """
    from scipy.signal import savgol_filter  # noqa: PLC0415

    t, phi = rec.t, rec["phi"]
    a = free.start + (k2 - free.start) // 3
    if k2 - a < 60:
        return None
    dt = float(np.median(np.diff(t[a:k2])))
    win = 41
    seg = phi[a - win:k2 + 1] if a >= win else phi[a:k2 + 1]
    w = savgol_filter(seg, win, 3, deriv=1, delta=dt)
    acc = savgol_filter(seg, win, 3, deriv=2, delta=dt)
    keep = slice(win, len(seg) - win // 2)
    w, acc, ph = w[keep], acc[keep], seg[keep]
    # -c (phi - phi_n) = J acc + d1 w + d2 w|w|   (linear in J, d1, d2)
    X = np.column_stack([acc, w, w * np.abs(w)])
    y = -c * (ph - phi_n)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    J, d1, d2 = (float(x) for x in coef)
    if not np.isfinite(J) or J <= 0:
        return None
    return {"J": J, "d1": max(d1, 0.0), "d2": max(d2, 0.0)}


def _dissipation_mismatch(t, phi, k1, k2, k3, k4, law, direction) -> tuple[float, float]:
    """``dW = W_reverse - W_forward`` from the two strokes' speed profiles over angle."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    def speed_over_angle(a: int, b: int):
        lo, hi = max(a - 30, 0), min(b + 30, len(t) - 1)
        dt = float(np.median(np.diff(t[lo:hi])))
        speed = np.abs(savgol_filter(phi[lo:hi + 1], 41, 3, deriv=1, delta=dt))
        ang = phi[lo:hi + 1]
        order = np.argsort(ang)
        return ang[order], speed[order]

    af, sf = speed_over_angle(k1, k2)
    ar, sr = speed_over_angle(k3, k4)
    grid = np.linspace(phi[k1], phi[k2], 200)
    vf, vr = np.interp(grid, af, sf), np.interp(grid, ar, sr)

    def D(v):
        return law["d1"] * v + law["d2"] * v * v

    dW = float(np.trapezoid(D(vr) - D(vf), direction * grid)) if len(grid) > 1 else 0.0
    return dW, 0.5 * abs(dW)


def _voltage_offset(t: np.ndarray, psi: np.ndarray, u: np.ndarray) -> float:
    """Intercept of the terminal voltage against the flywheel rate on an open-circuit stroke, V."""
    omega = np.gradient(smooth_angle(t, psi), t)
    X = np.column_stack([np.ones_like(omega), omega])
    coef, *_ = np.linalg.lstsq(X, u, rcond=None)
    return float(coef[0])


def _electric_work(t: np.ndarray, u: np.ndarray, i: np.ndarray, R: float, L: float) -> float:
    """Electric energy minus ohmic loss and the change of magnetic energy, J (the patent's form).

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
    electric = float(np.sum(u[1:] * mean * h))
    ohmic = R * float(np.sum(mean_sq * h))
    magnetic = 0.5 * L * (i[-1] ** 2 - i[0] ** 2)
    return electric - ohmic - magnetic
