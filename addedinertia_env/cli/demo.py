"""``addedinertia demo``: the main job on the default simulated rig."""

from __future__ import annotations

from agents.registry import DEFAULT_CONTROLLER

import time
from pathlib import Path

from addedinertia_env.identify import IdentificationError
from addedinertia_env.records.plots import plot_run
from addedinertia_env.records.record import write_record
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.evaluation.scoring import CORRECTED, estimate, score_episode
from addedinertia_env.experiment.protocol import plan_from_preset
from addedinertia_env.apps.simulate import simulate_run
from addedinertia_env.cli.common import emit_json, info, non_negative_int


def register(sub) -> None:
    """Add the ``demo`` subcommand and its options to the subparsers ``sub`` (``addedinertia demo --help``)."""
    p = sub.add_parser("demo", help="simulate the default rig, identify lambda66, plot the run")
    p.add_argument("--out", default="out/demo")
    p.add_argument("--rig", default="wigley-2m")
    p.add_argument("--controller", default=DEFAULT_CONTROLLER)
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia demo`` with the parsed ``args``; writes the record and the figure under ``--out`` and prints the identified lambda66 (kg m^2) against the simulator's; returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    out = Path(args.out)
    data = load_preset(args.rig)
    rig = rig_from_mapping(data)
    plan = plan_from_preset(data)
    t0 = time.perf_counter()
    record = simulate_run(rig, args.controller, plan, seed=args.seed, run_id="demo")
    csv_path = write_record(record, out / "demo.csv")
    figure = plot_run(record, out / "demo.png", title=f"{args.rig}, controller {args.controller}")
    estimated = estimate([record], CORRECTED)
    if estimated.failed:
        raise IdentificationError(estimated.failure)
    score = score_episode([record], CORRECTED, estimated=estimated, metrics=False)  # truth: the record's truth block
    truth, err = score.lambda66_true, score.rel_error
    summary = {"rig": args.rig, "controller": args.controller, "record": str(csv_path), "figure": str(figure),
               "lambda66_true": truth, "lambda66_est": score.lambda66_est, "ci95": list(score.ci95),
               "rel_error": err, "n_intervals": estimated.n_intervals, "wall_s": time.perf_counter() - t0}
    if args.json:
        emit_json(summary)
    else:
        lo, hi = score.ci95
        print(f"rig {args.rig}, controller {args.controller}")
        print(f"lambda66 true      {truth:.4f} kg m^2")
        print(f"lambda66 estimated {score.lambda66_est:.4f} kg m^2  (95 % interval {lo:.4f} .. {hi:.4f})")
        print(f"relative error     {100 * err:+.3f} %")
        info(f"record {csv_path}, figure {figure}")
    return 0
