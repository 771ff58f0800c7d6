"""The energy method's error budget: each term's share, found by swapping in the simulator's truth.

For one simulated reverse-symmetric run whose true state is logged at every sample, the
estimator's balance terms (:class:`~addedinertia_env.identify.energy.BalanceTerms`, one
set per boundary angle) are replaced one group at a time by their true values, and the
change of the run's weighted estimate is that group's share of the error. With every
term true, what is left is the simulator's own bookkeeping (integrator drift). This
module reads the simulator's truth: it is scoring code, never used by an estimator.

Groups (percent of the true lambda66, signed: estimate minus truth):

* ``engine inertia``: the inertia MuJoCo's mass matrix integrates minus the ``truth`` written;
* ``bookkeeping``: the balance with every term true (integrator drift over the strokes);
* ``crossing times``: measured work series read at the true crossing instants;
* ``hull rates``: true rates at the true crossings;
* ``spring``: true angles at the rests and the true neutral;
* ``current offset/gain``: the work recomputed from the current corrected with the sensor's
  true offset and gain (when the estimator calibrated the torque on the flywheel's balance,
  this is what that calibration's scale left);
* ``current noise``: the true (noise-free) sampled current, trapezoid rule;
* ``smoothed angles``: the true angles instead of the smoothed encoder angles in the work sum;
* ``integration rule``: the true current's exact course between samples (the electrical
  transient) instead of the estimator's rule on the sample grid (and its fitted lag);
* ``motor friction``: the true rotor friction instead of the rig block's model;
* ``hull at rest``: true kinetic energy left at t2 and t3;
* ``dissipation mismatch``: the true ``W_reverse - W_forward`` instead of the model's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from addedinertia_env.identify.energy import (
    DEFAULT_FRACTIONS,
    DENSE_ANGLES,
    BalanceTerms,
    RunBalance,
    hann_weights,
    inertia_from_terms,
    prepared_balance,
)
from addedinertia_env.records.record import RunRecord
from addedinertia_env.sim import forces
from addedinertia_env.sim.mujoco_rig import MujocoRig, TrueState
from addedinertia_env.sim.params import RigParams
from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.protocol import ExperimentPlan
from addedinertia_env.experiment.runner import run_experiment


class TruthLoggingRig(MujocoRig):
    """A MuJoCo rig that keeps the true state after every sample (row k of the record = ``states[k]``)."""

    def reset(self, *args, **kwargs):
        """Reset as :class:`MujocoRig` does and start the true-state log with the state after the reset."""
        reading = super().reset(*args, **kwargs)
        self.states: list[TrueState] = [self.true_state()]
        return reading

    def step(self, cmd):
        """Step as :class:`MujocoRig` does and log the true state at the new sample."""
        reading = super().step(cmd)
        self.states.append(self.true_state())
        return reading


@dataclass
class TrueRun:
    """A simulated record with its true state per sample (arrays of the :class:`TrueState` fields)."""

    record: RunRecord
    params: RigParams
    states: dict[str, np.ndarray]
    engine_hull_inertia: float  # kg m^2, M[hull,hull] - M[fly,fly] of MuJoCo's mass matrix

    @property
    def truth(self) -> float:
        """The simulator's lambda66, kg m^2 (scoring only)."""
        return self.params.hull.lambda66


def simulate_with_truth(params: RigParams, controller: str | Controller, plan: ExperimentPlan | None = None,
                        seed: int = 0) -> TrueRun:
    """One reverse-symmetric run on ``params`` with ``controller`` (a name, or ``"oracle"``)."""
    rig = TruthLoggingRig(params, seed=seed)
    if controller == "oracle":
        from addedinertia_env.experiment.oracle import OracleController  # noqa: PLC0415

        ctrl = OracleController(rig)
    elif isinstance(controller, str):
        from agents import make_controller  # noqa: PLC0415

        ctrl = make_controller(controller)
    else:
        ctrl = controller
    record = run_experiment(rig, ctrl, plan)
    states = {f.name: np.array([getattr(s, f.name) for s in rig.states]) for f in dataclasses.fields(TrueState)}
    M = np.zeros((rig.model.nv, rig.model.nv))
    mujoco.mj_fullM(rig.model, rig.data, M)
    h, f = rig._hull_dof, rig._fly_dof
    return TrueRun(record, params, states, float(M[h, h] - M[f, f] - params.hull.J_hull))


# --- true terms -------------------------------------------------------------------------

def _true_crossing(t: np.ndarray, phi: np.ndarray, w: np.ndarray, k: int, level: float) -> tuple[float, float]:
    """Instant and rate where the true angle crosses ``level`` between samples k-1 and k (cubic Hermite)."""
    a, b = k - 1, k
    h = t[b] - t[a]
    p0, p1, m0, m1 = phi[a], phi[b], w[a] * h, w[b] * h

    def H(x):
        return ((2 * x**3 - 3 * x**2 + 1) * p0 + (x**3 - 2 * x**2 + x) * m0 + (-2 * x**3 + 3 * x**2) * p1
                + (x**3 - x**2) * m1)

    def dH(x):
        return (6 * x**2 - 6 * x) * p0 + (3 * x**2 - 4 * x + 1) * m0 + (-6 * x**2 + 6 * x) * p1 + (3 * x**2 - 2 * x) * m1

    x = (level - p0) / (p1 - p0) if p1 != p0 else 0.5
    for _ in range(8):
        x -= (H(x) - level) / dH(x)
    return float(t[a] + x * h), float(dH(x) / h)


def true_terms(run: TrueRun, bal: RunBalance, est: BalanceTerms) -> BalanceTerms:
    """The balance terms at ``est.phi1`` from the simulator's truth (reaction form)."""
    s, p = run.states, run.params
    t, phi, w = s["t"], s["phi"], s["w"]
    k1 = _crossing_index(phi, bal.free.start, bal.k2, est.phi1, bal.direction)
    k4 = _crossing_index(phi, bal.rev.start, bal.rev.stop - 1, est.phi1, -bal.direction)
    t1, w1 = _true_crossing(t, phi, w, k1, est.phi1)
    t4, w4 = _true_crossing(t, phi, w, k4, est.phi1)
    t2, t3 = t[bal.k2], t[bal.k3]
    R, D = s["reaction_work_hull"], s["dissipated_hull"]
    J = p.hull.J_hull + p.hull.lambda66
    spring = float(forces.potential_energy(phi[bal.k2], p) + forces.potential_energy(phi[bal.k3], p)
                   - 2 * forces.potential_energy(est.phi1, p))
    W_f = -(np.interp(t2, t, D) - np.interp(t1, t, D))
    W_r = -(np.interp(t4, t, D) - np.interp(t3, t, D))
    return BalanceTerms(phi1=est.phi1, t1=t1, t4=t4, w1f=w1, w1r=w4, spring=spring,
                        A_f=float(np.interp(t2, t, R) - np.interp(t1, t, R)),
                        A_r=float(np.interp(t4, t, R) - np.interp(t3, t, R)),
                        hull_rest=float(0.5 * J * (w[bal.k2] ** 2 + w[bal.k3] ** 2)), dW=float(W_r - W_f))


def _crossing_index(phi, a, b, level, direction):
    seg = direction * (phi[a:b] - level)
    idx = np.nonzero((seg[:-1] < 0) & (seg[1:] >= 0))[0]
    return int(a + idx[0] + 1)


# --- work series under different assumptions ---------------------------------------------

def _reaction_work_series(bal: RunBalance, current: np.ndarray, phi: np.ndarray | None = None) -> np.ndarray:
    """Cumulative reaction work (J) from a sampled current series (A) under the estimator's
    integration rule and friction model, on the estimator's smoothed angles or on ``phi``."""
    i_mid = bal.interval_current(current)
    dphi = np.diff(bal.phi_s if phi is None else phi)
    return np.concatenate([[0.0], np.cumsum(-(bal.k_t * i_mid - _estimated_friction(bal)) * dphi)])


def _estimated_friction(bal: RunBalance) -> np.ndarray:
    """The estimator's rotor friction torque over each sample interval, N m."""
    omega = np.diff(bal.psi_s) / np.diff(bal.t)
    return bal.f_visc * omega + bal.f_coul * np.sign(omega)


def _exact_current_work(run: TrueRun, bal: RunBalance) -> np.ndarray:
    """Cumulative reaction work (J) of the true current's exact time course on the true angles,
    with the estimator's friction model: what the sampled current cannot give."""
    s = run.states
    friction = np.concatenate([[0.0], np.cumsum(_estimated_friction(bal) * np.diff(s["phi"]))])
    return -bal.k_t * s["current_angle"] + friction


# --- the budget ---------------------------------------------------------------------------

GROUPS = ("crossing times", "hull rates", "spring", "current offset/gain", "current noise", "smoothed angles",
          "integration rule", "motor friction", "hull at rest", "dissipation mismatch")


def _weighted(lams: list[float], g: np.ndarray) -> float:
    return float(np.dot(g, lams))


def budget(run: TrueRun, fractions=DEFAULT_FRACTIONS) -> dict[str, float]:
    """Signed error shares (percent of the true lambda66) of the run's dense weighted estimate.

    Each group's share is the estimate minus the estimate with that group taken from the
    truth: the shares add up to the estimate's error minus the bookkeeping residual
    (to first order; the terms enter nearly linearly).

    Keys: ``estimate`` (total error), ``engine inertia``, ``bookkeeping`` (all terms true),
    each of :data:`GROUPS` (one group swapped to truth, the rest as estimated), and
    ``sum of groups`` (to compare with ``estimate - bookkeeping``).
    """
    rec, p = run.record, run.params
    bal = prepared_balance(rec.without_truth(), "reaction", fractions, True)[0]
    f = np.linspace(fractions[0], fractions[1], DENSE_ANGLES)
    g_all = hann_weights(f, fractions[0], fractions[1])
    ests, trues, g = [], [], []
    for frac, gk in zip(f, g_all):
        got = bal.terms(bal.phi_n + frac * (bal.phi2 - bal.phi_n))
        if isinstance(got, str) or gk <= 0:
            continue
        ests.append(got[0])
        trues.append(true_terms(run, bal, got[0]))
        g.append(gk)
    g = np.array(g) / np.sum(g)
    lam, J_h = run.truth, p.hull.J_hull

    def pct(terms_list) -> float:
        return 100.0 * (_weighted([inertia_from_terms(T, J_h) for T in terms_list], g) / lam - 1.0)

    base = pct(ests)
    out = {"estimate": base, "engine inertia": 100.0 * run.engine_hull_inertia / lam - 100.0,
           "bookkeeping": pct(trues)}

    def swap(**fields_from_true) -> float:
        """The error removed by taking these fields from the truth: estimate minus swapped, percent."""
        swapped = []
        for E, T in zip(ests, trues):
            changes = {k: (v(E, T) if callable(v) else getattr(T, k)) for k, v in fields_from_true.items()}
            swapped.append(dataclasses.replace(E, **changes))
        return base - pct(swapped)

    t = bal.t
    W_est = bal.work_cum

    def work_between(W):
        return {"A_f": lambda E, T: float(np.interp(t[bal.k2], t, W) - np.interp(E.t1, t, W)),
                "A_r": lambda E, T: float(np.interp(E.t4, t, W) - np.interp(t[bal.k3], t, W))}

    # Crossing instants: the same measured work series read at the true instants.
    out["crossing times"] = swap(A_f=lambda E, T: float(np.interp(t[bal.k2], t, W_est) - np.interp(T.t1, t, W_est)),
                                 A_r=lambda E, T: float(np.interp(T.t4, t, W_est) - np.interp(t[bal.k3], t, W_est)))
    out["hull rates"] = swap(w1f=None, w1r=None)
    out["hull rate, forward"] = swap(w1f=None)
    out["hull rate, reverse"] = swap(w1r=None)
    out["spring"] = swap(spring=None)
    out["hull at rest"] = swap(hull_rest=None)
    out["dissipation mismatch"] = swap(dW=None)
    # Work term, split by what the current and angle series are.
    sens = p.sensors
    i_cal = (rec["i"] - sens.current_offset) / (1.0 + sens.current_gain_error)
    W_cal = _reaction_work_series(bal, i_cal)
    W_clean = _reaction_work_series(bal, run.states["i"])
    W_clean_true_angles = _reaction_work_series(bal, run.states["i"], phi=run.states["phi"])
    W_exact = _exact_current_work(run, bal)
    steps = [("current offset/gain", W_est, W_cal), ("current noise", W_cal, W_clean),
             ("smoothed angles", W_clean, W_clean_true_angles), ("integration rule", W_clean_true_angles, W_exact)]
    for name, before, after in steps:
        # swap(...) is the error removed; the difference of two is what the step between them removes.
        out[name] = swap(**work_between(after)) - swap(**work_between(before))
    out["motor friction"] = swap(A_f=None, A_r=None) - swap(**work_between(W_exact))
    out["sum of groups"] = sum(out[k] for k in GROUPS)
    return out


def budget_summary(runs: list[dict[str, float]]) -> dict[str, tuple[float, float]]:
    """Median and spread (half the 16-84 % range) of each budget line over several runs, percent."""
    keys = runs[0].keys()
    out = {}
    for k in keys:
        v = np.array([r[k] for r in runs])
        out[k] = (float(np.median(v)), float(0.5 * (np.percentile(v, 84) - np.percentile(v, 16))))
    return out


# --- seeded runs on the shipped presets -------------------------------------------------------

def preset_rig(preset: str, sensors: str = "calibrated") -> RigParams:
    """Preset ``preset`` with its sensors as shipped (``"preset"``), with the current and voltage
    gain errors set to zero (``"calibrated"``: noise, offsets and quantisation kept), or ideal."""
    from addedinertia_env.sim.params import SensorParams  # noqa: PLC0415
    from addedinertia_env.sim.presets import load_rig  # noqa: PLC0415

    rig = load_rig(preset)
    if sensors == "ideal":
        return rig.replace(sensors=SensorParams.ideal(rig.sensors.sample_rate))
    if sensors == "calibrated":
        return rig.replace(sensors=dataclasses.replace(rig.sensors, current_gain_error=0.0, voltage_gain_error=0.0))
    if sensors == "preset":
        return rig
    raise ValueError(f"sensors={sensors!r}: expected 'preset', 'calibrated' or 'ideal'")


def seeded_plan(preset: str, seed: int, spread: float = 0.1) -> ExperimentPlan:
    """The preset's plan with the twist ``alpha`` varied by +-``spread``/2 (relative) per seed.

    With the motor passive, the free stroke is the same in every seed of a rig: its encoder
    quantisation errors (the rest angle, the forward rates) would be one frozen draw shared
    by all seeds. An experimenter never twists the rod exactly alike twice; varying the
    twist per seed makes those errors differ between seeds as they do between real runs.
    """
    from addedinertia_env.sim.presets import load_preset  # noqa: PLC0415
    from addedinertia_env.experiment.protocol import plan_from_preset

    data = load_preset(preset)
    base = plan_from_preset(data)
    u = float(np.random.default_rng([seed, 1791]).random()) - 0.5
    return dataclasses.replace(base, alpha=base.alpha * (1.0 + spread * u))


def seeded_errors(preset: str, seeds, controller: str = "lqr", sensors: str = "calibrated") -> list[dict[str, float]]:
    """For each seed: the energy method's relative error (percent) and whether its 95 % interval
    covers the truth, on one run of ``preset`` (``seeded_plan``, ``preset_rig``)."""
    from addedinertia_env.identify import identify  # noqa: PLC0415

    rig = preset_rig(preset, sensors)
    out = []
    for seed in seeds:
        run = simulate_with_truth(rig, controller, seeded_plan(preset, seed), seed=seed)
        res = identify([run.record], "energy")
        out.append({"seed": seed, "error_pct": 100.0 * (res.lambda66 / run.truth - 1.0),
                    "covered": bool(res.ci95[0] <= run.truth <= res.ci95[1]),
                    "half_width_pct": 50.0 * (res.ci95[1] - res.ci95[0]) / run.truth})
    return out
