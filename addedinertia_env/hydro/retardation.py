"""Cummins' retardation function of yaw from the radiation damping B66(omega).

Cummins (1962): the radiation moment after an arbitrary yaw motion is
``-A66(inf) phi'' - integral_0^t K(t - s) phi'(s) ds`` with the kernel

    K(t) = (2 / pi) integral_0^inf B66(omega) cos(omega t) d omega     [N m s / s = N m]

and Ogilvie (1964) gives the added inertia back from it,

    A66(omega) = A66(inf) - (1 / omega) integral_0^inf K(t) sin(omega t) dt,

which is the consistency check used here: the BEM's own A66(omega) against the one
rebuilt from its B66 and A66(inf).

B66 is known on a finite grid. Below the first grid point B66 is taken to rise from 0
(it goes as omega^3 or faster at zero frequency); between points it is linear; above the
last point it decays as ``omega^-3`` (the usual far tail), integrated to 20 times the last
frequency. Negative B66 values (numerical noise where wave radiation vanishes, long
periods) are clipped to 0 and counted.
"""

from __future__ import annotations

import numpy as np

TAIL_POWER = 3.0


def _dense(omega: np.ndarray, b: np.ndarray, n: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """B66 on a dense grid from 0 to 20 omega_max (piecewise linear, omega^-3 tail)."""
    w_max = float(omega[-1])
    w = np.concatenate([np.linspace(0.0, w_max, n), np.geomspace(w_max, 20.0 * w_max, n)[1:]])
    inner = np.interp(w, np.concatenate([[0.0], omega]), np.concatenate([[0.0], b]))
    tail = b[-1] * (w_max / np.maximum(w, 1e-12)) ** TAIL_POWER
    return w, np.where(w <= w_max, inner, tail)


def retardation_function(omega, b66, t) -> dict:
    """K(t) (N m) from B66 (N m s) sampled at ``omega`` (rad/s, increasing), at times ``t`` (s).

    Returns ``{"t", "K", "clipped", "tail_fraction"}``: ``clipped`` counts negative B66
    values set to 0; ``tail_fraction`` is the share of ``integral B66 d omega`` that comes
    from the assumed tail beyond the last frequency (small is good).
    """
    omega = np.asarray(omega, dtype=float)
    b = np.asarray(b66, dtype=float)
    if omega.ndim != 1 or len(omega) < 3 or np.any(np.diff(omega) <= 0) or omega[0] <= 0:
        raise ValueError("omega: expected at least 3 increasing frequencies > 0 (rad/s)")
    clipped = int(np.count_nonzero(b < 0))
    b = np.maximum(b, 0.0)
    w, bd = _dense(omega, b)
    t = np.asarray(t, dtype=float)
    K = (2.0 / np.pi) * np.trapezoid(bd[None, :] * np.cos(np.outer(t, w)), w, axis=1)
    total = np.trapezoid(bd, w)
    tail = np.trapezoid(bd[w >= omega[-1]], w[w >= omega[-1]])
    return {"t": t, "K": K, "clipped": clipped, "tail_fraction": float(tail / total) if total > 0 else 0.0}


def added_inertia_from_kernel(t, K, a_inf: float, omega) -> np.ndarray:
    """Ogilvie's relation: A66(omega) = A66(inf) - (1/omega) integral K(t) sin(omega t) dt, kg m^2."""
    t = np.asarray(t, dtype=float)
    K = np.asarray(K, dtype=float)
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    integral = np.trapezoid(K[None, :] * np.sin(np.outer(omega, t)), t, axis=1)
    return a_inf - integral / omega


def memory_time(t, K, fraction: float = 0.05) -> float:
    """Time (s) after which |K| stays below ``fraction`` of its peak: how long the water remembers."""
    t = np.asarray(t, dtype=float)
    a = np.abs(np.asarray(K, dtype=float))
    if a.max() == 0:
        return 0.0
    above = np.nonzero(a >= fraction * a.max())[0]
    return float(t[above[-1]])


def kernel_summary(omega, a66, b66, a_inf: float, t_max: float = 10.0, n: int = 2001) -> dict:
    """Retardation function and its checks, JSON-ready.

    ``ogilvie_max_rel_error``: the largest relative difference between the BEM's A66 and the
    one rebuilt from K(t) and A66(inf), over the frequencies between 1.5 rad/s and the last
    one (below, the integral needs ever longer records and the check says little).
    """
    t = np.linspace(0.0, t_max, n)
    r = retardation_function(omega, b66, t)
    omega = np.asarray(omega, dtype=float)
    sel = omega >= 1.5
    rebuilt = added_inertia_from_kernel(t, r["K"], a_inf, omega[sel])
    a = np.asarray(a66, dtype=float)[sel]
    err = float(np.max(np.abs(rebuilt - a) / np.abs(a))) if sel.any() else None
    return {"t": t.tolist(), "K": r["K"].tolist(), "K0": float(r["K"][0]),
            "memory_time_5pct": memory_time(t, r["K"]), "clipped_negative_B66": r["clipped"],
            "tail_fraction": r["tail_fraction"], "ogilvie_max_rel_error": err}
