"""Whole-record (gray-box) identification of lambda66, with its Cramer-Rao bound.

The gray-box model of :mod:`addedinertia_env.discover.model` (the hull's own equation
with the measured motor current as input, plus the flywheel's balance) is fitted by
output error to every stroke of every given run (physics.md section 5, last bullet). The
torsion stiffness ``c`` comes from the record's ``rig`` block (static calibration), so
``lambda66`` is identifiable: the free stroke gives ``(J_h + lambda66) / c``, the reverse
stroke ties it to the motor's known torque.

Uncertainty, reported side by side so a user sees how far the estimate is from what
the data allow:

* ``ci95``: the wider of two intervals: (a) 1.96 sigma from the Fisher information
  ``s^2 (J^T J)^-1`` with the residual variance ``s^2`` *as fitted*, inflated by
  ``(1 + rho)/(1 - rho)`` for the residuals' lag-1 autocorrelation ``rho``; (b) the
  cluster-robust sandwich over strokes (:meth:`~addedinertia_env.discover.fit.Fit.sandwich_covariance`,
  each stroke with its flywheel residuals one cluster), with Student's t on ``G - 1``
  degrees of freedom for ``G`` strokes. (b) assumes nothing about the noise within a
  stroke, so it holds off the training distribution (another lab's DAQ and controller)
  and widens where the model is wrong;
* plus, in quadrature, the **current-gain systematic**: a current sensor's gain is known
  to about 0.5 % (physics.md section 7; ``rig.current_gain_uncertainty``, relative, when a
  lab states its own), a common scale on every stroke's torque that no spread between
  strokes can reveal; its effect ``|d lambda66 / d gain| x uncertainty`` comes from the
  fit's own sensitivities (not added when the model fits the torque scale itself,
  ``torque_constant``);
* ``adequate``: False when the residuals stay structured (RMS over 3 x the encoder floor
  and lag-1 autocorrelation over 0.8, the ``unexplained`` test of ``discover``): the model
  class lacks something, and the interval, however wide, is conditional on it;
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
from scipy import stats

from addedinertia_env.records.record import MAX_GAP_PERIODS, RunRecord
from addedinertia_env.identify.common import IdentificationError, Result

DEFAULT_CURRENT_GAIN_UNCERTAINTY = 0.005  # relative, physics.md section 7 (current sensor gain error)


def identify_whole_record(records: list[RunRecord], effect: str | None = None,
                          lambda66_start: float | None = None, memory=None) -> Result:
    """lambda66 (kg m^2) with a 95 % interval and the Cramer-Rao bound, from reverse-symmetric
    and free-decay runs of one rig (others are skipped and listed in ``details['skipped']``).

    ``effect``: fit the nominal model extended by this candidate (a word of the effect
    vocabulary, e.g. the cause ``discover`` named, or two joined by ``+``); default the
    nominal model.
    ``lambda66_start`` (kg m^2): the fit's starting value for lambda66 (e.g. the BEM's A66
    at the swing frequency, ``addedinertia hull``); default the model's generic start.
    ``memory``: the water's memory identified from the same records
    (:class:`~addedinertia_env.identify.memory.MemoryIdentification`, as ``identify(..., memory="auto")``
    passes it); when it found one, the model carries its state
    (:class:`~addedinertia_env.discover.memory_state.MemoryGrayBoxModel`) and ``lambda66`` is A66(0);
    memory-free water (``memory: "none"``) or None: the model without it, unchanged.
    """
    from addedinertia_env.discover.fit import fit_model  # noqa: PLC0415
    from addedinertia_env.discover.model import GrayBoxModel, candidates  # noqa: PLC0415
    from addedinertia_env.discover.prepare import DiscoveryInputError, prepare  # noqa: PLC0415
    from addedinertia_env.discover.residuals import summary  # noqa: PLC0415

    effects = tuple(e.strip() for e in (effect or "").replace(",", "+").split("+") if e.strip() not in ("", "none"))
    for e in effects:
        if e not in candidates():
            raise IdentificationError(f"effect {effect!r}: expected 'none', one of {', '.join(candidates())}, "
                                      "or two joined by '+'")
    try:
        data = prepare(records)
    except DiscoveryInputError as e:
        raise IdentificationError(str(e)) from None
    from addedinertia_env.discover.diagnose import choose_release_lag  # noqa: PLC0415

    if lambda66_start is not None and not (math.isfinite(lambda66_start) and lambda66_start > 0):
        raise IdentificationError(f"lambda66_start = {lambda66_start!r}: expected a finite number > 0 (kg m^2)")
    data, fit = choose_release_lag(data, effects or None)  # which sample the DAQ logged the release at
    from addedinertia_env.discover.memory_state import MemoryGrayBoxModel, kernel_of  # noqa: PLC0415

    kernel = kernel_of(memory)
    model = fit.model if kernel is None else MemoryGrayBoxModel(data, effects or None, kernel)
    x0 = None
    if lambda66_start is not None:
        x0 = model.start() if kernel is None else model.extend(fit.theta)
        x0[model.names.index("lambda66")] = float(lambda66_start)
        fit = fit_model(model, x0)
    elif kernel is not None:  # from the memory-free fit's parameters
        fit = fit_model(model, model.extend(fit.theta))
    lam = fit.params["lambda66"]
    sigma_fisher = math.sqrt(max(fit.covariance(inflate=True)[0, 0], 0.0))
    sigma_white = math.sqrt(max(fit.covariance(inflate=False)[0, 0], 0.0))
    groups = stroke_groups(model)
    G = len(groups)
    sigma_sandwich = math.sqrt(max(fit.sandwich_covariance(groups)[0, 0], 0.0)) if G >= 2 else math.inf
    t_quantile = float(stats.t.ppf(0.975, G - 1)) if G >= 2 else math.inf
    half_noise = max(1.96 * sigma_fisher, t_quantile * sigma_sandwich if G >= 2 else 0.0)
    stated = records[0].known.current_gain_uncertainty
    gain_u = DEFAULT_CURRENT_GAIN_UNCERTAINTY if stated is None else stated
    sigma_gain = 0.0
    if "torque_constant" not in effects and gain_u > 0:
        sigma_gain = abs(_gain_sensitivity(model, fit)) * gain_u
    half = math.hypot(half_noise, 1.96 * sigma_gain)
    sigma = half / 1.96
    J = fit.jacobian
    crb = math.sqrt(max(np.linalg.pinv(J.T @ J)[0, 0], 0.0))
    per_run = []
    for k, rd in enumerate(data.runs):
        rows = _rows_of_run(model, k)
        Jk = J[rows]
        per_run.append({"run": rd.name, "crb": math.sqrt(max(np.linalg.pinv(Jk.T @ Jk)[0, 0], 0.0))})
    s = summary(fit)
    adequate = not (max(s["hull_excess"], s["flywheel_excess"]) > 3.0 and s["lag1"] > 0.8)
    return Result(method="whole-record", lambda66=lam, ci95=(lam - half, lam + half),
                  n_intervals=len(fit.residuals),
                  details={"crb": crb, "per_run_crb": per_run, "sigma": sigma, "sigma_white": sigma_white,
                           "sigma_fisher": sigma_fisher, "sigma_sandwich": sigma_sandwich, "strokes": G,
                           "sigma_current_gain": sigma_gain, "current_gain_uncertainty": gain_u,
                           "interval": ("sandwich over strokes" if G >= 2 and t_quantile * sigma_sandwich
                                        > 1.96 * sigma_fisher else "Fisher, AR(1)-inflated")
                           + (" + current-gain systematic" if sigma_gain > 0 else ""),
                           "adequate": adequate,
                           "verdict": "model adequate" if adequate else "unexplained: residuals keep structure "
                           f"({max(s['hull_excess'], s['flywheel_excess']):.1f} x noise floor, lag-1 {s['lag1']:.2f}); "
                           "run discover",
                           "skipped": list(data.skipped), "gaps": record_gaps(records),
                           "current_sampling": dict(data.current_mode_report),
                           "release_lag_s": data.release_lag,
                           "ci_over_crb": sigma / crb if crb > 0 else None, "model": "+".join(effects) or "nominal",
                           "params": fit.params, "stderr": fit.stderr(), "n_runs": len(data.runs),
                           "residual_rms": fit.hull_rms, "residual_excess": s["hull_excess"],
                           "flywheel_excess": s["flywheel_excess"], "lag1": s["lag1"],
                           "converged": fit.success,
                           "lambda66_start": float((model.start() if x0 is None else x0)[model.names.index("lambda66")]),
                           "n_evals": fit.n_evals, **_memory_details(memory, kernel, lam, fit.params.get("A66_inf"))})


def _memory_details(memory, kernel, lam: float, a_inf: float | None) -> dict:
    """What the fit took from the water's memory (``identify --json``)."""
    if memory is None:
        return {}
    out = {"memory": memory.to_json()["memory"], "prior": memory.prior}
    if kernel is not None:
        out.update({"memory_state": f"{kernel.family}: {kernel.order} states, the kernel's shape identified from the "
                                    "same records (identify/memory.py), its size lambda66 - A66_inf fitted here",
                    "A66_inf": lam * kernel.a_inf_ratio if a_inf is None else a_inf})
    return out


def record_gaps(records: list[RunRecord]) -> list[dict]:
    """Every interval of ``t`` longer than five nominal periods (the spec's reporting threshold), per record:
    ``run``, ``after_t`` (s), ``length_s``. A stroke is integrated up to a gap that no integrator step can
    bridge (the input over it is unknown) and the samples after it, until the brake, are not fitted."""
    out = []
    for rec in records:
        t = np.asarray(rec.t, dtype=float)
        dt = np.diff(t)
        limit = MAX_GAP_PERIODS / rec.known.sample_rate * (1 + 1e-6)
        out += [{"run": rec.name, "after_t": float(t[k]), "length_s": float(dt[k])}
                for k in np.nonzero(dt > limit)[0].tolist()]
    return out


def _rows_of_run(model, run: int) -> np.ndarray:
    """Indices of run ``run``'s residuals in the stacked (hull, flywheel) residual vector."""
    rows = [np.arange(sl.start, sl.stop) for r, _, sl in model.hull_index() if r == run]
    rows.append(model.flywheel_rows(run))
    return np.concatenate(rows)


def stroke_groups(model) -> list[np.ndarray]:
    """Residual rows per stroke (hull segment); a run's flywheel rows join its last stroke."""
    by_seg = [np.arange(sl.start, sl.stop) for _, _, sl in model.hull_index()]
    last = {}
    for k, seg in enumerate(model.segments):
        last[seg.run] = k
    for run, k in last.items():
        fly = model.flywheel_rows(run)
        if fly.size:
            by_seg[k] = np.concatenate([by_seg[k], fly])
    return by_seg


def _gain_sensitivity(model, fit) -> float:
    """d lambda66 / d (current gain), kg m^2 per unit relative gain: the linearised refit when
    every logged current is scaled by ``1 + g`` (the model's own Jacobian, one extra evaluation)."""
    from addedinertia_env.discover.model import GrayBoxModel  # noqa: PLC0415

    effects = model.effects + ("torque_constant",)
    scaled = model.with_effects(effects) if hasattr(model, "with_effects") else GrayBoxModel(model.data, effects)
    params = fit.params
    new = [k for k, n in enumerate(scaled.names) if n not in params]  # the torque-constant ratio, 1 = as stated
    theta = np.array([params.get(n, 1.0) for n in scaled.names])
    eps = 1e-3
    r0 = scaled.residuals(theta[None, :])[0]
    theta[new[0]] += eps
    r1 = scaled.residuals(theta[None, :])[0]
    J = fit.jacobian
    d_theta = -np.linalg.pinv(J.T @ J) @ (J.T @ ((r1 - r0) / eps))
    return float(d_theta[0])
