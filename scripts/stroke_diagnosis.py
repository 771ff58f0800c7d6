"""Diagnose one scenario of a suite: one cycle per controller (``run_experiment``), the reverse stroke summed
up from the record (share of samples with the current at its limit or the voltage at the supply, the peak
voltage and current, the flywheel's rate from ``psi``), and what the controller was given (the inertia
prior beside the scenario's true ``J_hull + lambda66``, printed for the diagnosis only: no controller reads it).

    python scripts/stroke_diagnosis.py drive-v3 1000000001 feedforward-pd smith-pd "pd@omega_c=10"
    python scripts/stroke_diagnosis.py drive-v3 1000000001 feedforward-pd --true-prior   # prior := the truth

``--true-prior`` replaces the task's inertia prior by the true value (the plan's ``lambda66_prior``): what
each controller would do with a right prior (a diagnosis, never an entry).
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from addedinertia_env.bench.runner import cycle_seed, episode_controller
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.experiment.scenarios import build_rig
from addedinertia_env.sim.forces import true_lambda66


def main() -> None:
    """Print one block per controller."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("seed", type=int)
    ap.add_argument("controllers", nargs="+", help='"name" or "name@knob=value,..."')
    ap.add_argument("--true-prior", action="store_true", help="the inertia prior replaced by the truth (diagnosis)")
    a = ap.parse_args()
    suite = load_suite(a.suite)
    sc = suite.scenario(a.seed)
    true_J = sc.rig.hull.J_hull + true_lambda66(sc.rig)
    if a.true_prior:
        sc = dataclasses.replace(sc, plan=dataclasses.replace(sc.plan, lambda66_prior=true_lambda66(sc.rig)))
    m = sc.rig.motor
    delay = 1e3 * sc.loop.obs_delay_s if sc.loop is not None else 0.0
    print(f"seed {a.seed}: supply {m.u_max:.1f} V, R {m.R:.2f} Ohm, i_max {m.i_max:.1f} A, J_f {m.J_flywheel:.3f} kg m^2, "
          f"gear {getattr(sc.rig.drive, 'gear_ratio', 1.0):.1f}, link {delay:.1f} ms, true J_hull + lambda66 {true_J:.2f} kg m^2")
    for spec in a.controllers:
        name, _, knobs = spec.partition("@")
        kwargs = {k: float(v) for k, v in (kv.split("=") for kv in knobs.split(",") if kv)}
        task = suite.task(sc, name, kwargs or None)
        rig = build_rig(sc, seed=cycle_seed(sc, 0))
        ctl = episode_controller(task.controller, task.controller_kwargs, rig)
        rec = run_experiment(rig, ctl, sc.plan, run_id="diagnosis")
        s = rec.samples
        rev = np.asarray(s["phase"]).astype(str) == "reverse"
        i, u = np.asarray(s["i"])[rev], np.asarray(s["u"])[rev]
        omega = np.gradient(np.asarray(s["psi"]), np.asarray(s["t"]))[rev]
        ctx = getattr(ctl, "ctx", None)
        print(f"  {spec}: current at its limit {np.mean(np.abs(i) > 0.98 * m.i_max):.0%} of the reverse stroke, "
              f"voltage at the supply {np.mean(np.abs(u) > 0.98 * m.u_max):.0%}; peak |u| {np.max(np.abs(u)):.1f} V, "
              f"peak |i| {np.max(np.abs(i)):.1f} A; flywheel {omega[0]:+.1f} rad/s at the start, {omega.min():+.1f} .. "
              f"{omega.max():+.1f}" + (f"; inertia prior {ctx.inertia_prior:.2f} kg m^2" if ctx is not None else "")
              + (f"; controller's J {ctl.J:.2f}" if hasattr(ctl, "J") else ""))


if __name__ == "__main__":
    main()
