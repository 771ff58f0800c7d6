"""A66 at each drive frequency from forced-oscillation records, for water that remembers.

The forced method (:mod:`~addedinertia_env.identify.forced`, the Chinese patent's) fits one
inertia over all its frequencies: right when the added inertia is one number, not when it
depends on the frequency. Here each driven segment gives A66 at its own frequency, read in
steady state, and A66(0) is extrapolated from those points.

**The hull's own equation** (as in :mod:`~addedinertia_env.identify.memory`: the motor's
torque is internal to hull + flywheel, so the current and its gain error drop out)::

    (J_h + J_f) phi'' + J_f psi'' + Q_rad + drag = -c (phi - phi_n)

In steady motion at the drive frequency ``omega`` the radiation moment is
``-A66(omega) phi'' - B66(omega) phi'`` (no history left to remember), and the drags'
fundamental is in phase with the rate. With ``Phi`` and ``Psi`` the complex amplitudes
of the hull's and the flywheel's (encoder) angles at ``omega``::

    A66(omega) = c / omega^2 - J_h - J_f - J_f Re(Psi / Phi),
    B(omega)   = J_f omega Im(Psi / Phi)        (water + bearing + drag, N m s)

The amplitudes are least-squares fits over the segment's measured part (after its
``t_settled``: the water's memory of the switch has died out) of a constant, a quadratic
drift (the flywheel's angle creeps), the drive frequency, and the hull's own swing (its
natural frequency, refined around the record's half-swing guess): a lightly damped hull
keeps the transient of each switch for minutes, so it is fitted, not waited out.

Uncertainty (95 %): the two halves of the measured part read separately (their half
difference, a systematic the least squares does not see) in quadrature with the least
squares' own (white-residual) standard error; ``c`` and ``J_f`` as the rig block states
them (taken as known, like the other methods).

**A66(0)** (:func:`extrapolate_zero`): every passive kernel's added inertia is even in
``omega`` near zero, ``A66(omega) = A66(0) + a2 omega^2 + a4 omega^4 + ...``; the
points below the swing frequency are fitted by the two lowest orders of that expansion
(the interval is the union of both), so the extrapolation carries the spread of the two.

Only the record's samples, ``rig`` and ``experiment`` blocks are read; never ``truth``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from addedinertia_env.identify.common import IdentificationError
from addedinertia_env.records.record import RunRecord

Z95 = 1.96
NATURAL_SCAN = np.linspace(0.96, 1.04, 41)  # the hull's own frequency, as a share of the half-swing guess
DECAY_SCAN = (0.0, 0.01, 0.02, 0.04, 0.08, 0.16)  # 1/s: the hull's own swing's decay rate
MIN_MEASURED_PERIODS = 1.5  # drive periods a segment's measured part needs
BELOW_SWING = 0.95  # points used for A66(0): drive frequency under this share of the swing frequency


@dataclass
class FrequencyPoint:
    """A66 at one drive frequency (kg m^2), from one driven segment."""

    run: str
    segment: int
    omega: float  # rad/s
    A66: float
    sigma: float  # 1.96 sigma = half the 95 % interval
    damping: float  # N m s, everything in phase with the rate
    amplitude: float  # rad, hull swing at omega
    measured_s: float  # s of steady drive read
    natural_omega: float  # rad/s, the hull's own swing fitted beside it
    natural_decay: float  # 1/s, its decay rate
    swing_omega: float  # rad/s, the record's half-swing frequency (experiment.omega_guess)

    @property
    def ci95(self) -> tuple[float, float]:
        """The 95 % interval of A66 at this frequency, kg m^2."""
        return self.A66 - Z95 * self.sigma, self.A66 + Z95 * self.sigma


def forced_points(records: list[RunRecord]) -> list[FrequencyPoint]:
    """One :class:`FrequencyPoint` per driven segment of every forced-oscillation record."""
    if not records:
        raise IdentificationError("forced runs: no records given")
    out = []
    for rec in records:
        exp = rec.experiment
        if exp.get("kind") != "forced-oscillation":
            raise IdentificationError(f"{rec.name}: A66 per frequency needs a record of kind 'forced-oscillation', "
                                      f"not {exp.get('kind')!r}; simulate one with `addedinertia simulate --kind "
                                      "forced-oscillation --frequencies HZ HZ HZ --settle S`")
        segments = exp.get("segments")
        guess = exp.get("omega_guess")
        if not isinstance(segments, list) or not segments or not isinstance(guess, (int, float)) or not guess > 0:
            raise IdentificationError(f"{rec.name}: experiment.segments (a list of {{'omega', 't_start', 't_end'}}) "
                                      f"and experiment.omega_guess (rad/s > 0) are needed; got {segments!r}, {guess!r}")
        for k, seg in enumerate(segments):
            point = _segment_point(rec, k, seg, float(guess))
            if point is not None:
                out.append(point)
    if not out:
        raise IdentificationError(f"{', '.join(r.name for r in records)}: no driven segment has "
                                  f"{MIN_MEASURED_PERIODS} measured periods after its settling time")
    return out


def _segment_point(rec: RunRecord, k: int, seg: dict, guess: float) -> FrequencyPoint | None:
    try:
        omega = float(seg["omega"])
        t_a = float(seg.get("t_settled", seg["t_start"]))
        t_b = float(seg["t_end"])
    except (KeyError, TypeError, ValueError):
        raise IdentificationError(f"{rec.name}: experiment.segments[{k}] = {seg!r}: expected 'omega' (rad/s), "
                                  "'t_start', 't_end' and optionally 't_settled' (s)") from None
    if not (omega > 0 and t_b - t_a >= MIN_MEASURED_PERIODS * 2 * math.pi / omega):
        return None
    t = np.asarray(rec.t, float)
    sel = (t >= t_a) & (t <= t_b)
    if "brake" in rec.samples:
        sel &= ~np.asarray(rec["brake"], bool)
    full = _amplitudes(t[sel], np.asarray(rec["phi"], float)[sel], np.asarray(rec["psi"], float)[sel], omega, guess)
    if full is None:
        return None
    known = rec.known
    A, B = _inertia(full[0], omega, known)
    halves = []
    idx = np.flatnonzero(sel)
    for part in (idx[: len(idx) // 2], idx[len(idx) // 2:]):
        sub = _amplitudes(t[part], np.asarray(rec["phi"], float)[part], np.asarray(rec["psi"], float)[part], omega,
                          guess, natural=full[2])
        if sub is not None:
            halves.append(_inertia(sub[0], omega, known)[0])
    s_halves = 0.5 * abs(halves[0] - halves[1]) if len(halves) == 2 else 0.0
    return FrequencyPoint(run=rec.name, segment=k, omega=omega, A66=A, sigma=math.hypot(full[1], s_halves), damping=B,
                          amplitude=abs(full[0][0]), measured_s=float(t_b - t_a), natural_omega=full[2][0],
                          natural_decay=full[2][1], swing_omega=guess)


def _inertia(amps, omega: float, known) -> tuple[float, float]:
    Phi, Psi = amps
    R = Psi / Phi
    A = known.c_torsion / omega**2 - known.J_hull - known.J_flywheel - known.J_flywheel * R.real
    return float(A), float(known.J_flywheel * omega * R.imag)


def _design(tau: np.ndarray, omega: float, natural: tuple[float, float]) -> np.ndarray:
    wn, decay = natural
    env = np.exp(-decay * (tau - tau[0]))
    return np.column_stack([np.ones_like(tau), tau, tau * tau, np.cos(omega * tau), np.sin(omega * tau),
                            env * np.cos(wn * tau), env * np.sin(wn * tau)])


def _amplitudes(t, phi, psi, omega: float, guess: float, natural: float | None = None):
    """((Phi, Psi) complex amplitudes at ``omega``, the 1-sigma of A66 from the white residual, natural omega)."""
    if len(t) < 50:
        return None
    tau = t - 0.5 * (t[0] + t[-1])
    scale = max(abs(tau[0]), 1e-9)
    tau_n = tau / scale  # the drift's columns on a unit scale
    candidates = [natural] if natural is not None else [(r * guess, d) for r in NATURAL_SCAN for d in DECAY_SCAN]
    best = None
    for wn in candidates:
        if abs(wn[0] - omega) < 2 * math.pi / (t[-1] - t[0]):  # not separable from the drive over this span
            continue
        X = _design(tau, omega, wn)
        X[:, 1], X[:, 2] = tau_n, tau_n * tau_n
        coef, *_ = np.linalg.lstsq(X, phi, rcond=None)
        rss = float(np.sum((phi - X @ coef) ** 2))
        if best is None or rss < best[0]:
            best = (rss, wn, X)
    if best is None:
        return None
    _, wn, X = best
    XtX_inv = np.linalg.inv(X.T @ X)
    cp = XtX_inv @ X.T @ phi
    cq = XtX_inv @ X.T @ psi
    Phi, Psi = complex(cp[3], -cp[4]), complex(cq[3], -cq[4])
    n, p = X.shape
    s2_psi = float(np.sum((psi - X @ cq) ** 2)) / max(n - p, 1)
    s2_phi = float(np.sum((phi - X @ cp) ** 2)) / max(n - p, 1)
    # A66 depends on Re(Psi/Phi): its standard error from the amplitudes' (white) standard errors
    se_amp_psi = math.sqrt(s2_psi * 0.5 * (XtX_inv[3, 3] + XtX_inv[4, 4]))
    se_amp_phi = math.sqrt(s2_phi * 0.5 * (XtX_inv[3, 3] + XtX_inv[4, 4]))
    ratio = abs(Psi / Phi)
    se_R = ratio * math.hypot(se_amp_psi / max(abs(Psi), 1e-300), se_amp_phi / abs(Phi))
    return (Phi, Psi), se_R, wn


def extrapolate_zero(points: list[FrequencyPoint], swing_omega: float | None = None) -> dict:
    """A66(0) from the points below the swing frequency: weighted least squares of
    ``A66(0) + a2 omega^2`` and ``A66(0) + a2 omega^2 + a4 omega^4`` (the latter only with
    three or more frequencies); the value of the first, the interval the union of both."""
    sw = swing_omega if swing_omega is not None else float(np.median([p.swing_omega for p in points]))
    use = [p for p in points if p.omega < BELOW_SWING * sw]
    if len({round(p.omega, 9) for p in use}) < 2:
        raise IdentificationError(f"A66(0) from forced runs needs at least two drive frequencies under "
                                  f"{BELOW_SWING:g} x the swing frequency ({sw:.4g} rad/s); got "
                                  f"{sorted({round(p.omega, 4) for p in use})} rad/s")
    w = np.array([p.omega for p in use])
    y = np.array([p.A66 for p in use])
    s = np.array([max(p.sigma, 1e-12) for p in use])
    fits = {}
    for name, powers in (("a2", (0, 2)), ("a2a4", (0, 2, 4))):
        if len(set(w.round(9))) < len(powers):
            continue
        X = np.column_stack([w**k for k in powers]) / s[:, None]
        cov = np.linalg.inv(X.T @ X)
        coef = cov @ X.T @ (y / s)
        resid = (y - (X * s[:, None]) @ coef) / s
        dof = len(y) - len(powers)
        birge = math.sqrt(max(float(resid @ resid) / dof, 1.0)) if dof > 0 else 1.0
        sig = math.sqrt(cov[0, 0]) * birge
        fits[name] = {"A66_zero": float(coef[0]), "ci95": [float(coef[0] - Z95 * sig), float(coef[0] + Z95 * sig)],
                      "coefficients": [float(c) for c in coef]}
    first = fits["a2"]
    lo = min(f["ci95"][0] for f in fits.values())
    hi = max(f["ci95"][1] for f in fits.values())
    return {"A66_zero": first["A66_zero"], "ci95": [lo, hi], "families": fits,
            "frequencies_used": sorted({float(x) for x in w}), "swing_omega": float(sw)}


def forced_summary(records: list[RunRecord]) -> dict:
    """The JSON-able reading of forced records: every point, and A66(0) where it can be extrapolated."""
    points = forced_points(records)
    out = {"points": [{**asdict(p), "ci95": list(p.ci95)} for p in points]}
    try:
        out["A66_zero"] = extrapolate_zero(points)
    except IdentificationError as e:
        out["A66_zero"] = f"not extrapolated: {e}"
    return out


def with_forced(result, forced_records: list[RunRecord]):
    """The energy method's result with forced runs read beside it as evidence about the water's
    memory: ``details["forced"]`` holds A66 at every drive frequency and A66(0) extrapolated
    from them. Where the other records leave the memory ``not identifiable`` (or none were
    corrected) and the forced runs give A66(0), that value and its interval become
    ``lambda66`` (``details["lambda66_from"]`` says so); otherwise the estimate is unchanged
    and the forced A66(0) stands beside it as a check (per-frequency accuracy ~0.1-0.2 %,
    docs/RADIATION_MEMORY.md: coarser than the corrected energy method)."""
    from addedinertia_env.identify.common import Result  # noqa: PLC0415

    details = dict(result.details)
    try:
        summary = forced_summary(forced_records)
    except IdentificationError as e:
        details["forced"] = f"not read: {e}"
        return Result(method=result.method, lambda66=result.lambda66, ci95=result.ci95,
                      n_intervals=result.n_intervals, details=details)
    details["forced"] = summary
    value, ci = result.lambda66, result.ci95
    zero = summary["A66_zero"]
    unidentified = str(details.get("memory", "")).startswith("not identifiable")
    if unidentified and isinstance(zero, dict):
        details["lambda66_from"] = ("forced runs: A66(0) extrapolated from A66 at the drive frequencies under the "
                                    "swing (the reverse runs' memory was not identifiable)")
        details["lambda66_unidentified_memory"] = value
        value, ci = zero["A66_zero"], tuple(zero["ci95"])
        details.pop("ci95_widened_by", None)
    return Result(method=result.method, lambda66=float(value), ci95=(float(ci[0]), float(ci[1])),
                  n_intervals=result.n_intervals, details=details)
