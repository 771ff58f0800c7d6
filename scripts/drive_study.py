"""Which drive flaws make control decide? (issue 28, step 1)

Runs wigley-2m scenarios (realistic sensors, the default tuned gains) with one drive flaw
at a time, every controller on the same scenarios and sensor noise, and prints per flaw
and controller the mean |error| of lambda66 (the method as written, the bench's ranked
estimate), the mean paired control error |e - e_oracle| and the failures, as JSON lines.

    python scripts/drive_study.py --seeds 3 --jobs 1 > out/drive_study.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys

from addedinertia_env.bench.runner import run_tasks
from addedinertia_env.bench.suites import EpisodeTask
from addedinertia_env.sim.drive import DriveParams
from addedinertia_env.experiment.scenarios import make_scenario

# One flaw at a time, at a realistic size (docs/DRIVE.md cites the parts).
FLAWS = {
    "ideal": DriveParams(),
    "gearbox 5:1": DriveParams(gear_ratio=5.0),
    "gear friction 5:1 eta 0.85": DriveParams(gear_ratio=5.0, gear_efficiency=0.85),
    "gear drag 5:1 0.02 N m": DriveParams(gear_ratio=5.0, gear_drag=0.02),
    "cogging 20 mN m x 24": DriveParams(cogging_torque=0.02, cogging_periods=24.0),
    "cogging 5:1 20 mN m x 24": DriveParams(gear_ratio=5.0, cogging_torque=0.02, cogging_periods=24.0),
    "driver 1 ms": DriveParams(driver_time_constant=1e-3),
    "driver 5 ms": DriveParams(driver_time_constant=5e-3),
    # backlash (issue 28 step 1 of the second session): 1 deg at the flywheel, a 150 g cm^2 rotor
    "backlash 5:1 1 deg": DriveParams(gear_ratio=5.0, backlash=math.radians(1.0), rotor_inertia=1.5e-5),
    "gearhead 5:1 eta 0.95 drag 5 mN m": DriveParams(gear_ratio=5.0, gear_efficiency=0.95, gear_drag=0.005),
    "gearhead 5:1 eta 0.92 drag 5 mN m backlash 1 deg": DriveParams(
        gear_ratio=5.0, gear_efficiency=0.92, gear_drag=0.005, backlash=math.radians(1.0), rotor_inertia=1.5e-5),
}
SUPPLIES = {"supply 12 V": 12.0}
CONTROLLERS = ("oracle", "zero", "pd", "pid", "lqr", "feedforward-pd", "drive-aware")


def tasks(seeds: list[int], flaws: list[str], controllers: list[str]) -> list[EpisodeTask]:
    """One episode per (flaw, seed, controller)."""
    out = []
    for flaw in flaws:
        for seed in seeds:
            sc = make_scenario(seed, preset="wigley-2m", fixed={"sensor_quality": "realistic"},
                               name=f"study/{flaw}/{seed}")
            rig = sc.rig
            if flaw in FLAWS:
                d = FLAWS[flaw]
                rig = rig.replace(drive=d, motor=dataclasses.replace(rig.motor, k_t=rig.motor.k_t / d.gear_ratio))
            else:
                rig = rig.replace(motor=dataclasses.replace(rig.motor, u_max=SUPPLIES[flaw]))
            sc = dataclasses.replace(sc, rig=rig)
            for c in controllers:  # "name" or "name@knob=value,knob=value" (a knob's value other than tuned)
                name, _, knobs = c.partition("@")
                kwargs = {k: float(v) for k, v in (kv.split("=") for kv in knobs.split(",") if kv)}
                out.append(EpisodeTask(suite="drive-study", split=flaw, scenario=sc, preset="wigley-2m",
                                       controller=name, controller_kwargs=kwargs))
    return out


def main() -> None:
    """Run the study, print one JSON row per episode on stdout and a table on stderr."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=700000)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--flaws", nargs="*", default=[*FLAWS, *SUPPLIES])
    ap.add_argument("--controllers", nargs="*", default=list(CONTROLLERS))
    a = ap.parse_args()
    seeds = list(range(a.first_seed, a.first_seed + a.seeds))
    rows = run_tasks(tasks(seeds, a.flaws, a.controllers), jobs=a.jobs,
                     on_row=lambda r: print(json.dumps({k: r.get(k) for k in (
                         "controller", "controller_kwargs", "split", "seed", "rel_error", "rel_error_corrected", "failure",
                         "tracking_rms_rad", "saturated_frac", "wall_s")}), flush=True))
    oracle = {(r["split"], r["seed"]): r["rel_error"] for r in rows if r["controller"] == "oracle"}
    for flaw in a.flaws:
        for c in a.controllers:
            rs = [r for r in rows if r["split"] == flaw and r["controller"] == c]
            ok = [r for r in rs if r["rel_error"] is not None]
            err = sum(abs(r["rel_error"]) for r in ok) / max(1, len(ok))
            paired = [abs(r["rel_error"] - oracle[(flaw, r["seed"])]) for r in ok
                      if oracle.get((flaw, r["seed"])) is not None]
            pc = sum(paired) / max(1, len(paired))
            print(f"{flaw:28s} {c:15s} mean|e| {100 * err:7.3f} %  mean|c| {100 * pc:7.3f} %  "
                  f"failed {len(rs) - len(ok)}/{len(rs)}", file=sys.stderr)


if __name__ == "__main__":
    main()
