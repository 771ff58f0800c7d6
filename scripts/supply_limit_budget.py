"""The supply limit in the energy method's error budget (docs/ENERGY_METHOD.md, issue 28): wigley-2m with a
light flywheel (0.03 kg m^2) and feedforward-pd, realistic sensors, on a 48 V and a 9 V supply, same seeds;
per run the error of the method as written, the tracking rms and whether discovery names ``supply_limit``.

    PYTHONPATH=$PWD python scripts/supply_limit_budget.py --seeds 3
"""

from __future__ import annotations

import argparse
import dataclasses
import json

from addedinertia_env.apps.simulate import simulate_run
from addedinertia_env.discover.supply_limit import judge
from addedinertia_env.evaluation.scoring import AS_WRITTEN, score_episode
from addedinertia_env.experiment.protocol import plan_from_preset
from addedinertia_env.sim.presets import load_preset, rig_from_mapping


def main() -> None:
    """One JSON line per (seed, supply)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--supplies", type=float, nargs="+", default=[48.0, 9.0])
    ap.add_argument("--flywheel", type=float, default=0.03, help="J_flywheel, kg m^2")
    a = ap.parse_args()
    for seed in range(a.first_seed, a.first_seed + a.seeds):
        for u_max in a.supplies:
            data = load_preset("wigley-2m")
            params, plan = rig_from_mapping(data), plan_from_preset(data)
            params = params.replace(motor=dataclasses.replace(params.motor, u_max=u_max, J_flywheel=a.flywheel))
            rec = simulate_run(params, "feedforward-pd", plan, seed=seed, run_id=f"supply-{u_max:g}V-{seed}")
            s = score_episode([rec], AS_WRITTEN)
            ev = judge([rec.without_truth()])
            print(json.dumps({"seed": seed, "u_max": u_max, "rel_error": s.rel_error, "tracking_rms_rad":
                              s.tracking_rms_rad, "supply_limit": ev["named"], "saturated_s": ev.get("saturated_s")}),
                  flush=True)


if __name__ == "__main__":
    main()
