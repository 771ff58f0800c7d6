"""The stratified delete-one-cluster jackknife (docs/INTERVALS.md, issue 26).

An estimate built from a few clusters of evidence (here the stretches of free motion a hull's records hold:
each start from rest and the swing after it) has a sampling error that a covariance from the residuals
within one fit can understate: the clusters' residuals are correlated, the fit is nonlinear (the memory's
poles), and there are too few clusters for a sandwich estimate to be trusted. The delete-one-cluster
jackknife (the "CV3" estimator of MacKinnon, Nielsen & Webb 2023, *Cluster-robust inference: a guide to
empirical practice*, J. Econometrics 232: 272-299, section 4; Bell & McCaffrey 2002, Survey Methodology 28:
169-181) refits without each cluster in turn and reads the spread of the refits.

The jackknife needs the clusters it leaves out to be *exchangeable*: repeats of one kind of measurement.
A hull's stretches are not all alike (a free decay's long swing, the stroke after a reverse run's release
from its hold, the stroke after the brake lets go at rest: each informs the memory model at other
frequencies), and leaving out the one decay of a set refits a different experiment, not a resample of the
same one (it moved A66(0) by 0.7-11 % on 8 of 25 drawn hulls whose errors are at most 0.13 %). So the
clusters are grouped into strata of one kind each, and the variance is the stratified jackknife's
(Wolter 2007, *Introduction to Variance Estimation*, 2nd ed., section 4.5; Kish & Frankel 1974, JRSS B 36:
1-37):

    v = sum_h (n_h - 1) / n_h  sum_{i in h} (x_(hi) - mean_h)^2,

with ``n - H`` degrees of freedom (``n`` clusters in ``H`` strata; a stratum of one contributes nothing
and no degree of freedom), and the 95 % interval takes Student's t with them.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence

import numpy as np


def stratified_jackknife(values: Sequence[float], strata: Sequence[Hashable]) -> tuple[float, int]:
    """The stratified delete-one jackknife standard deviation of an estimate and its degrees of freedom.

    ``values[i]`` is the estimate refitted without cluster ``i``; ``strata[i]`` names cluster ``i``'s kind.
    Returns ``(sd, dof)``; ``(nan, 0)`` when no stratum holds two clusters (no spread to read). Raises
    ValueError on mismatched lengths or non-finite values."""
    x = np.asarray(values, float)
    if x.ndim != 1 or len(x) != len(strata):
        raise ValueError(f"stratified_jackknife(): expected one stratum per value, got {x.shape} values and "
                         f"{len(strata)} strata")
    if not np.all(np.isfinite(x)):
        raise ValueError("stratified_jackknife(): every refitted value must be finite")
    var, dof = 0.0, 0
    for h in dict.fromkeys(strata):
        xh = x[[i for i, s in enumerate(strata) if s == h]]
        n = len(xh)
        if n < 2:
            continue
        var += (n - 1) / n * float(np.sum((xh - xh.mean()) ** 2))
        dof += n - 1
    return (math.sqrt(var), dof) if dof else (math.nan, 0)


def t95(dof: int) -> float:
    """The two-sided 95 % point of Student's t with ``dof`` degrees of freedom (``dof`` >= 1)."""
    from scipy import stats  # noqa: PLC0415

    if dof < 1:
        raise ValueError(f"t95(): dof={dof}; expected at least 1")
    return float(stats.t.ppf(0.975, dof))
