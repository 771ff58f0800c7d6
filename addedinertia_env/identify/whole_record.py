"""Whole-record (gray-box) identification of lambda66, with its Cramer-Rao bound.

The gray-box model of :mod:`addedinertia_env.discover.model` (the hull's own equation
with the measured motor current as input, plus the flywheel's balance) is fitted by
output error to every stroke of every given run (physics.md section 5, last bullet). The
torsion stiffness ``c`` comes from the record's ``rig`` block (static calibration), so
``lambda66`` is identifiable: the free stroke gives ``(J_h + lambda66) / c``, the reverse
stroke ties it to the motor's known torque.

Uncertainty, reported side by side so a user sees how far the estimate is from what
the data allow:

* ``ci95``: 1.96 sigma from the Fisher information ``s^2 (J^T J)^-1`` with the residual
  variance ``s^2`` *as fitted*, inflated by ``(1 + rho)/(1 - rho)`` for the residuals'
  lag-1 autocorrelation ``rho``: model error and correlated residuals widen it;
* ``crb``: the Cramer-Rao bound, the standard deviation that white sensor noise at the
  encoders' quantisation floor alone would allow, ``(J^T J)^-1`` of the residuals scaled
  by that floor; ``per_run_crb`` is the same for each run's data alone.

The model is only as right as its class: an effect it lacks biases lambda66 by whole
percents while ``ci95`` may stay narrow; ``addedinertia discover`` tests for that. Never
reads ``truth``.
"""

from __future__ import annotations

import math

import numpy as np

from ..record import RunRecord
from .common import IdentificationError, Result


def identify_whole_record(records: list[RunRecord], effect: str | None = None,
                          lambda66_start: float | None = None) -> Result:
    """lambda66 (kg m^2) with a 95 % interval and the Cramer-Rao bound, from reverse-symmetric runs.

    ``effect``: fit the nominal model extended by this candidate (a word of the effect
    vocabulary, e.g. the cause ``discover`` named); default the nominal model.
    ``lambda66_start`` (kg m^2): the fit's starting value for lambda66 (e.g. the BEM's A66
    at the swing frequency, ``addedinertia hull``); default the model's generic start.
    """
    from ..discover.fit import fit_model  # noqa: PLC0415
    from ..discover.model import GrayBoxModel, candidates  # noqa: PLC0415
    from ..discover.prepare import DiscoveryInputError, prepare  # noqa: PLC0415
    from ..discover.residuals import summary  # noqa: PLC0415

    if effect in ("none", ""):
        effect = None
    if effect is not None and effect not in candidates():
        raise IdentificationError(f"effect {effect!r}: expected 'none' or one of {', '.join(candidates())}")
    try:
        data = prepare(records)
    except DiscoveryInputError as e:
        raise IdentificationError(str(e)) from None
    model = GrayBoxModel(data, effect)
    x0 = None
    if lambda66_start is not None:
        if not (math.isfinite(lambda66_start) and lambda66_start > 0):
            raise IdentificationError(f"lambda66_start = {lambda66_start!r}: expected a finite number > 0 (kg m^2)")
        x0 = model.start()
        x0[model.names.index("lambda66")] = float(lambda66_start)
    fit = fit_model(model, x0)
    lam = fit.params["lambda66"]
    sigma = math.sqrt(max(fit.covariance(inflate=True)[0, 0], 0.0))
    sigma_white = math.sqrt(max(fit.covariance(inflate=False)[0, 0], 0.0))
    J = fit.jacobian
    crb = math.sqrt(max(np.linalg.pinv(J.T @ J)[0, 0], 0.0))
    per_run = []
    for k, rd in enumerate(data.runs):
        rows = _rows_of_run(model, k)
        Jk = J[rows]
        per_run.append({"run": rd.name, "crb": math.sqrt(max(np.linalg.pinv(Jk.T @ Jk)[0, 0], 0.0))})
    s = summary(fit)
    return Result(method="whole-record", lambda66=lam, ci95=(lam - 1.96 * sigma, lam + 1.96 * sigma),
                  n_intervals=len(fit.residuals),
                  details={"crb": crb, "per_run_crb": per_run, "sigma": sigma, "sigma_white": sigma_white,
                           "ci_over_crb": sigma / crb if crb > 0 else None, "model": effect or "nominal",
                           "params": fit.params, "stderr": fit.stderr(), "n_runs": len(data.runs),
                           "residual_rms": fit.hull_rms, "residual_excess": s["hull_excess"],
                           "flywheel_excess": s["flywheel_excess"], "lag1": s["lag1"],
                           "converged": fit.success,
                           "lambda66_start": float((model.start() if x0 is None else x0)[model.names.index("lambda66")]),
                           "n_evals": fit.n_evals})


def _rows_of_run(model, run: int) -> np.ndarray:
    """Indices of run ``run``'s residuals in the stacked (hull, flywheel) residual vector."""
    rows = [np.arange(sl.start, sl.stop) for r, _, sl in model.hull_index() if r == run]
    offset = model.n_hull
    for k, fw in enumerate(model.data.runs):
        n = sum(sl.stop - sl.start for sl in fw.flywheel.chunks)
        if k == run:
            rows.append(np.arange(offset, offset + n))
        offset += n
    return np.concatenate(rows)
