"""Write docs/BEM_PRIOR.md: what a BEM lambda66 prior changes, measured.

    python -m addedinertia_env.reports.bem_prior [--seeds 4]

Two places take a prior for lambda66:

* the controller context's ``inertia_prior`` (``J_hull + lambda66``), which the default
  controller ``feedforward-pd`` uses for its feedforward torque. By default it is the free
  stroke's stop estimate ``-c (phi2 - phi_n) / f''(t2)``; with ``ExperimentPlan(lambda66_prior=...)``
  it is ``J_hull`` plus the BEM's A66 at the swing frequency (``configs/rigs/PRESET.bem.json``);
* the whole-record fit's starting value (``identify_whole_record(..., lambda66_start=...)``),
  by default a generic 10 kg m^2.

For each preset and seed the same simulated rig (realistic sensors, physics.md section 7)
runs once with each prior; the energy method's error, the tracking error and the motor
energy are compared, then the whole-record fit is started from each value on the first record.
Uses the cached BEM value: nothing is solved.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from agents import make_controller

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.sim.hull_presets import bem_lambda66
from addedinertia_env.identify import identify
from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.experiment.metrics import episode_metrics
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.experiment.protocol import plan_from_preset
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.sim.mujoco_rig import MujocoRig

COMMAND = "python -m addedinertia_env.reports.bem_prior"
PRESETS = ("wigley-2m", "spheroid-7")
CONTROLLER = "feedforward-pd"


class Probe:
    """Passes through to the controller; keeps the context's inertia prior."""

    def __init__(self, inner):
        self.inner = inner
        self.inertia_prior = None

    def reset(self, context) -> None:
        """Keep the context's ``inertia_prior`` (kg m^2) and reset the wrapped controller with it."""
        self.inertia_prior = context.inertia_prior
        self.inner.reset(context)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """The wrapped controller's action for ``observation`` (Stable-Baselines3 ``predict`` signature)."""
        return self.inner.predict(observation, state, episode_start, deterministic)


def measure(seeds: int, progress=print) -> dict:
    """Run each preset and seed with the stroke prior and with the BEM prior, and start the
    whole-record fit from each value.

    Returns ``{"rows": ..., "fits": ...}``: per run the energy-method error and interval
    half-width (fractions of the true lambda66), tracking RMS (rad) and motor energy (J);
    per preset the whole-record fit's result (kg m^2), evaluations and time (s).
    ``progress`` gets one line per run.
    """
    rows, fits = [], []
    for name in PRESETS:
        data = load_preset(name)
        params = rig_from_mapping(data)
        plan = plan_from_preset(data)
        lam_bem = bem_lambda66(name, "swing")
        for seed in range(seeds):
            for label, p in (("stroke", plan), ("bem", dataclasses.replace(plan, lambda66_prior=lam_bem))):
                probe = Probe(make_controller(CONTROLLER))
                rec = run_experiment(MujocoRig(params, seed=seed), probe, p, run_id=f"{name}-{label}-{seed}")
                res = identify([rec], "energy")
                m = episode_metrics(rec)
                truth = params.hull.lambda66  # scoring only
                rows.append({"preset": name, "seed": seed, "prior": label, "truth": truth, "lambda66_bem": lam_bem,
                             "inertia_prior": probe.inertia_prior, "J_true": params.hull.J_hull + truth,
                             "error": res.lambda66 / truth - 1.0, "ci_half": 0.5 * (res.ci95[1] - res.ci95[0]) / truth,
                             "tracking_rms": m.tracking_rms_rad if np.isfinite(m.tracking_rms_rad) else None,
                             "energy": m.energy_J, "rec": rec})
                progress(f"{name} seed {seed} prior {label}: error {100 * rows[-1]['error']:+.3f} %")
        rec = next(r["rec"] for r in rows if r["preset"] == name and r["prior"] == "stroke")
        for label, start in (("generic 10", None), ("BEM", lam_bem)):
            t0 = time.perf_counter()
            res = identify([rec], "whole-record", lambda66_start=start)
            fits.append({"preset": name, "start": label, "start_value": res.details["lambda66_start"],
                         "lambda66": res.lambda66, "truth": params.hull.lambda66, "n_evals": res.details["n_evals"],
                         "seconds": time.perf_counter() - t0, "converged": res.details["converged"]})
            progress(f"{name} whole-record from {label}: {res.lambda66:.5f} in {fits[-1]['seconds']:.1f} s")
    return {"rows": rows, "fits": fits}


def render(m: dict, seeds: int, wall: float) -> str:
    """The Markdown of docs/BEM_PRIOR.md from :func:`measure`'s result, with the command and the run time ``wall`` (s)."""
    L = ["# The BEM value as a prior for lambda66", "",
         "Generated by a command; do not edit by hand. To regenerate (a few minutes on 2 cores):", "",
         "```", f"{COMMAND} --seeds {seeds}", "```", "",
         f"- Machine: {machine_line()}; the machine was shared with other jobs. Run time {wall:.0f} s.",
         f"- Presets {', '.join(PRESETS)} as shipped (realistic sensors); controller `{CONTROLLER}` (the only classical "
         "controller that reads the context's inertia prior); seeds 0.."
         f"{seeds - 1}; the same seed gives the same sensor noise with either prior.",
         "- BEM lambda66: A66 at the preset's swing frequency from `configs/rigs/PRESET.bem.json` "
         "(docs/HYDRODYNAMICS.md). Stroke prior: the free stroke's stop estimate.", "",
         "## Controller context prior (energy method)", "",
         "| preset | prior | true lambda66 | BEM lambda66 | median prior error (J_h + lambda66) | median abs energy-method error | "
         "mean interval half-width | median tracking rms (mrad) | median motor energy (J) |",
         "|---|---|---|---|---|---|---|---|---|"]
    rows = m["rows"]
    for name in PRESETS:
        for label in ("stroke", "bem"):
            rs = [r for r in rows if r["preset"] == name and r["prior"] == label]
            if not rs:
                continue
            J_true = None
            truth = rs[0]["truth"]

            def med(key, scale=1.0, absolute=False):
                vals = [r[key] for r in rs if r.get(key) is not None]
                if not vals:
                    return "n/a"
                v = np.median(np.abs(vals)) if absolute else np.median(vals)
                return f"{v * scale:.3g}"

            pri = [r["inertia_prior"] / r["J_true"] - 1.0 for r in rs if r.get("inertia_prior") is not None]
            del J_true
            L.append(f"| {name} | {label} | {truth:.3f} | {rs[0]['lambda66_bem']:.3f} | "
                     f"{(f'{100 * np.median(pri):+.2f} %' if pri else 'n/a')} | {med('error', 100, True)} % | "
                     f"{med('ci_half', 100)} % | {med('tracking_rms', 1000)} | {med('energy')} |")
    L += ["", "## Whole-record fit start", "",
          "| preset | start | start value | lambda66 | error | function evaluations | seconds | converged |",
          "|---|---|---|---|---|---|---|---|"]
    for f in m["fits"]:
        L.append(f"| {f['preset']} | {f['start']} | {f['start_value']:.3f} | {f['lambda66']:.5f} | "
                 f"{100 * (f['lambda66'] / f['truth'] - 1):+.4f} % | {f['n_evals']} | {f['seconds']:.1f} | {f['converged']} |")
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    """Regenerate ``docs/BEM_PRIOR.md`` (the command is in the module docstring); ``argv`` as on the command line; returns 0."""
    p = argparse.ArgumentParser(prog=COMMAND)
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--out", default="docs/BEM_PRIOR.md")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    m = measure(args.seeds, progress=lambda s: print(s, file=sys.stderr, flush=True))
    root = Path(__file__).resolve().parents[2]
    atomic_write_text(root / args.out, render(m, args.seeds, time.perf_counter() - t0))
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
