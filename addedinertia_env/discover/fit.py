"""Output-error least squares of a :class:`~.model.GrayBoxModel`, with its Fisher information.

The Jacobian is by forward finite differences, all perturbed parameter sets integrated
in one batch. Uncertainty: ``cov = s^2 (J^T J)^-1`` with ``s^2`` the residual variance,
inflated by ``(1 + rho) / (1 - rho)`` where ``rho`` is the residuals' lag-1
autocorrelation (AR(1) effective sample size), because the residuals of sampled,
quantised data are correlated (physics.md section 8, last bullet).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from addedinertia_env.discover.model import GrayBoxModel


@dataclass
class Fit:
    """A least-squares fit of a :class:`GrayBoxModel`: parameters, scaled residuals, Jacobian, cost."""

    model: GrayBoxModel
    theta: np.ndarray
    residuals: np.ndarray  # scaled (hull / phi_noise, flywheel / theta_noise)
    jacobian: np.ndarray  # of the scaled residuals
    cost: float  # sum of squared scaled residuals
    n_evals: int
    success: bool
    message: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def params(self) -> dict[str, float]:
        """``{name: value}`` of the fitted parameters (units of the model's ``ParamSpec``)."""
        return self.model.as_dict(self.theta)

    @property
    def hull_residuals(self) -> np.ndarray:
        """Hull-angle residuals, rad (unscaled), of every run in turn."""
        return self.model.split(self.residuals)[0]

    @property
    def flywheel_residuals(self) -> np.ndarray:
        """Flywheel residuals, rad."""
        return self.model.split(self.residuals)[1]

    @property
    def hull_rms(self) -> float:
        """RMS of the hull residuals, rad."""
        return float(np.sqrt(np.mean(self.hull_residuals**2)))

    def lag1(self) -> float:
        """Lag-one autocorrelation of the residuals (-)."""
        return lag1_autocorrelation(self.residuals, self.model)

    def covariance(self, inflate: bool = True) -> np.ndarray:
        """Parameter covariance from the Fisher information of the scaled residuals."""
        n, p = self.jacobian.shape
        s2 = self.cost / max(n - p, 1)
        cov = s2 * np.linalg.pinv(self.jacobian.T @ self.jacobian)
        if inflate:
            rho = min(max(self.lag1(), 0.0), 0.999)
            cov = cov * (1 + rho) / (1 - rho)
        return cov

    def sandwich_covariance(self, groups: list[np.ndarray]) -> np.ndarray:
        """Cluster-robust (sandwich) parameter covariance, the residuals grouped by ``groups``.

        ``(J^T J)^-1 [sum_g J_g^T r_g r_g^T J_g] (J^T J)^-1`` times ``G / (G - 1)``: it makes
        no assumption on the noise within a group (correlated, or model error), only that
        groups (strokes) are independent; where the model is wrong the residuals carry
        structure and the interval widens with them.
        """
        J, r = self.jacobian, self.residuals
        bread = np.linalg.pinv(J.T @ J)
        meat = np.zeros_like(bread)
        for g in groups:
            s = J[g].T @ r[g]
            meat += np.outer(s, s)
        G = len(groups)
        return bread @ meat @ bread * (G / max(G - 1, 1))

    def stderr(self, inflate: bool = True) -> dict[str, float]:
        """Standard error of each parameter (its own unit), by name; ``inflate`` widens for correlated residuals."""
        sd = np.sqrt(np.clip(np.diag(self.covariance(inflate)), 0, None))
        return self.model.as_dict(sd)


def lag1_autocorrelation(scaled: np.ndarray, model: GrayBoxModel) -> float:
    """Lag-1 autocorrelation of the residuals, within segments (hull part)."""
    hull = model.split(scaled)[0]
    num = den = 0.0
    for _, _, sl in model.hull_index():
        x = hull[sl] - np.mean(hull[sl])
        num += float(np.sum(x[1:] * x[:-1]))
        den += float(np.sum(x * x))
    return num / den if den > 0 else 0.0


def fit_model(model: GrayBoxModel, x0: np.ndarray | None = None, max_nfev: int = 40) -> Fit:
    """Least squares from ``x0`` (default: the model's start values).

    Every point the solver asks the residuals of is integrated together with its
    forward-difference Jacobian rows, in one batch: the solver asks the Jacobian at the
    points it accepts, which are most of those it tries, and a batch of ``p + 1``
    parameter sets costs little more than one (the integration is one loop over time for
    all of them). The numbers are those of separate evaluations (each row is integrated on
    its own values).
    """
    x0 = model.start() if x0 is None else np.asarray(x0, dtype=float)
    lo, hi = model.bounds()
    x0 = np.clip(x0, lo + 1e-12 * (hi - lo), hi - 1e-12 * (hi - lo))
    scales = model.scales()
    last: dict = {}
    count = {"n": 0}

    def steps_at(x):
        steps = 1e-5 * np.maximum(np.abs(x), scales)
        return np.where(x + steps > hi, -steps, steps)  # stay inside the bounds

    def evaluate(x):
        key = x.tobytes()
        if last.get("key") != key:
            steps = steps_at(x)
            X = np.vstack([x[None, :], x[None, :] + np.diag(steps)])
            F = model.residuals(X)
            count["n"] += len(X)
            last.update(key=key, f=F[0], J=((F[1:] - F[0][None, :]) / steps[:, None]).T)
        return last["f"], last["J"]

    def fun(x):
        return evaluate(x)[0]

    def jac(x):
        return evaluate(x)[1]

    res = least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale=scales, method="trf", max_nfev=max_nfev,
                        xtol=1e-10, ftol=1e-10, gtol=1e-10)
    r, J = evaluate(res.x)
    return Fit(model=model, theta=res.x, residuals=r, jacobian=J, cost=float(r @ r), n_evals=count["n"],
               success=bool(res.success), message=str(res.message))


def effective_n(fit: Fit) -> float:
    """AR(1) effective number of independent residuals."""
    rho = min(max(fit.lag1(), 0.0), 0.999)
    return len(fit.residuals) * (1 - rho) / (1 + rho)


def bic(fit: Fit, n_eff: float) -> float:
    """BIC with an effective sample size (Gaussian likelihood, variance profiled out)."""
    n = len(fit.residuals)
    return n_eff * math.log(fit.cost / n) + len(fit.theta) * math.log(n_eff)


def aic(fit: Fit, n_eff: float) -> float:
    """Akaike information criterion of ``fit`` with ``n_eff`` effective samples (lower is better)."""
    n = len(fit.residuals)
    return n_eff * math.log(fit.cost / n) + 2 * len(fit.theta)
