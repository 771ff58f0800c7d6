"""Damping laws from a series of successive free-decay amplitudes (the textbook's record).

Input: a CSV with columns ``swing`` (successive half-swing numbers, 1, 2, 3, ...) and
``theta_deg`` (amplitude in degrees, > 0); other columns are ignored. This is the form
of ``../shared/data/textbook_roll_decay.csv`` (source 004, tables 6.1 and 6.2).

Two things are done with it:

1. **The textbook's procedure reproduced** (``textbook_processing``): formula 6.17
   (Blagoveshchensky) ``nu = 2 dtheta / (pi theta_mean)`` and formula 6.18
   ``nu = (2/pi) d ln(theta)``, on the raw decrements and, where the textbook's own
   processing table is given, on its hand-smoothed decrements, compared with its printed
   columns (maximum absolute difference).
2. **Our own analysis of the raw series** (``fit_laws``): candidate envelope laws
   ``d theta / dN = -f(theta)`` per half swing ``N``, each integrated in closed form and
   fitted to the *amplitudes* by output error (so the reading errors stay independent,
   which they are not in differenced decrements), weighted by the reading resolution:

   ========================  ===============================
   law                        f(theta)
   ========================  ===============================
   ``linear``                 a theta (the nominal law)
   ``quadratic``              b theta^2
   ``coulomb``                c
   ``linear+quadratic``       a theta + b theta^2
   ``linear+coulomb``         a theta + c
   ========================  ===============================

   with chi-square against the resolution, AIC and BIC, parameter 95 % intervals,
   residual runs and lag-1 autocorrelation. For ``linear`` damping ``nu = 2 a / pi`` is
   constant; a nu that falls with the amplitude says quadratic, one that rises says dry.

The amplitude resolution: every printed amplitude is a multiple of 0.1025 deg (0.5 mm of
trace at 0.205 deg/mm, ``../shared/data/README.md``), so a rounding error uniform over
one step has a standard deviation 0.1025 / sqrt(12) = 0.0296 deg.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import stats
from scipy.optimize import least_squares

READING_RESOLUTION_DEG = 0.1025  # deg, one 0.5 mm step of trace at 0.205 deg/mm (data README)
READING_SIGMA_DEG = READING_RESOLUTION_DEG / math.sqrt(12.0)
MIN_AMPLITUDES = 5


class DecayInputError(ValueError):
    """An amplitude file that cannot be analysed; the message names file, line, column and value."""


@dataclass
class Amplitudes:
    """A free-decay amplitude series read from ``path``: half-swing numbers and amplitudes in deg."""

    path: str
    swing: np.ndarray  # half-swing numbers
    theta: np.ndarray  # deg


def read_amplitudes(path: str | Path) -> Amplitudes:
    """Read and check an amplitude series; raises :class:`DecayInputError` on anything doubtful."""
    path = Path(path)
    rows = list(csv.reader(_read_text(path, "an amplitude CSV with columns 'swing' and 'theta_deg'").splitlines()))
    if not rows:
        raise DecayInputError(f"{path}: empty file; expected a header with columns 'swing' and 'theta_deg'")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in ("swing", "theta_deg") if c not in header]
    if missing:
        raise DecayInputError(f"{path}: line 1: missing column(s) {missing}; header is {header}, expected "
                              "'swing' (half-swing number) and 'theta_deg' (amplitude, degrees)")
    ks, kt = header.index("swing"), header.index("theta_deg")
    swing, theta = [], []
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise DecayInputError(f"{path}: line {n}: {len(row)} fields, expected {len(header)} as in the header")
        for col, k, out in (("swing", ks, swing), ("theta_deg", kt, theta)):
            text = row[k].strip()
            try:
                v = float(text)
            except ValueError:
                raise DecayInputError(f"{path}: line {n}, column '{col}': {text!r} is not a number; expected a finite number") from None
            if not math.isfinite(v):
                raise DecayInputError(f"{path}: line {n}, column '{col}': {text!r}; expected a finite number")
            out.append(v)
        if swing[-1] != round(swing[-1]):
            raise DecayInputError(f"{path}: line {n}, column 'swing': {row[ks].strip()!r}; expected a whole number")
        if theta[-1] <= 0:
            raise DecayInputError(f"{path}: line {n}, column 'theta_deg': {row[kt].strip()!r}; expected an "
                                  "amplitude > 0 degrees (amplitudes are magnitudes)")
        if len(swing) > 1 and swing[-1] != swing[-2] + 1:
            raise DecayInputError(f"{path}: line {n}, column 'swing': {swing[-1]:g} after {swing[-2]:g}; expected "
                                  "successive half swings numbered 1, 2, 3, ... with none missing")
    if len(theta) < MIN_AMPLITUDES:
        raise DecayInputError(f"{path}: {len(theta)} amplitude(s); expected at least {MIN_AMPLITUDES}")
    th = np.array(theta)
    if th[-1] >= th[0]:
        raise DecayInputError(f"{path}: the last amplitude {th[-1]:g} deg is not below the first {th[0]:g} deg; "
                              "expected a decaying record")
    return Amplitudes(path=str(path), swing=np.array(swing), theta=th)


# --- the textbook's procedure --------------------------------------------------------

def nu_blagoveshchensky(dtheta, theta_mean):
    """Formula 6.17: nu = 2 dtheta / (pi theta_mean)."""
    return 2.0 * np.asarray(dtheta) / (math.pi * np.asarray(theta_mean))


def nu_logarithmic(dln_theta):
    """Formula 6.18: nu = (2 / pi) d ln(theta)."""
    return 2.0 / math.pi * np.asarray(dln_theta)


def _read_text(path: Path, what: str) -> str:
    """The text of ``path``; DecayInputError naming the file and ``what`` was expected otherwise."""
    if not path.exists():
        raise DecayInputError(f"{path}: no such file; expected {what}")
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise DecayInputError(f"{path}: not UTF-8 text; expected {what}") from None
    except OSError as e:
        raise DecayInputError(f"{path}: cannot read ({e.strerror}); expected {what}") from None


def _read_processing(path: Path) -> dict[str, np.ndarray]:
    rows = list(csv.DictReader(_read_text(path, "the textbook's processing table (CSV)").splitlines()))
    if not rows:
        raise DecayInputError(f"{path}: no rows; expected the textbook's processing table with a header line")
    need = ("swing", "dtheta_raw_deg", "dtheta_smoothed_deg", "theta_mean_deg", "nu_formula_6_17", "ln_theta",
            "dln_raw", "dln_smoothed", "nu_formula_6_18")
    missing = [c for c in need if c not in rows[0]]
    if missing:
        raise DecayInputError(f"{path}: line 1: missing column(s) {missing} of the textbook processing table")
    out = {}
    for c in need:
        vals = []
        for n, r in enumerate(rows, start=2):
            text = (r[c] or "").strip()
            try:
                vals.append(float(text) if text else math.nan)
            except ValueError:
                raise DecayInputError(f"{path}: line {n}, column '{c}': {text!r} is not a number; expected a finite number") from None
        out[c] = np.array(vals)
    return out


def textbook_processing(amp: Amplitudes, processing: str | Path | None) -> dict:
    """Formulas 6.17 and 6.18 on the raw series; and, with the textbook's table, on its smoothed decrements."""
    th = amp.theta
    dtheta = th[:-1] - th[1:]
    theta_mean = 0.5 * (th[:-1] + th[1:])
    dln = np.log(th[:-1]) - np.log(th[1:])
    out: dict = {"raw": {"swing": amp.swing[1:].tolist(), "dtheta_deg": dtheta.tolist(),
                         "theta_mean_deg": theta_mean.tolist(),
                         "nu_6_17": nu_blagoveshchensky(dtheta, theta_mean).tolist(),
                         "nu_6_18": nu_logarithmic(dln).tolist()}}
    if processing is None:
        out["printed"] = None
        return out
    p = _read_processing(Path(processing))
    rows = ~np.isnan(p["dtheta_smoothed_deg"])
    sw = p["swing"][rows]
    if not np.array_equal(sw, amp.swing[1:][: len(sw)]):
        raise DecayInputError(f"{processing}: swings {sw.tolist()} do not match the amplitude file's "
                              f"{amp.swing[1:].tolist()}")
    nu17 = nu_blagoveshchensky(p["dtheta_smoothed_deg"][rows], p["theta_mean_deg"][rows])
    nu18 = nu_logarithmic(p["dln_smoothed"][rows])
    n = len(sw)

    def cmp(ours, printed):
        d = np.abs(np.asarray(ours) - np.asarray(printed))
        return {"max_abs_diff": float(np.max(d)), "at_swing": int(sw[int(np.argmax(d))])}

    out["printed"] = {
        "file": str(processing), "swing": sw.tolist(),
        "dtheta_smoothed_deg": p["dtheta_smoothed_deg"][rows].tolist(),
        "theta_mean_deg": p["theta_mean_deg"][rows].tolist(),
        "dln_smoothed": p["dln_smoothed"][rows].tolist(),
        "nu_6_17_printed": p["nu_formula_6_17"][rows].tolist(), "nu_6_17_reproduced": nu17.tolist(),
        "nu_6_18_printed": p["nu_formula_6_18"][rows].tolist(), "nu_6_18_reproduced": nu18.tolist(),
        "check_nu_6_17": cmp(nu17, p["nu_formula_6_17"][rows]),
        "check_nu_6_18": cmp(nu18, p["nu_formula_6_18"][rows]),
        "check_dtheta_raw": cmp(dtheta[:n], p["dtheta_raw_deg"][rows]),
        "check_theta_mean": cmp(theta_mean[:n], p["theta_mean_deg"][rows]),
        "check_ln_theta": {"max_abs_diff": float(np.nanmax(np.abs(np.log(th) - p["ln_theta"][: len(th)])))},
        "check_dln_raw": cmp(dln[:n], p["dln_raw"][rows]),
        # The hand-smoothed decrements against the raw ones: how much the author's curve moved them.
        "smoothing_shift_deg": {"mean": float(np.mean(p["dtheta_smoothed_deg"][rows] - dtheta[:n])),
                                "rms": float(np.sqrt(np.mean((p["dtheta_smoothed_deg"][rows] - dtheta[:n]) ** 2)))},
    }
    return out


# --- damping laws fitted to the raw amplitudes -------------------------------------------

LAWS = {
    "linear": ("a",),
    "quadratic": ("b",),
    "coulomb": ("c",),
    "linear+quadratic": ("a", "b"),
    "linear+coulomb": ("a", "c"),
}
UNITS = {"a": "1/half-swing", "b": "1/(deg half-swing)", "c": "deg/half-swing", "theta0": "deg"}


def envelope(law: str, theta0: float, params: dict[str, float], n: np.ndarray) -> np.ndarray:
    """Closed-form solution of d theta/dN = -f(theta), theta(0) = theta0, after ``n`` half swings."""
    a, b, c = params.get("a", 0.0), params.get("b", 0.0), params.get("c", 0.0)
    n = np.asarray(n, dtype=float)
    if law == "linear":
        return theta0 * np.exp(-a * n)
    if law == "quadratic":
        return theta0 / (1.0 + b * theta0 * n)
    if law == "coulomb":
        return theta0 - c * n
    if law == "linear+quadratic":
        if abs(a) < 1e-12:
            return theta0 / (1.0 + b * theta0 * n)
        e = np.exp(-a * n)
        return a * theta0 * e / (a + b * theta0 * (1.0 - e))
    if law == "linear+coulomb":
        if abs(a) < 1e-12:
            return theta0 - c * n
        return (theta0 + c / a) * np.exp(-a * n) - c / a
    raise ValueError(f"unknown law {law!r}; expected one of {', '.join(LAWS)}")


def law_nu(law: str, params: dict[str, float], theta_deg) -> np.ndarray:
    """Textbook nu = (2/pi) f(theta) / theta that the law implies at amplitude theta."""
    th = np.asarray(theta_deg, dtype=float)
    a, b, c = params.get("a", 0.0), params.get("b", 0.0), params.get("c", 0.0)
    return 2.0 / math.pi * (a + b * th + c / th)


@dataclass
class LawFit:
    """One damping law fitted to an amplitude series (:func:`fit_law`).

    ``params`` in the units of :data:`UNITS` (``theta0`` deg, ``a`` 1/half-swing, ``b``
    1/(deg half-swing), ``c`` deg/half-swing), with standard errors and 95 % intervals;
    ``residuals`` in deg; chi-square against the reading resolution, AIC and BIC (sigma
    fitted), lag-1 autocorrelation and the sign-runs test of the residuals.
    """

    law: str
    params: dict[str, float]
    stderr: dict[str, float]
    ci95: dict[str, list[float]]
    residuals: np.ndarray  # deg
    chi2: float
    dof: int
    p_value: float  # chi-square goodness of fit against the reading resolution
    aic: float
    bic: float
    lag1: float
    runs: int  # sign runs of the residuals
    runs_expected: float
    runs_p: float
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """The fit as a JSON-ready dict (parameters with their units, statistics, residuals in deg)."""
        return {"law": self.law, "params": self.params, "units": {k: UNITS[k] for k in self.params},
                "stderr": self.stderr, "ci95": self.ci95, "rms_deg": float(np.sqrt(np.mean(self.residuals**2))),
                "max_abs_residual_deg": float(np.max(np.abs(self.residuals))), "chi2": self.chi2, "dof": self.dof,
                "chi2_p": self.p_value, "aic": self.aic, "bic": self.bic, "lag1": self.lag1,
                "sign_runs": self.runs, "sign_runs_expected": self.runs_expected, "sign_runs_p": self.runs_p,
                "residuals_deg": self.residuals.tolist(), **self.extra}


def _runs_test(r: np.ndarray) -> tuple[int, float, float]:
    """Wald-Wolfowitz runs test on residual signs: (runs, expected, two-sided p)."""
    s = r > 0
    n1, n2 = int(s.sum()), int((~s).sum())
    runs = 1 + int(np.sum(s[1:] != s[:-1]))
    n = n1 + n2
    if n1 == 0 or n2 == 0:
        return runs, float(runs), 1.0
    mu = 2 * n1 * n2 / n + 1
    var = 2 * n1 * n2 * (2 * n1 * n2 - n) / (n * n * (n - 1))
    z = (runs - mu) / math.sqrt(var) if var > 0 else 0.0
    return runs, mu, float(2 * stats.norm.sf(abs(z)))


def fit_law(law: str, amp: Amplitudes, sigma: float = READING_SIGMA_DEG) -> LawFit:
    """Fit the envelope law ``law`` (a key of :data:`LAWS`) to ``amp`` by output error.

    ``sigma`` is the reading standard deviation in deg (the residuals are weighted by it).
    Every damping coefficient is bounded at >= 0. Returns the :class:`LawFit`; its intervals
    are widened by the reduced chi-square when the law fits worse than ``sigma`` allows.
    """
    names = ("theta0",) + LAWS[law]
    n = amp.swing - amp.swing[0]
    th = amp.theta
    total_drop = th[0] - th[-1]
    guess = {"theta0": th[0], "a": math.log(th[0] / th[-1]) / n[-1], "b": total_drop / (n[-1] * th[0] * th[-1]),
             "c": total_drop / n[-1]}
    if law in ("linear+quadratic", "linear+coulomb"):
        guess["a"] *= 0.5
        guess["b"] *= 0.5
        guess["c"] *= 0.5
    x0 = np.array([guess[k] for k in names])

    def resid(x):
        return (envelope(law, x[0], dict(zip(names[1:], x[1:])), n) - th) / sigma

    # Damping cannot feed energy in: every coefficient >= 0 (a negative dry friction is no law).
    lo = np.array([0.0] + [0.0] * (len(names) - 1))
    x0 = np.maximum(x0, 1e-9)
    sol = least_squares(resid, x0, bounds=(lo, np.inf), x_scale=np.abs(x0) + 1e-6, xtol=1e-14, ftol=1e-14,
                        gtol=1e-14)
    r = sol.fun * sigma
    chi2 = float(np.sum(sol.fun**2))
    k = len(names)
    dof = len(th) - k
    cov = np.linalg.pinv(sol.jac.T @ sol.jac)  # sigma known (reading resolution)
    # If the law fits worse than the resolution allows, the known-sigma interval is too
    # narrow: widen by the reduced chi-square (as a scale factor, never below 1).
    cov = cov * max(chi2 / dof, 1.0) if dof > 0 else cov
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    tq = stats.t.ppf(0.975, max(dof, 1))
    params = dict(zip(names, map(float, sol.x)))
    # Gaussian log-likelihood. With the reading sigma taken as known: AIC = chi2 + 2k,
    # BIC = chi2 + k ln n. The data reject that sigma (chi2/dof >> 1: hand reading scatters
    # more than the 0.5 mm step), so the ranking uses sigma fitted as well:
    # BIC = n ln(chi2/n) + (k + 1) ln n.
    n_pts = len(th)
    runs, mu, runs_p = _runs_test(r)
    x = r - r.mean()
    lag1 = float(np.sum(x[1:] * x[:-1]) / np.sum(x * x)) if np.sum(x * x) > 0 else 0.0
    return LawFit(law=law, params=params, stderr=dict(zip(names, map(float, se))),
                  ci95={nm: [float(v - tq * s), float(v + tq * s)] for nm, v, s in zip(names, sol.x, se)},
                  residuals=r, chi2=chi2, dof=dof, p_value=float(stats.chi2.sf(chi2, dof)) if dof > 0 else float("nan"),
                  aic=n_pts * math.log(chi2 / n_pts) + 2 * (k + 1),
                  bic=n_pts * math.log(chi2 / n_pts) + (k + 1) * math.log(n_pts), lag1=lag1, runs=runs,
                  runs_expected=mu, runs_p=runs_p,
                  extra={"aic_known_sigma": chi2 + 2 * k, "bic_known_sigma": chi2 + k * math.log(n_pts),
                         "at_bound": [nm for nm, v in zip(names[1:], sol.x[1:]) if v <= 1e-12],
                         "sigma_fitted_deg": float(np.sqrt(np.sum(r**2) / max(dof, 1)))})


def fit_laws(amp: Amplitudes) -> list[LawFit]:
    """Fit every law of :data:`LAWS` to ``amp``; returns the fits, best (lowest BIC) first."""
    fits = [fit_law(law, amp) for law in LAWS]
    fits.sort(key=lambda f: f.bic)
    return fits


def nested_f_test(small: LawFit, big: LawFit) -> float:
    """p-value of the F test that the extra parameter of ``big`` is zero."""
    extra = big.dof and (small.dof - big.dof)
    if not extra or big.chi2 <= 0:
        return float("nan")
    f = ((small.chi2 - big.chi2) / extra) / (big.chi2 / big.dof)
    return float(stats.f.sf(f, extra, big.dof))


def analyse(path: str | Path, processing: str | Path | None = None) -> dict:
    """Everything ``addedinertia decay`` reports; ``processing``: the textbook's processing table, if any."""
    amp = read_amplitudes(path)
    if processing is None:
        sibling = Path(path).with_name(Path(path).stem + "_processing.csv")
        processing = sibling if sibling.exists() else None
    fits = fit_laws(amp)
    by = {f.law: f for f in fits}
    best = fits[0]
    lin = by["linear"]
    out = {
        "file": amp.path, "n_amplitudes": int(len(amp.theta)),
        "reading_sigma_deg": READING_SIGMA_DEG,
        "law": best.law,
        "models": [f.to_json() for f in fits],
        "delta_bic_vs_linear": {f.law: lin.bic - f.bic for f in fits},
        "f_test_p": {"linear -> linear+quadratic": nested_f_test(lin, by["linear+quadratic"]),
                     "linear -> linear+coulomb": nested_f_test(lin, by["linear+coulomb"])},
        "nominal_law": {"law": "linear", "nu": float(2 / math.pi * lin.params["a"]),
                        "chi2_per_dof": lin.chi2 / lin.dof, "sign_runs": lin.runs,
                        "sign_runs_expected": lin.runs_expected, "residual_lag1": lin.lag1},
        "textbook": textbook_processing(amp, processing),
    }
    # Sensitivity: the last three decrements are one to three reading steps; drop them.
    if len(amp.theta) > 8:
        short = Amplitudes(path=amp.path, swing=amp.swing[:-3], theta=amp.theta[:-3])
        sf = fit_laws(short)
        out["without_last_three"] = {"law": sf[0].law, "models": [
            {"law": f.law, "params": f.params, "chi2_per_dof": f.chi2 / f.dof, "bic": f.bic} for f in sf]}
    # nu at the record's mean amplitudes for each law, next to the textbook's
    tm = 0.5 * (amp.theta[:-1] + amp.theta[1:])
    out["nu_by_law"] = {"theta_mean_deg": tm.tolist(),
                        **{f.law: law_nu(f.law, f.params, tm).tolist() for f in fits}}
    return out


def plot(result: dict, path: str | Path) -> Path:
    """Amplitudes with the fitted envelopes, and nu against amplitude (textbook vs laws)."""
    import os  # noqa: PLC0415
    import tempfile  # noqa: PLC0415

    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    amp = read_amplitudes(result["file"])
    n = amp.swing - amp.swing[0]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    ax1.errorbar(amp.swing, amp.theta, yerr=READING_RESOLUTION_DEG / 2, fmt="ko", ms=3, label="read amplitudes")
    ax2r = ax2
    for m in result["models"]:
        if m["law"] in ("linear", "linear+quadratic", "linear+coulomb"):
            p = {k: v for k, v in m["params"].items() if k != "theta0"}
            nn = np.linspace(0, n[-1], 200)
            ax1.plot(nn + amp.swing[0], envelope(m["law"], m["params"]["theta0"], p, nn),
                     label=f"{m['law']} (BIC {m['bic']:.1f})")
            th = np.linspace(amp.theta[-1], amp.theta[0], 100)
            ax2r.plot(th, law_nu(m["law"], p, th), label=m["law"])
    ax1.set_xlabel("half swing N")
    ax1.set_ylabel("amplitude theta [deg]")
    ax1.legend(fontsize=8)
    raw = result["textbook"]["raw"]
    ax2.plot(raw["theta_mean_deg"], raw["nu_6_17"], "k.", label="raw decrements, formula 6.17")
    pr = result["textbook"].get("printed")
    if pr:
        ax2.plot(pr["theta_mean_deg"], pr["nu_6_17_printed"], "s", mfc="none", label="textbook printed 6.17")
        ax2.plot(pr["theta_mean_deg"], pr["nu_6_18_printed"], "^", mfc="none", label="textbook printed 6.18")
    ax2.set_xlabel("mean amplitude theta_m [deg]")
    ax2.set_ylabel("nu")
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".png", dir=path.parent)
    os.close(fd)
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, path)
    plt.close(fig)
    return path
