"""One deploy on the bench emulator against the same controller's simulated spread (issue 28, drive-v3).

Starts ``addedinertia bench-server`` in its own process (``--fast``: lock-step; ``--realtime``: free-running,
with ``--latency-ms`` of link delay on every frame the board sends), deploys the controller with the round
trip stated as the deploy's own pings measure it (``--link-round-trip-ms ping``), then runs the same
controller in simulation over ``--seeds`` sensor seeds (the two-rate board where ``--host-rate-hz`` is given)
behind a loop that states the same round trip and delays the readings by ``--latency-ms`` (0 in lock-step:
the board waits for the host). Prints one JSON line: the deploy's status, samples lost, lambda66 and its
interval, the stated round trip, the simulated lambda66s and the band (min/max widened by 0.5 % of the
truth, the slow test's rule; the truth is read for scoring only).

    PYTHONPATH=$PWD python scripts/deploy_vs_sim.py --rig wigley-2m-drive-v3 --controller smith-pd
    PYTHONPATH=$PWD python scripts/deploy_vs_sim.py --rig wigley-2m-drive-v3 --policy agents/policies/drive_v3_ars.onnx --host-rate-hz 100 --realtime --latency-ms 5
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.identify import identify
from addedinertia_env.loop.control_loop import ControlLoop, LoopRig
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from agents import make_controller
from hw_adapter.deploy import DeployOptions, deploy
from hw_adapter.lab import load_lab
from hw_adapter.loopback import spawn_bench_server


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rig", default="wigley-2m-drive-v3")
    who = ap.add_mutually_exclusive_group(required=True)
    who.add_argument("--controller")
    who.add_argument("--policy")
    ap.add_argument("--host-rate-hz", type=float, default=None)
    ap.add_argument("--realtime", action="store_true", help="free-running board (default: lock-step)")
    ap.add_argument("--latency-ms", type=float, default=0.0, help="the emulator's link latency, ms (--faults latency=MS)")
    ap.add_argument("--watchdog-ms", type=float, default=None,
                    help="the host's link watchdog, ms (default: deploy's, 20 ms free-running; 1000 in lock-step)")
    ap.add_argument("--seeds", type=int, default=4)
    args = ap.parse_args()
    name = args.controller or f"onnx:{args.policy}"
    params = rig_from_mapping(load_preset(args.rig))
    truth = params.hull.lambda66  # scoring only
    lab = load_lab(args.rig)
    server_args = ["--rig", args.rig, "--once", "--realtime" if args.realtime else "--fast"]
    if args.latency_ms:
        server_args += ["--faults", f"latency={args.latency_ms:g}"]
    proc, url = spawn_bench_server(*server_args)
    t0 = time.perf_counter()
    try:
        with tempfile.TemporaryDirectory() as out:
            opts = DeployOptions(bench=url, controller=name, lab=lab, out=Path(out), host_rate_hz=args.host_rate_hz,
                                 watchdog_s=1e-3 * args.watchdog_ms if args.watchdog_ms else None if args.realtime else 1.0, link_round_trip_s="ping")
            summary, status = deploy(opts, make_controller(name))
    finally:
        proc.wait(timeout=30)
    deploy_s = time.perf_counter() - t0
    stated = summary.get("link_round_trip_s")
    delay = 1e-3 * args.latency_ms if args.realtime else 0.0
    sims = []
    for seed in range(args.seeds):
        rig = LoopRig(MujocoRig(params, seed=seed), ControlLoop(obs_delay_s=delay, stated_round_trip_s=stated))
        rec = run_experiment(rig, make_controller(name), lab.plan(), policy_rate_hz=args.host_rate_hz)
        sims.append(identify([rec], "energy").lambda66)
    lo, hi = min(sims) - 0.005 * truth, max(sims) + 0.005 * truth
    lam = summary.get("lambda66")
    print(json.dumps({
        "rig": args.rig, "controller": name, "host_rate_hz": args.host_rate_hz,
        "board": "realtime" if args.realtime else "lockstep", "latency_ms": args.latency_ms,
        "watchdog_ms": summary.get("watchdog_ms"),
        "status": summary["status"], "exit": status, "stated_round_trip_ms": None if stated is None else 1e3 * stated,
        "samples": summary.get("loop_samples"), "skipped_samples": summary.get("skipped_samples"),
        "samples_lost": summary.get("samples_lost"), "late_segments": summary.get("late_segments"),
        "overruns": summary.get("overruns"), "lambda66": lam, "ci95": summary.get("ci95"), "truth": truth,
        "error_pct": None if lam is None else 100 * (lam / truth - 1), "sims": sims, "band": [lo, hi],
        "inside_band": lam is not None and lo <= lam <= hi, "deploy_wall_s": round(deploy_s, 1)}))


if __name__ == "__main__":
    main()
