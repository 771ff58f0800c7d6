"""What booking the gearhead's loss does to the energy method (docs/ENERGY_METHOD.md, issue 28): each
controller's first cycle on a suite's scenarios, the signed error as written before the loss was booked
(``energy_balance.GEAR_LOSS = False``), with the fitted loss booked (the method now), and, as a
diagnostic that reads the simulator's truth, with the drawn loss booked instead of the fitted one; beside
them the fitted and the drawn loss. One JSON row per episode on stdout.

    PYTHONPATH=$PWD python scripts/drive_gear_budget.py drive-v1 --split tuning --count 16 \
        --controllers oracle feedforward-pd zero --records out/gear-records > out/drive_gear_budget.jsonl

``--records DIR`` keeps each record (pickle) and reuses it on a rerun.
"""

from __future__ import annotations

import argparse
import json
import pickle
from pathlib import Path

import addedinertia_env.identify.energy_balance as energy_balance
import addedinertia_env.identify.energy_gear as energy_gear
from addedinertia_env.bench.runner import build_rig, cycle_seed, episode_controller
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.identify import identify


def _error(rec) -> float | None:
    try:
        r = identify([rec.without_truth()], "energy", asymmetry_correction=False, interval_details=False)
    except Exception:  # noqa: BLE001 - a failed identification is a null error
        return None
    return r.lambda66 / rec.meta["truth"]["lambda66"] - 1.0


def _record(suite, sc, controller: str, cache: Path | None):
    path = cache / f"{suite.name}-{sc.seed}-{controller}.pkl" if cache else None
    if path is not None and path.exists():
        return pickle.loads(path.read_bytes())
    task = suite.task(sc, controller)
    rig = build_rig(task.scenario, seed=cycle_seed(task.scenario, 0))
    rec = run_experiment(rig, episode_controller(controller, task.controller_kwargs, rig), task.scenario.plan,
                         run_id=f"{sc.name}/cycle-0")
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(rec))
    return rec


def main() -> None:
    """Run the comparison; print one JSON row per episode."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("--split", default="tuning")
    ap.add_argument("--count", type=int, default=16)
    ap.add_argument("--controllers", nargs="+", default=["oracle", "feedforward-pd", "zero"])
    ap.add_argument("--records", type=Path, default=None)
    a = ap.parse_args()
    suite = load_suite(a.suite)
    fit = energy_gear.gear_loss_fit
    for sc in suite.scenarios(a.split)[:a.count]:
        for c in a.controllers:
            rec = _record(suite, sc, c, a.records)
            drawn = rec.meta["truth"]["drive"]
            row = {"seed": sc.seed, "controller": c, "drawn_mesh": 1.0 - drawn["gear_efficiency"],
                   "drawn_drag_Nm": drawn["gear_drag"]}
            energy_balance.GEAR_LOSS = False
            row["e_as_written_before"] = _error(rec)
            energy_balance.GEAR_LOSS = True
            row["e_booked"] = _error(rec)
            g = energy_balance.RunBalance(rec.without_truth(), "reaction", False).gear_loss
            row["fit"] = None if g is None else {"scale": g.scale, "mesh": g.mesh, "drag_Nm": g.drag,
                                                 "rms_rad": g.rms_rad, "both_quadrants": g.both_quadrants}

            def drawn_loss(*args, _d=drawn):  # the diagnostic: the fit's scale, the drawn loss
                got = fit(*args)
                if got is None:
                    return None
                return energy_gear.GearLoss(scale=got.scale, mesh=1.0 - _d["gear_efficiency"] if got.both_quadrants
                                            else 0.0, drag=_d["gear_drag"], mesh_se=0.0, drag_se=0.0,
                                            rms_rad=got.rms_rad, both_quadrants=got.both_quadrants)

            energy_balance.gear_loss_fit = drawn_loss
            row["e_drawn_loss_booked"] = _error(rec)
            energy_balance.gear_loss_fit = fit
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
