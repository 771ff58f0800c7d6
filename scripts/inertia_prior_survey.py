"""The inertia a controller is given against the truth, on a split's scenarios: the task's prior read at the
free stroke's stop (``ControllerContext.inertia_prior``) and the whole stroke's least-squares inertia
(agents/stroke_inertia.py), each divided by the true ``J_hull + lambda66`` (read here to judge them, by no
controller). One line per scenario; the free stroke only (no controller runs).

    python scripts/inertia_prior_survey.py drive-v3 --split train --count 32
"""

from __future__ import annotations

import argparse

from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.protocol import Experiment
from addedinertia_env.experiment.runner import controller_context
from addedinertia_env.experiment.scenarios import build_rig
from addedinertia_env.sim.forces import true_lambda66
from agents.stroke_inertia import stroke_fit_inertia


def main() -> None:
    """Print one line per scenario and the ranges."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("--split", default="train", help="tuning, test, or train (seeds outside both)")
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--count", type=int, default=8)
    a = ap.parse_args()
    suite = load_suite(a.suite)
    prior, fit = [], []
    for k in range(a.first, a.first + a.count):
        seed = suite.split_seed(a.split, k)
        sc = suite.scenario(seed)
        exp = Experiment(build_rig(sc), sc.plan)
        exp.start()
        ctx = controller_context(exp)
        true_J = sc.rig.hull.J_hull + true_lambda66(sc.rig)
        prior.append(ctx.inertia_prior / true_J)
        fit.append(stroke_fit_inertia(ctx) / true_J)
        print(f"{seed}: prior / truth {prior[-1]:.2f}, whole-stroke fit / truth {fit[-1]:.2f}", flush=True)
    print(f"prior {min(prior):.2f} .. {max(prior):.2f}; whole-stroke fit {min(fit):.2f} .. {max(fit):.2f} (n = {len(fit)})")


if __name__ == "__main__":
    main()
