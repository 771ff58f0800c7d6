"""Averaging over model families that fit the same records (docs/INTERVALS.md, issue 26).

A66(0) is an extrapolation from the rig's frequencies, so which passive memory family is right
matters, and the records say it only in degrees. Instead of the *union* of every family within a
fixed residual tolerance (which sized the interval by the worst family kept), each family gets an
Akaike weight (Burnham & Anderson 2002, *Model Selection and Multimodel Inference*, 2nd ed.,
sections 4.2-4.3; Buckland, Burnham & Augustin 1997, Biometrics 53: 603-618)

    w_i ~ exp(-AIC_i / 2),   AIC_i = n ln(RSS_i / RSS_min) + 2 k_i,

and the quantity's distribution is the mixture ``sum_i w_i N(x_i, s_i^2)`` of the families'
estimates and their own (clustered) standard errors; the 95 % interval is its 2.5 and 97.5 %
points. Its variance is Burnham & Anderson's unconditional one (their eq. 6.12: each family's
variance plus its squared distance from the average), so a family far off with a small weight widens
the interval by its weight's worth, not by all of it.

``n`` is the number of *independent* pieces of evidence, not of equation rows: the memory fit's rows
within one 1.5 s window are double integrals over the same samples and move together (the same reason
its covariance is clustered by window), so ``n`` is the number of windows. Counting every 20 ms row
would make a 1 % residual difference decide between families as if it were certain. AIC, not BIC:
the water's true kernel is not in the set (a free surface's is of infinite order), so the weights
should rank how well each family *approximates* it (Kullback-Leibler), which is what AIC estimates.
"""

from __future__ import annotations

import math

import numpy as np

Z95 = 1.959963984540054  # two-sided 95 % point of the normal


def akaike_weights(rss, n_params, n_independent: int) -> np.ndarray:
    """Akaike weights of fits with residual sums of squares ``rss`` and ``n_params`` free parameters each
    (the parameters common to all fits need not be counted), from ``n_independent`` independent pieces of
    evidence (the clusters of the residual). Raises ValueError on empty, mismatched or non-positive input."""
    r = np.asarray(rss, float)
    k = np.asarray(n_params, float)
    if r.ndim != 1 or not len(r) or r.shape != k.shape:
        raise ValueError(f"akaike_weights(): expected 1-D rss and n_params of one non-zero length, got {r.shape} "
                         f"and {k.shape}")
    if not np.all(np.isfinite(r)) or np.any(r <= 0) or n_independent < 1:
        raise ValueError(f"akaike_weights(): rss must be finite and positive, n_independent >= 1 (got "
                         f"{n_independent})")
    aic = n_independent * np.log(r / r.min()) + 2.0 * k
    w = np.exp(-0.5 * (aic - aic.min()))
    return w / w.sum()


def mixture_interval(values, sigmas, weights, level: float = 0.95) -> tuple[float, float]:
    """The central ``level`` interval of the mixture ``sum_i weights_i N(values_i, sigmas_i^2)`` (its
    ``(1 - level)/2`` and ``(1 + level)/2`` points, found by bisection on the mixture's distribution)."""
    from scipy import optimize, stats  # noqa: PLC0415

    x = np.asarray(values, float)
    s = np.maximum(np.asarray(sigmas, float), 1e-300)
    w = np.asarray(weights, float)
    if not (x.shape == s.shape == w.shape) or x.ndim != 1 or not len(x):
        raise ValueError("mixture_interval(): values, sigmas and weights must be 1-D of one non-zero length")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(s)) and np.all(w >= 0) and w.sum() > 0):
        raise ValueError("mixture_interval(): values and sigmas must be finite, weights >= 0 and not all 0")
    w = w / w.sum()
    lo_b, hi_b = float(np.min(x - 12 * s)), float(np.max(x + 12 * s))

    def point(p: float) -> float:
        f = lambda v: float(np.sum(w * stats.norm.cdf((v - x) / s))) - p  # noqa: E731
        if hi_b <= lo_b:
            return float(x[0])
        return float(optimize.brentq(f, lo_b, hi_b, xtol=1e-12 * max(1.0, abs(hi_b)), rtol=1e-12))

    a = 0.5 * (1.0 - level)
    return point(a), point(1.0 - a)


def unconditional_sigma(values, sigmas, weights) -> float:
    """Burnham & Anderson's (2002, eq. 6.12) unconditional standard deviation of the model average:
    ``sqrt(sum_i w_i (s_i^2 + (x_i - xbar)^2))``, ``xbar`` the weighted mean."""
    x, s, w = (np.asarray(a, float) for a in (values, sigmas, weights))
    w = w / w.sum()
    xbar = float(w @ x)
    return math.sqrt(float(w @ (s**2 + (x - xbar) ** 2)))
