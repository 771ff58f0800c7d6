"""The energy method corrected for the water's memory (docs/RADIATION_MEMORY.md).

With radiation memory the hull's kinetic energy holds only A66(inf); the rest of the water's
inertia is the memory moment ``mu``, whose work ``W = integral mu w dt`` (the hull's work
on the water) is not mirrored between the forward stroke (boundary angle to rest) and the
reverse stroke (rest to boundary): a causal memory cannot be mirrored in time. Summing the
two strokes' balances (physics.md section 4), the energy method's per-angle value is

    lambda_E(phi1) = A66(inf) + (W_rev - W_fwd) / ((w1f^2 + w1r^2) / 2)   (+ its own noise)

instead of A66(0). With a memory model identified from the records
(:mod:`~addedinertia_env.identify.memory`) the works are computed from the *measured* motion,
and each run's value is corrected by the model's bias at the same angles and weights:

    bias = (W_rev - W_fwd) / KE - (A66(0) - A66(inf)),    lambda66 = lambda_E - bias.

``A66(inf)`` cancels; the bias is linear in the memory coefficients for given poles, so its
variance comes from their (window-clustered) covariance, and the reported interval is the
mixture of the memory families that fit the records, by their Akaike weights (the extrapolation
to zero frequency is where they differ). Never reads ``truth``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addedinertia_env.records.record import RunRecord, motion_phase
from addedinertia_env.identify.memory import (MIN_STRETCHES, SMOOTH_HALF, FamilyFit, MemoryIdentification, _basis,
                                              _smooth)

FRACTIONS = (0.25, 0.75)  # the energy method's default dense range of boundary angles (energy.DEFAULT_FRACTIONS)
N_ANGLES = 41
# Not identifiable: the uncorrected estimate's interval is widened by the largest memory
# bias measured on either water (docs/RADIATION_MEMORY.md: -14.6 % to +9 %).
UNIDENTIFIED_BIAS = 0.15


@dataclass
class RunMemoryWork:
    """One reverse run's memory works at its boundary angles (J, rad/s, kg m^2)."""

    run: str
    phi1: np.ndarray
    weights: np.ndarray
    KE: np.ndarray  # (w1f^2 + w1r^2) / 2, (rad/s)^2
    dW_basis: np.ndarray  # angles x memory coefficients: (W_rev - W_fwd) per unit coefficient


def run_memory_work(rec: RunRecord, fit: FamilyFit, angles: np.ndarray | None = None,
                    keep_all: bool = False, fractions=FRACTIONS) -> RunMemoryWork | None:
    """The memory works of ``fit``'s basis at the energy method's boundary angles of one
    reverse-symmetric run (None when the run has no forward and reverse stroke). ``angles``: the
    boundary angles (rad) the energy method used (default: its dense range from this run's own rest
    angle over ``fractions``, the energy method's ``(lo, hi)`` range); ``keep_all``: every angle is
    kept, nan where a stroke does not pass it."""
    dt = 1.0 / rec.known.sample_rate
    t = np.asarray(rec.t, float)
    grid = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-6)) + 1)
    phase_raw = motion_phase(rec)
    idx = np.clip(np.searchsorted(t, grid), 0, len(t) - 1)
    phase = phase_raw[idx]
    phi = _smooth(np.interp(grid, t, rec["phi"]), SMOOTH_HALF)
    w = np.gradient(phi, dt)
    w[(phase == "hold") | (phase == "idle")] = 0.0  # braked (the idle tail after the reverse stroke is never used)
    fwd = np.flatnonzero(phase == "free")
    rev = np.flatnonzero(phase == "reverse")
    if len(fwd) < 10 or len(rev) < 10:
        return None
    k_mid = rev[0]
    rest = float(np.median(phi[fwd[-1]:rev[0] + 1])) if rev[0] > fwd[-1] else float(phi[k_mid])
    phi_n = rec.known.phi_neutral
    from addedinertia_env.identify.energy import hann_weights  # noqa: PLC0415

    lo, hi = _window(fractions)
    f = np.linspace(lo, hi, N_ANGLES)
    weights = hann_weights(f, lo, hi)
    phi1 = phi_n + f * (rest - phi_n)
    if angles is not None:
        phi1 = np.asarray(angles, float)
        weights = np.ones_like(phi1)
    # the basis' memory moments and their works along the measured motion
    cols = []
    from scipy import signal  # noqa: PLC0415

    from addedinertia_env.identify.memory import _section_tfs  # noqa: PLC0415

    for num, den in _section_tfs(fit.sections):
        bd, ad = signal.bilinear(np.polymul(num, [1.0, 0.0]), den, 1.0 / dt)
        mu = signal.lfilter(bd, ad, w)
        p = mu * w
        cols.append(np.r_[0.0, np.cumsum((p[1:] + p[:-1]) * 0.5 * dt)])
    Wc = np.stack(cols, axis=1)  # cumulative work per unit coefficient
    KE, dW, keep = [], [], []
    for j, a in enumerate(phi1):
        k1 = _crossing(phi, fwd, a)
        k4 = _crossing(phi, rev, a)
        if k1 is None or k4 is None:
            keep.append(False)
            KE.append(np.nan)
            dW.append(np.full(Wc.shape[1], np.nan))
            continue
        w1f, w1r = abs(_at(w, k1)), abs(_at(w, k4))
        W1, W4, Wm = _at(Wc, k1), _at(Wc, k4), Wc[k_mid]
        dW.append((W4 - Wm) - (Wm - W1))
        KE.append(0.5 * (w1f**2 + w1r**2))
        keep.append(True)
    keep = np.array(keep)
    if not keep.any():
        return None
    if keep_all:
        return RunMemoryWork(rec.name, phi1, weights, np.array(KE), np.array(dW))
    return RunMemoryWork(rec.name, phi1[keep], weights[keep], np.array(KE)[keep], np.array(dW)[keep])


def _window(fractions) -> tuple[float, float]:
    """The ``(lo, hi)`` range of boundary angles the energy method averaged over (a list of
    three or more fractions: its smallest and largest, the same span)."""
    f = [float(x) for x in fractions]
    return min(f), max(f)


def _crossing(phi: np.ndarray, idx: np.ndarray, level: float):
    """The fractional sample index where ``phi`` first crosses ``level`` within the samples ``idx``."""
    seg = phi[idx] - level
    k = np.nonzero((seg[:-1] < 0) != (seg[1:] < 0))[0]
    if not len(k):
        return None
    k = int(k[0])
    frac = seg[k] / (seg[k] - seg[k + 1]) if seg[k] != seg[k + 1] else 0.0
    return float(idx[k] + frac)


def _at(x: np.ndarray, k: float):
    i = int(math.floor(k))
    f = k - i
    if i + 1 >= len(x):
        return x[-1]
    return x[i] * (1 - f) + x[i + 1] * f


def family_bias(work: RunMemoryWork, fit: FamilyFit) -> tuple[float, np.ndarray]:
    """The run's Hann-weighted bias (kg m^2) under ``fit`` and its gradient in the memory coefficients."""
    g = work.weights / work.weights.sum()
    g0 = np.real(_basis(fit.sections, 0.0))
    per_coef = (g[:, None] * (work.dW_basis / work.KE[:, None])).sum(axis=0) - g0
    return float(per_coef @ fit.theta), per_coef


@dataclass
class CorrectedEstimate:
    """The energy method's lambda66 (kg m^2) with the memory's work removed: the value and its ci95, each
    passive family's own value, and the bias removed (kg m^2)."""

    value: float
    ci95: tuple[float, float]
    per_family: dict[str, dict]
    bias: float


class _FamilyUnion:
    """Each averaged family's corrected value and interval, their Akaike-weighted mixture's 95 % interval
    (the memory fit's weights, :func:`~addedinertia_env.identify.memory.family_intervals`), and the best
    family's value."""

    def __init__(self, memory: MemoryIdentification):
        self.memory, self.out, self.best = memory, {}, None
        self.values, self.sigmas, self.weights = [], [], []

    def add(self, fit: FamilyFit, value: float, half: float, biases: list[float]) -> None:
        """One family's corrected ``value`` with its 95 % ``half``-width and its runs' memory ``biases``."""
        lo, hi, bias = value - half, value + half, float(np.mean(biases))
        self.out[fit.family] = {"lambda66": value, "ci95": [lo, hi], "bias": bias,
                                "weight": self.memory.weights.get(fit.family, 1.0)}
        self.values.append(value)
        self.sigmas.append(half / Z95)
        self.weights.append(self.memory.weights.get(fit.family, 1.0))
        if fit is self.memory.best:
            self.best = (value, bias)

    def estimate(self) -> CorrectedEstimate | None:
        """The best family's value with the families' mixture interval (None: no family corrected)."""
        from addedinertia_env.identify.model_average import mixture_interval  # noqa: PLC0415

        if self.best is None:
            return None
        x, s, w = (np.asarray(a, float) for a in (self.values, self.sigmas, self.weights))
        ok = np.isfinite(x) & np.isfinite(s) & (w > 0)  # a family without a finite interval gives none to mix
        lo, hi = mixture_interval(x[ok], s[ok], w[ok]) if ok.any() else (math.nan, math.nan)
        return CorrectedEstimate(self.best[0], (min(lo, self.best[0]), max(hi, self.best[0])), self.out, self.best[1])


def corrected_energy(records: list[RunRecord], details: dict, memory: MemoryIdentification,
                     fractions=FRACTIONS) -> CorrectedEstimate | None:
    """lambda66 = A66(0) from the energy method's per-angle values (``details``: the energy result's, with its
    ``intervals`` and ``per_run_sigma_parts``) corrected angle by angle by each accepted family's memory bias;
    the interval is the families' mixture, weighted as the memory fit's.

    The bias at each angle is the memory's work over the energy method's *own* kinetic denominator (its
    crossing rates), so a rate error scales the balance and its memory term together, as in water without
    memory. Each run's budget is the energy method's (rates, current, torque scale, dissipation law) with
    its trend term taken on the *corrected* values (the uncorrected ones follow the memory's work across the
    angles, which is what the correction removes); the runs are pooled on that (Birge ratio), and the
    memory coefficients' share, common to every run, is added once."""
    from addedinertia_env.identify.common import pooled_interval  # noqa: PLC0415
    from addedinertia_env.identify.energy_pooling import _trend_excess  # noqa: PLC0415

    intervals, parts_list = details.get("intervals"), details.get("per_run_sigma_parts")
    if not intervals or not parts_list or any(p is None for p in parts_list):
        return _corrected_from_runs(records, details.get("per_run", []), details.get("per_run_sigma", []), memory,
                                    fractions)
    by_run: dict[str, list] = {}
    for iv in intervals:
        if not iv.get("rejected"):
            by_run.setdefault(iv["run"], []).append(iv)
    runs = [(rec, by_run[rec.name], parts) for rec, parts in zip([r for r in records if r.name in by_run], parts_list)]
    union = _FamilyUnion(memory)
    for fit in memory.accepted:
        g0 = np.real(_basis(fit.sections, 0.0))
        vals, sigs, grads, biases = [], [], [], []
        for rec, ivs, parts in runs:
            phi1 = np.array([iv["phi1"] for iv in ivs])
            work = run_memory_work(rec, fit, phi1, keep_all=True)
            if work is None:
                continue
            KE = np.array([0.5 * (iv["w1f"] ** 2 + iv["w1r"] ** 2) for iv in ivs])
            per_coef = work.dW_basis / KE[:, None] - g0  # angles x coefficients
            ok = np.all(np.isfinite(per_coef), axis=1)
            g = np.array([iv["weight"] for iv in ivs])[ok]
            if not ok.any() or g.sum() <= 0:
                continue
            g = g / g.sum()
            bias = per_coef[ok] @ fit.theta
            corrected = np.array([iv["lambda66"] for iv in ivs])[ok] - bias
            s_ind = np.array([iv["sigma_independent"] for iv in ivs])[ok]
            trend = _trend_excess(phi1[ok], corrected, s_ind, g, parts.get("slope_noise", 0.0))
            vals.append(float(g @ corrected))
            sigs.append(math.sqrt(parts["rate"] ** 2 + parts["current"] ** 2 + parts["common"] ** 2 + trend**2))
            grads.append(g @ per_coef[ok])
            biases.append(float(g @ bias))
        if not vals:
            continue
        value, lo, hi = pooled_interval(np.array(vals), np.array(sigs))
        # the memory model's share: its coefficients' covariance through the runs' pooled gradient
        wts = 1.0 / np.maximum(np.array(sigs), 1e-300) ** 2
        grad = (wts[:, None] * np.array(grads)).sum(axis=0) / wts.sum()
        common = float(np.sqrt(max(grad @ fit.cov_theta @ grad, 0.0))) if fit.cov_theta is not None else 0.0
        union.add(fit, value, math.hypot(0.5 * (hi - lo), Z95 * common), biases)
    return union.estimate()


Z95 = 1.959963984540054  # two-sided 95 % point of the normal


def _corrected_from_runs(records: list[RunRecord], per_run: list[float], per_run_sigma: list[float],
                         memory: MemoryIdentification, fractions=FRACTIONS) -> CorrectedEstimate | None:
    """:func:`corrected_energy` from the runs' values alone (an energy result made without its per-angle
    intervals, ``interval_details=False``): each run's Hann-weighted value corrected by the family's bias
    at the run's own dense angles; the interval is the families' weighted mixture."""
    from addedinertia_env.identify.common import pooled_interval  # noqa: PLC0415

    union = _FamilyUnion(memory)
    for fit in memory.accepted:
        vals, sigs, biases = [], [], []
        for rec, v, s in zip(records, per_run, per_run_sigma):
            work = run_memory_work(rec, fit, fractions=fractions)
            if work is None or not np.isfinite(v):
                continue
            b, grad = family_bias(work, fit)
            sb = float(np.sqrt(max(grad @ fit.cov_theta @ grad, 0.0))) if fit.cov_theta is not None else 0.0
            vals.append(v - b)
            sigs.append(math.hypot(s, sb) if np.isfinite(s) else sb)
            biases.append(b)
        if not vals:
            continue
        value, lo, hi = pooled_interval(np.array(vals), np.array(sigs))
        # the model's bias error is common to every run: not averaged away by pooling
        common = float(np.mean([math.sqrt(max(sg**2 - (s if np.isfinite(s) else 0.0)**2, 0.0))
                                for sg, s in zip(sigs, per_run_sigma)]))
        union.add(fit, value, math.hypot(0.5 * (hi - lo), 1.96 * common), biases)
    return union.estimate()


def combine(fit: float, fit_ci) -> tuple[float, tuple[float, float]]:
    """A66(0) from the two estimates the records give under the identified memory: the memory fit's own
    ``A66(inf) + sum theta_i G_i(0)`` (the whole records' equation, every unbraked sample of every record) is the
    value, with the memory fit's interval (the passive families' Akaike mixture with the fit's resolution:
    :func:`~addedinertia_env.identify.memory.identify_memory`).
    The energy method corrected (the balance at the boundary angles, through the same identified model) is its check,
    reported beside it (:func:`balance_check`), not mixed in.

    Not their inverse-variance mean: the corrected balance's budget holds its rates, current, torque scale and the
    memory coefficients' covariance, but not the error of the model's *work* between the strokes (after a 15 s hold
    on another lab's records it is 0.26-0.31 % off while its interval says +-0.1 %, docs/INTERVALS.md), so a mean
    would pull the value off by a quarter of that. Nor a floor of half their disagreement (the rule to session 11):
    the disagreement is mostly the balance's own error, so it sized the interval by the check, not by the value
    reported (foreign-lab-2: 0.22 % half-width for a 0.008 % median error; docs/INTERVALS.md, "With memory")."""
    lo, hi = fit_ci
    return float(fit), (float(min(lo, fit)), float(max(hi, fit)))


def balance_check(energy: float, energy_ci, fit: float, fit_ci) -> dict:
    """The corrected balance beside the memory fit's A66(0): their difference (kg m^2) and that difference over the
    two intervals' half-widths together (``z``, 1.96 where they just agree at 95 %), for the JSON."""
    d = float(energy) - float(fit)
    h_e = max(energy - energy_ci[0], energy_ci[1] - energy)
    h_f = max(fit - fit_ci[0], fit_ci[1] - fit)
    scale = math.hypot(h_e, h_f) / Z95
    return {"difference": d, "z": d / scale if scale > 0 else math.inf}


def with_memory(result, all_records: list[RunRecord], reverse_records: list[RunRecord], prior: str = "none",
                bem_cache=None, fractions=FRACTIONS):
    """The energy method's :class:`~addedinertia_env.identify.common.Result` with the water's
    memory identified from ``all_records`` (decays and reverse runs) and corrected for:
    ``lambda66`` becomes A66(0) (:func:`combine`); the JSON adds ``A66_swing``, ``A66_inf`` (each with ``ci95``),
    the memory model, and the uncorrected value. Memory-free water (``memory: "none"``):
    the energy method's numbers unchanged. Not identifiable: the uncorrected value with its
    interval widened by the bias memory may carry (:data:`UNIDENTIFIED_BIAS`). Identified from fewer than
    :data:`~addedinertia_env.identify.memory.MIN_STRETCHES` stretches of free motion (one reverse run alone):
    the corrected value with an interval of +- the whole correction (``memory_interval`` says why). ``prior``: ``"none"`` (the
    records alone) or ``"bem"`` (:mod:`~addedinertia_env.identify.memory_prior`), stated as ``prior``."""
    from addedinertia_env.identify.memory_prior import identify_memory_with_prior  # noqa: PLC0415

    mem = identify_memory_with_prior(all_records, prior, bem_cache)
    details = dict(result.details)
    details.update(mem.to_json())
    details["prior"] = prior
    value, ci = result.lambda66, result.ci95
    if mem.identified:
        corrected = corrected_energy(reverse_records, details, mem, fractions)
        if corrected is not None:
            details["lambda66_uncorrected"] = value
            details["lambda66_uncorrected_ci95"] = list(ci)
            details["memory_bias"] = corrected.bias
            details["memory_correction"] = corrected.per_family
            details["lambda66_energy_corrected"] = corrected.value
            details["lambda66_energy_corrected_ci95"] = list(corrected.ci95)
            value, ci = combine(mem.A_zero, mem.ci95["A66_zero"])
            details["memory_balance_check"] = balance_check(corrected.value, corrected.ci95, mem.A_zero,
                                                            mem.ci95["A66_zero"])
            if mem.n_stretches < MIN_STRETCHES:
                # too few starts from rest to estimate the model's error: its variances are clustered by stretch
                # (and by 2-4 windows), so neither a family's interval nor their mixture means anything; the
                # records bound the correction only by its own size, and the interval holds it whole
                half = abs(value - result.lambda66)
                ci = (value - half, value + half)
                half_e = abs(corrected.value - result.lambda66)  # the corrected balance's likewise
                details["lambda66_energy_corrected_ci95"] = [corrected.value - half_e, corrected.value + half_e]
                details["memory_interval"] = (
                    f"+- the whole memory correction ({100 * half / abs(value):.2f} %): "
                    f"{mem.n_stretches} stretch(es) of free motion, at least {MIN_STRETCHES} needed to estimate the "
                    "memory model's error (hand identify the hull's free decays beside its reverse runs)")
        else:
            details["memory"] = "not identifiable: no forward and reverse stroke to correct in the reverse runs"
    if str(details.get("memory", "")).startswith("not identifiable"):
        half = UNIDENTIFIED_BIAS * abs(value)
        ci = (min(ci[0], value - half), max(ci[1], value + half))
        details["ci95_widened_by"] = f"+-{100 * UNIDENTIFIED_BIAS:.0f} % (the bias an unidentified memory may carry)"
    from addedinertia_env.identify.common import Result  # noqa: PLC0415

    return Result(method=result.method, lambda66=value, ci95=(float(ci[0]), float(ci[1])),
                  n_intervals=result.n_intervals, details=details)
