"""What the nominal model gets wrong, which effect explains it, and what extending the model gains.

Procedure (``docs/DISCOVERY.md`` explains the choices):

1. fit the nominal model (``lambda66``, ``b1``, ``b2``) to every stroke of every run
   jointly by output error (:mod:`.fit`), hull and flywheel channels together;
2. for each candidate effect, add its one or two parameters and refit from the nominal
   solution;
3. judge each candidate by (a) BIC with an effective sample size (AR(1) of the residuals),
   (b) the physical size of its fitted parameter (clear of its standard error and of the
   rig's known sensor imperfections), and, for the best few, (c) two-fold held-out
   prediction: fit on half of the runs, predict the other half, and back;
4. name the best candidate that passes all three; otherwise ``unexplained`` when the
   nominal residuals stay well above the noise floor and far from white, else ``none``.

Never reads ``truth``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..record import RunRecord
from . import residuals as resid
from .fit import Fit, bic, effective_n, fit_model
from ..rig.effects import registry
from .model import GrayBoxModel, candidates as candidate_names
from .prepare import Prepared, prepare


@dataclass(frozen=True)
class Thresholds:
    """Decision thresholds, fixed before the detection table was run (docs/DISCOVERY.md).

    Set from physics and convention, then checked on one dataset per effect at seed 100
    (which the detection table, seeds 0-9, does not use); not tuned on the table.
    """

    min_delta_bic: float = 10.0  # "very strong" evidence on the Kass-Raftery scale, with n_eff
    min_heldout_gain: float = 0.10  # held-out RMS must drop by at least 10 %
    min_z: float = 4.0  # fitted size / its (correlation-inflated) standard error
    top_k_heldout: int = 3  # candidates that get the held-out check (best by BIC)
    unexplained_excess: float = 3.0  # residual RMS / noise floor, either channel, that is "structure"
    unexplained_lag1: float = 0.8  # and residuals this correlated
    # Smallest fitted size called an effect, per size parameter: clear of the rig's known
    # imperfections (current gain error 0.5 %, half-sample hold lag 0.5 ms, physics.md
    # sections 7, 8). Each effect's file states its own (``min_size`` in the registry).
    min_size: dict = field(default_factory=lambda: {s.size_param: s.min_size for s in registry.specs()})


@dataclass
class Candidate:
    cause: str
    fit: Fit
    delta_bic: float
    n_eff: float
    z: float
    size_ok: bool
    heldout_rms: float | None = None  # normalised (noise units), both channels
    heldout_gain: float | None = None
    accepted: bool = False
    reason: str = ""

    def to_json(self) -> dict:
        p = self.fit.params
        se = self.fit.stderr()
        extra = {k: p[k] for k in p if k not in ("lambda66", "b1", "b2")}
        return {"cause": self.cause, "score": self.delta_bic, "delta_bic": self.delta_bic, "n_eff": self.n_eff,
                "params": extra, "stderr": {k: se[k] for k in extra}, "z": self.z, "size_ok": self.size_ok,
                "residual_rms": self.fit.hull_rms,
                "flywheel_rms": float(np.sqrt(np.mean(self.fit.flywheel_residuals**2))),
                "lambda66": p["lambda66"], "heldout_rms": self.heldout_rms, "heldout_gain": self.heldout_gain,
                "accepted": self.accepted, "reason": self.reason}


@dataclass
class Diagnosis:
    cause: str
    data: Prepared
    nominal: Fit
    candidates: list[Candidate]
    heldout_nominal: float | None
    thresholds: Thresholds
    wall_s: float = 0.0

    @property
    def best(self) -> Candidate | None:
        return next((c for c in self.candidates if c.cause == self.cause), None)

    @property
    def extended(self) -> Fit:
        b = self.best
        return b.fit if b is not None else self.nominal

    def gain(self) -> dict:
        ext = self.extended
        b = self.best
        return {"residual_rms_nominal": self.nominal.hull_rms, "residual_rms_extended": ext.hull_rms,
                "flywheel_rms_nominal": float(np.sqrt(np.mean(self.nominal.flywheel_residuals**2))),
                "flywheel_rms_extended": float(np.sqrt(np.mean(ext.flywheel_residuals**2))),
                "lambda66_nominal": self.nominal.params["lambda66"], "lambda66_extended": ext.params["lambda66"],
                "heldout_rms_nominal": self.heldout_nominal,
                "heldout_rms_extended": b.heldout_rms if b is not None else self.heldout_nominal,
                "heldout_gain": b.heldout_gain if b is not None else 0.0}

    def to_json(self) -> dict:
        nominal_se = self.nominal.stderr()
        ext = self.extended
        return {"cause": self.cause, "candidates": [c.to_json() for c in self.candidates], "gain": self.gain(),
                "nominal": {"params": self.nominal.params, "stderr": nominal_se},
                "extended": {"cause": self.cause, "params": ext.params, "stderr": ext.stderr()},
                "residuals_nominal": resid.summary(self.nominal),
                "residuals_extended": resid.summary(ext),
                "runs": [{"run": r.name, "alpha": r.alpha, "hold_s": r.hold_s, "current_offset": r.current_offset,
                          "current_noise": r.current_noise} for r in self.data.runs],
                "thresholds": {k: v for k, v in self.thresholds.__dict__.items()}, "wall_s": self.wall_s}


def _physical_size(cause: str, params: dict[str, float]) -> tuple[str, float]:
    """The parameter that measures an effect's size, and its departure from 'no effect'."""
    spec = registry.get(cause)
    return spec.size_param, params[spec.size_param] - spec.param(spec.size_param).neutral


def _start_for(model: GrayBoxModel, nominal: Fit) -> np.ndarray:
    x = model.start()
    x[:3] = nominal.theta
    return x


def _holdout_folds(data: Prepared) -> list[tuple[list[int], list[int]]]:
    """Two folds, each training set covering as many (amplitude, hold) levels as it can."""
    n = len(data.runs)
    if n < 2:
        return []
    order = sorted(range(n), key=lambda k: (round(data.runs[k].alpha, 4), round(data.runs[k].hold_s, 2)))
    # (a1,h1), (a1,h2), (a2,h1), (a2,h2) -> folds {0,3} / {1,2}: each has both amplitudes and holds.
    a = [order[k] for k in range(n) if k % 4 in (0, 3)]
    b = [order[k] for k in range(n) if k % 4 in (1, 2)]
    if not a or not b:
        a, b = order[::2], order[1::2]
    return [(a, b), (b, a)]


def heldout_rms(data: Prepared, effect: str | None, start: np.ndarray) -> float:
    """Normalised RMS of predictions of held-out runs (fits on the other runs), both folds pooled."""
    sq, n = 0.0, 0
    for train, test in _holdout_folds(data):
        fit = fit_model(GrayBoxModel(data.subset(train), effect), x0=start, max_nfev=25)
        r = GrayBoxModel(data.subset(test), effect).residuals(fit.theta[None, :])[0]
        sq += float(r @ r)
        n += len(r)
    return math.sqrt(sq / n) if n else float("nan")


def discover(records: list[RunRecord], thresholds: Thresholds | None = None, heldout: bool = True,
             progress=None) -> Diagnosis:
    """Diagnose ``records`` (reverse-symmetric runs of one rig); see the module docstring."""
    import time  # noqa: PLC0415

    t0 = time.perf_counter()
    th = thresholds or Thresholds()
    data = prepare([r.without_truth() for r in records])
    nominal = fit_model(GrayBoxModel(data))
    candidates = []
    for cause in candidate_names():
        if progress:
            progress(cause)
        model = GrayBoxModel(data, cause)
        fit = fit_model(model, x0=_start_for(model, nominal))
        n_eff = effective_n(fit)
        dbic = bic(nominal, n_eff) - bic(fit, n_eff)
        pname, size = _physical_size(cause, fit.params)
        se = fit.stderr()[pname]
        z = abs(size) / se if se > 0 else math.inf
        size_ok = abs(size) >= th.min_size[pname] and z >= th.min_z
        candidates.append(Candidate(cause=cause, fit=fit, delta_bic=dbic, n_eff=n_eff, z=z, size_ok=size_ok))
    candidates.sort(key=lambda c: -c.delta_bic)
    ho_nominal = None
    if heldout and len(data.runs) >= 2:
        ho_nominal = heldout_rms(data, None, nominal.theta)
        for c in [c for c in candidates if c.delta_bic >= th.min_delta_bic and c.size_ok][: th.top_k_heldout]:
            c.heldout_rms = heldout_rms(data, c.cause, c.fit.theta)
            c.heldout_gain = 1.0 - c.heldout_rms / ho_nominal
    for c in candidates:
        reasons = []
        if c.delta_bic < th.min_delta_bic:
            reasons.append(f"delta BIC {c.delta_bic:.1f} < {th.min_delta_bic}")
        if not c.size_ok:
            reasons.append(f"fitted size not significant (z = {c.z:.1f})")
        if heldout and ho_nominal is not None:
            if c.heldout_gain is None:
                reasons.append("not among the best for the held-out check")
            elif c.heldout_gain < th.min_heldout_gain:
                reasons.append(f"held-out gain {c.heldout_gain:.1%} < {th.min_heldout_gain:.0%}")
        c.accepted = not reasons
        c.reason = "; ".join(reasons) if reasons else "accepted"
    accepted = [c for c in candidates if c.accepted]
    if accepted:
        cause = max(accepted, key=lambda c: c.delta_bic).cause
    else:
        s = resid.summary(nominal)
        structured = (max(s["hull_excess"], s["flywheel_excess"]) > th.unexplained_excess
                      and s["lag1"] > th.unexplained_lag1)
        cause = "unexplained" if structured else "none"
    return Diagnosis(cause=cause, data=data, nominal=nominal, candidates=candidates, heldout_nominal=ho_nominal,
                     thresholds=th, wall_s=time.perf_counter() - t0)
