"""What is left of the drive's bias once the gearhead's loss is booked (docs/DRIVE.md, issue 28): each
controller on a suite's scenarios with its drive as drawn and with one flaw switched off at a time
(same scenario, same sensor noise), the signed error of the energy method (loss booked). One JSON
row per episode on stdout.

    PYTHONPATH=$PWD python scripts/drive_residual.py drive-v1 --split tuning --count 8 \
        --controllers feedforward-pd lqr > out/drive_residual.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import json

from addedinertia_env.bench.runner import build_rig, cycle_seed, episode_controller
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.identify import identify

OFF = {  # a flaw switched off: the DriveParams fields set to their neutral values
    "as drawn": {},
    "no cogging": {"cogging_torque": 0.0},
    "no backlash": {"backlash": 0.0, "rotor_inertia": 0.0},
    "no gear loss": {"gear_efficiency": 1.0, "gear_drag": 0.0},
    "ideal driver": {"driver_time_constant": 0.0},
}


def main() -> None:
    """Run every variant; print one JSON row per episode."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("--split", default="tuning")
    ap.add_argument("--count", type=int, default=8)
    ap.add_argument("--controllers", nargs="+", default=["feedforward-pd", "lqr"])
    ap.add_argument("--variants", nargs="+", default=list(OFF), choices=list(OFF))
    a = ap.parse_args()
    suite = load_suite(a.suite)
    for sc in suite.scenarios(a.split)[:a.count]:
        for c in a.controllers:
            for v in a.variants:
                drive = dataclasses.replace(sc.rig.drive, **OFF[v])
                scen = dataclasses.replace(sc, rig=sc.rig.replace(drive=drive))
                task = suite.task(scen, c)
                rig = build_rig(task.scenario, seed=cycle_seed(task.scenario, 0))
                rec = run_experiment(rig, episode_controller(c, task.controller_kwargs, rig), task.scenario.plan)
                try:
                    r = identify([rec.without_truth()], "energy", asymmetry_correction=False, interval_details=False)
                    e = r.lambda66 / rec.meta["truth"]["lambda66"] - 1.0
                except Exception as ex:  # noqa: BLE001 - a failed identification is a null error
                    e, why = None, str(ex)[:120]
                else:
                    why = None
                print(json.dumps({"seed": sc.seed, "controller": c, "variant": v, "e": e, "failure": why}), flush=True)


if __name__ == "__main__":
    main()
