"""Figures of docs/BENCH.md: fault-to-safe-state time and control-loop jitter.

    .venv/bin/python -m hw_adapter.measure --out out/bench-figures.json

For each run an emulator is started as its own process (``addedinertia bench-server
--realtime``: free-running at the sample rate on the wall clock), and one experiment is
deployed on it in this process with ``feedforward-pd``:

* ``nominal``: no fault; gives the loop period and jitter (p50, p99) and overruns
  (``--fast``: the same against the lock-step emulator: throughput, not real time);
* one run per fault, injected ``--at`` seconds after RESET: the time from the fault's
  onset (first affected frame or sample, logged by the emulator) to the board's safe
  state (disarmed, drive passive, brake requested), both on the emulator's monotonic
  clock, so the two processes' clocks never mix.
"""

from __future__ import annotations

from addedinertia_env.machine import cpu_model

import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

from agents import make_controller

from .deploy import DeployOptions, deploy
from .lab import load_lab
from .loopback import spawn_bench_server

FAULTS = {"drop": "drop=1.0@{at}", "corrupt": "corrupt=1.0@{at}", "latency": "latency=300@{at}",
          "disconnect": "disconnect@{at}", "glitch": "glitch=0.2@{at}", "stuck_brake": "stuck_brake@{at}"}



def one_run(name: str, faults: str, args, work: Path) -> dict:
    events = work / f"{name}.events.jsonl"
    extra = ["--faults", faults] if faults else []
    proc, url = spawn_bench_server("--fast" if args.fast else "--realtime", "--rig", args.rig,
                                   "--board-watchdog-ms", str(args.board_watchdog_ms), *extra, events=events)
    try:
        opts = DeployOptions(bench=url, controller="feedforward-pd", lab=load_lab(args.rig), out=work / name,
                             hold_s=args.hold, watchdog_s=None if args.watchdog_ms is None else args.watchdog_ms * 1e-3)
        summary, status = deploy(opts, make_controller("feedforward-pd"))
    finally:
        proc.terminate()  # the server writes its event log as it stops
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
    log = [json.loads(line) for line in events.read_text().splitlines()] if events.exists() else []
    onset = next((e for e in log if e["event"] == "fault_onset"), None)
    safe = next((e for e in log if e["event"] == "safe"), None)
    row = {"run": name, "faults": faults, "exit_status": status, "status": summary["status"],
           "safe_stop": summary["safe_stop"], "trip": (summary.get("trip") or {}).get("kind"),
           "lambda66": summary.get("lambda66"), "overruns": summary.get("overruns"),
           "skipped_samples": summary.get("skipped_samples"), "loop_period_p50_ms": summary.get("loop_period_p50_ms"),
           "loop_jitter_p50_ms": summary.get("loop_jitter_p50_ms"),
           "loop_jitter_p99_ms": summary.get("loop_jitter_p99_ms"),
           "max_abs_current_sent_A": summary.get("max_abs_current_sent_A")}
    if onset and safe:
        row["fault_to_safe_ms"] = 1e3 * (safe["wall"] - onset["wall"])
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rig", default="wigley-2m")
    p.add_argument("--hold", type=float, default=0.3, help="brake hold, s")
    p.add_argument("--at", type=float, default=1.0, help="fault onset after RESET, s (in the free stroke)")
    p.add_argument("--watchdog-ms", type=float, default=None,
                   help="host watchdog (link silence), ms (default: deploy's, 20 ms free-running, 1 s lock-step)")
    p.add_argument("--fast", action="store_true", help="lock-step emulator instead of the free-running one")
    p.add_argument("--board-watchdog-ms", type=int, default=50)
    p.add_argument("--only", nargs="*", default=None, help="runs to do (nominal and fault names)")
    p.add_argument("--out", default="out/bench-figures.json")
    args = p.parse_args(argv)
    runs = {"nominal": "", **{k: v.format(at=args.at) for k, v in FAULTS.items()}}
    if args.only:
        runs = {k: v for k, v in runs.items() if k in args.only}
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-figures-") as tmp:
        for name, faults in runs.items():
            t0 = time.perf_counter()
            rows.append(one_run(name, faults, args, Path(tmp)))
            rows[-1]["wall_s"] = time.perf_counter() - t0
            print(json.dumps(rows[-1]), flush=True)
    result = {"machine": {"nproc": os.cpu_count(), "cpu": cpu_model(), "loadavg": os.getloadavg()},
              "settings": vars(args), "runs": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
