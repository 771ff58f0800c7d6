"""The forced-oscillation method (Chinese patent, source 003; physics.md section 5) on our rig.

The hull's own equation (the two rows of the mass matrix subtracted, physics.md s2) is::

    (J_h + lambda66) phi'' = -c (phi - phi_n) - (k_t i + M_f(Omega)) + Q_w(phi') + Q_b(phi')

where ``-(k_t i + M_f)`` is the reaction of the motor (torque and rotor-bearing friction)
on the hull. At the instants where the hull rate is zero the velocity-dependent damping
``Q_w + Q_b`` vanishes (linear and quadratic alike), so the measured torque
``y = -c (phi - phi_n) - k_t i - M_f`` equals ``(J_h + lambda66) phi''``. Collecting those
instants over several drive frequencies and regressing ``y = J x + b`` on
``x = phi''`` gives the slope ``J = J_h + lambda66``, as the patent does with force and
acceleration.

Signals: the current offset is calibrated where the motor is passive (before the first
driven segment; the true current is 0 there) and removed. Angle, rate, acceleration,
current and flywheel rate all go through the *same* centred Savitzky-Golay filter
(quintic, a sixth of a drive period wide, at most 401 samples), so the filtered signals obey the same linear
equation; the zero-rate instants are located on the filtered rate and every term is
interpolated there. Instants within half a filter window of a segment's ends are left
out (the filter straddles the switch of frequency there).

Uncertainty (95 %): the slope's standard error from the regression residuals (Student
t, ``n - 2`` degrees of freedom), and the current-sensor gain (0.5 %, physics.md section
7): the slope of the motor part ``-k_t i`` alone against ``x`` times 0.5 %, in quadrature.
Several records are pooled by inverse variance. ``c`` and ``k_t`` are taken as known (a
static calibration and the data sheet), as the record's ``rig`` block says.

Only the record's samples, ``rig`` and ``experiment`` blocks are used; never ``truth``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.identify.common import IdentificationError, Result, pooled_interval

CURRENT_GAIN_UNCERTAINTY = 0.005  # relative, current-sensor gain (physics.md section 7)
FILTER_PERIOD_FRACTION = 1.0 / 6.0  # Savitzky-Golay window, as a share of the drive period
FILTER_ORDER = 5
# scipy's Savitzky-Golay coefficients lose precision for long windows at order 5 (at
# 1000 samples the second derivative is wrong by orders of magnitude): cap the window.
FILTER_MAX_SAMPLES = 401


@dataclass
class Instant:
    """One zero-rate instant."""

    run: str
    segment: int
    t: float  # s
    accel: float  # rad/s^2, x
    torque: float  # N m, y = -c (phi - phi_n) - k_t i - M_f
    motor_torque: float  # N m, the -k_t i part of y


def identify_forced(records: list[RunRecord]) -> Result:
    """lambda66 (kg m^2) from one or more forced-oscillation records, with a 95 % interval."""
    if not records:
        raise IdentificationError("forced method: no records given")
    values, sigmas, fits, instants = [], [], [], []
    for rec in records:
        run_instants = _instants(rec)
        fit = _regress(rec, run_instants)
        values.append(fit["lambda66"])
        sigmas.append(fit["sigma"])
        fits.append(fit)
        instants += run_instants
    value, lo, hi = pooled_interval(np.array(values), np.array(sigmas))
    return Result(method="forced", lambda66=value, ci95=(lo, hi), n_intervals=len(instants),
                  details={"n_runs": len(records), "per_run": values, "fits": fits,
                           "intervals": [asdict(x) for x in instants]})


def _regress(rec: RunRecord, instants: list[Instant]) -> dict:
    x = np.array([p.accel for p in instants])
    y = np.array([p.torque for p in instants])
    m = np.array([p.motor_torque for p in instants])
    n = len(x)
    X = np.column_stack([x, np.ones(n)])
    XtX_inv = np.linalg.inv(X.T @ X)
    coef = XtX_inv @ X.T @ y
    resid = y - X @ coef
    s2 = float(resid @ resid) / (n - 2)
    se_slope = math.sqrt(s2 * XtX_inv[0, 0])
    from scipy.stats import t as student_t  # noqa: PLC0415

    t_factor = float(student_t.ppf(0.975, n - 2)) / 1.96  # express the noise part as a 1.96-sigma equivalent
    motor_slope = float((XtX_inv @ X.T @ m)[0])
    s_gain = CURRENT_GAIN_UNCERTAINTY * abs(motor_slope)
    J_h = rec.known.J_hull
    per_segment = {}
    for seg in sorted({p.segment for p in instants}):
        sel = np.array([p.segment == seg for p in instants])
        sgn = np.sign(x[sel])  # the patent: average torque and acceleration over a frequency's instants
        per_segment[seg] = {"mean_abs_accel": float(np.mean(sgn * x[sel])), "mean_abs_torque": float(np.mean(sgn * y[sel])),
                            "n": int(sel.sum())}
    return {"run": rec.name, "J_total": float(coef[0]), "lambda66": float(coef[0]) - J_h, "intercept": float(coef[1]),
            "sigma": math.hypot(t_factor * se_slope, s_gain), "sigma_regression": se_slope, "sigma_gain": s_gain,
            "residual_rms": math.sqrt(s2), "motor_slope": motor_slope, "per_segment": per_segment}


def _instants(rec: RunRecord) -> list[Instant]:
    from scipy.signal import savgol_filter  # noqa: PLC0415

    kind = rec.experiment.get("kind")
    if kind != "forced-oscillation":
        raise IdentificationError(f"{rec.name}: the forced method needs a record of kind 'forced-oscillation', "
                                  f"not {kind!r}; simulate one with `addedinertia simulate --kind forced-oscillation`")
    segments = rec.experiment.get("segments")
    if not isinstance(segments, list) or not segments or not all(
            isinstance(s, dict) and all(isinstance(s.get(k), (int, float)) for k in ("omega", "t_start", "t_end"))
            for s in segments):
        raise IdentificationError(f"{rec.name}: experiment.segments must list the driven segments as "
                                  "{'omega': rad/s, 't_start': s, 't_end': s}; got " f"{segments!r}")
    rig = rec.known
    c, phi_n, k_t = rig.c_torsion, rig.phi_neutral, rig.k_t
    f_visc, f_coul = rig.friction_viscous, rig.friction_coulomb
    t, phi, psi, i = rec.t, rec["phi"], rec["psi"], rec["i"]
    t_drive = min(float(s["t_start"]) for s in segments)
    passive = t < t_drive
    if "i_cmd" in rec.samples:
        passive &= rec["i_cmd"] == 0.0
    if passive.sum() < 50:
        raise IdentificationError(f"{rec.name}: fewer than 50 passive samples before the first driven segment "
                                  f"(t < {t_drive:.3f} s) to calibrate the current offset")
    i_offset = float(np.mean(i[passive]))
    dt = float(np.median(np.diff(t)))
    out: list[Instant] = []
    for k, s in enumerate(segments):
        sel = np.nonzero((t > float(s["t_start"])) & (t <= float(s["t_end"])))[0]
        period = 2.0 * math.pi / float(s["omega"])
        n = max(FILTER_ORDER + 2, min(int(round(FILTER_PERIOD_FRACTION * period / dt)), FILTER_MAX_SAMPLES) | 1)
        if len(sel) < 3 * n:
            continue
        ph, ps, cur = phi[sel], psi[sel], i[sel] - i_offset
        ph_f = savgol_filter(ph, n, FILTER_ORDER)
        w_f = savgol_filter(ph, n, FILTER_ORDER, deriv=1, delta=dt)
        a_f = savgol_filter(ph, n, FILTER_ORDER, deriv=2, delta=dt)
        i_f = savgol_filter(cur, n, FILTER_ORDER)
        om_f = savgol_filter(ps, n, FILTER_ORDER, deriv=1, delta=dt)
        motor = -k_t * i_f
        y = -c * (ph_f - phi_n) + motor + f_visc * om_f + f_coul * np.sign(om_f)
        half = n // 2 + 1
        zc = np.nonzero(np.sign(w_f[half:-half - 1]) * np.sign(w_f[half + 1:-half]) < 0)[0] + half
        for j in zc:
            frac = w_f[j] / (w_f[j] - w_f[j + 1])  # linear interpolation to the zero of the rate

            def at(v, j=j, frac=frac):
                return float(v[j] + frac * (v[j + 1] - v[j]))

            out.append(Instant(run=rec.name, segment=k, t=at(t[sel]), accel=at(a_f), torque=at(y), motor_torque=at(motor)))
    if len(out) < 4 or len({p.segment for p in out}) < 2:
        raise IdentificationError(f"{rec.name}: {len(out)} zero-rate instants in {len({p.segment for p in out})} "
                                  "frequency segment(s); need at least 4 in 2 (drive more periods per frequency)")
    return out
