"""Residual diagnostics: whiteness, and structure against amplitude, hold, phase and current."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from addedinertia_env.discover.fit import Fit

MAX_LAG = 20


def autocorrelation(fit: Fit, max_lag: int = MAX_LAG) -> np.ndarray:
    """Autocorrelation of the hull residuals at lags 0..max_lag, pooled over segments."""
    hull = fit.hull_residuals
    num = np.zeros(max_lag + 1)
    den = 0.0
    for _, _, sl in fit.model.hull_index():
        x = hull[sl] - np.mean(hull[sl])
        den += float(x @ x)
        for k in range(max_lag + 1):
            if k < len(x):
                num[k] += float(x[k:] @ x[: len(x) - k])
    return num / den if den > 0 else num


def ljung_box(fit: Fit, max_lag: int = MAX_LAG) -> tuple[float, float]:
    """Ljung-Box statistic over lags 1..max_lag and its p-value (white residuals: p not small)."""
    acf = autocorrelation(fit, max_lag)
    n = len(fit.hull_residuals)
    lags = np.arange(1, max_lag + 1)
    q = float(n * (n + 2) * np.sum(acf[1:] ** 2 / (n - lags)))
    return q, float(stats.chi2.sf(q, max_lag))


def structure(fit: Fit) -> dict:
    """Hull residual RMS by run (with its amplitude and hold) and by stroke; correlation with current."""
    data = fit.model.data
    hull = fit.hull_residuals
    by_run, by_phase = [], {"free": [], "reverse": [], "stroke": []}
    currents, resid_rev = [], []
    for seg, (run, kind, sl) in zip(fit.model.segments, fit.model.hull_index()):
        r = hull[sl]
        by_phase[kind].append(r)
        if kind in ("reverse", "stroke"):
            n = seg.step_samples
            currents.append(seg.current[n:: n][: seg.steps])
            resid_rev.append(r)
    for k, rd in enumerate(data.runs):
        parts = [hull[sl] for run, _, sl in fit.model.hull_index() if run == k]
        x = np.concatenate(parts)
        by_run.append({"run": rd.name, "alpha": rd.alpha, "hold_s": rd.hold_s,
                       "rms": float(np.sqrt(np.mean(x**2)))})
    phase_rms = {k: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) if v else float("nan")
                 for k, v in by_phase.items()}
    i_all = np.concatenate(currents) if currents else np.zeros(0)
    r_all = np.concatenate(resid_rev) if resid_rev else np.zeros(0)
    corr = float(np.corrcoef(i_all, r_all)[0, 1]) if i_all.size > 2 and np.std(i_all) > 0 and np.std(r_all) > 0 \
        else 0.0
    return {"by_run": by_run, "by_phase": phase_rms, "corr_current": corr,
            "amplitude_trend": _trend(by_run, "alpha"), "hold_trend": _trend(by_run, "hold_s")}


def _trend(by_run: list[dict], key: str) -> float:
    """Ratio of residual RMS at the largest to the smallest value of ``key`` (1: no trend)."""
    values = sorted({round(r[key], 6) for r in by_run})
    if len(values) < 2:
        return 1.0
    lo = np.mean([r["rms"] for r in by_run if round(r[key], 6) == values[0]])
    hi = np.mean([r["rms"] for r in by_run if round(r[key], 6) == values[-1]])
    return float(hi / lo) if lo > 0 else math.inf


def summary(fit: Fit) -> dict:
    """Everything the report shows about one fit's residuals."""
    data = fit.model.data
    q, p = ljung_box(fit)
    fly = fit.flywheel_residuals
    return {"hull_rms": fit.hull_rms, "hull_noise_floor": data.phi_noise, "hull_excess": fit.hull_rms / data.phi_noise,
            "flywheel_rms": _rms(fly), "flywheel_noise_floor": data.theta_noise,
            "flywheel_excess": _rms(fly) / data.theta_noise,
            "lag1": fit.lag1(), "ljung_box_q": q, "ljung_box_p": p, **structure(fit)}


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else 0.0
