"""Candidate damping laws ``d theta / dN = -f(theta)``: closed-form envelopes, output-error fits, tests."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats
from scipy.optimize import least_squares

from addedinertia_env.decay.amplitudes import READING_SIGMA_DEG, Amplitudes

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
