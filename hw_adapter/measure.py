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

Two-rate mode (``--host-rate-hz 100``, protocol version 2): the same runs with the board
running the inner loop and the host sending segments; rows add the host period, deadline
misses, late segments, samples lost from the record and lambda66 against the emulator's
truth (the preset's, for scoring only), and a ``stall`` run: the host stops sending
segments 0.1 s into the hold (its controller blocks for 0.5 s); the time from the stall's
start (host) to the board's own SEGMENTS fault (emulator), both on the system's
monotonic clock. ``--load N`` keeps N busy processes running during every run (the
"loaded" rows); ``--policy FILE`` runs an exported policy (``onnx:FILE``) instead of
``--controller``; ``--repeat K`` repeats the nominal run; ``--rt-priority P`` runs the host
at SCHED_FIFO priority P and the emulator (the board) at P + 5, as a bench PC would.
"""

from __future__ import annotations

from addedinertia_env.foundation.machine import cpu_model

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from agents import make_controller

from hw_adapter.deploy import DeployOptions, deploy
from hw_adapter.lab import load_lab
from hw_adapter.loopback import spawn_bench_server

FAULTS = {"drop": "drop=1.0@{at}", "corrupt": "corrupt=1.0@{at}", "latency": "latency=300@{at}",
          "disconnect": "disconnect@{at}", "glitch": "glitch=0.2@{at}", "stuck_brake": "stuck_brake@{at}"}



class StallingController:
    """Wraps a controller; its first decision ``after_s`` into the hold blocks for ``stall_s``
    (a host that stops sending segments). ``stalled_at``: monotonic time the stall began."""

    def __init__(self, inner, after_s: float = 0.1, stall_s: float = 0.5):
        self.inner, self.after_s, self.stall_s = inner, after_s, stall_s
        self.name = getattr(inner, "name", "controller")
        self.stalled_at: float | None = None
        self._t0: float | None = None

    def reset(self, context) -> None:
        """Reset the wrapped controller and start the clock of the stall."""
        self.inner.reset(context)
        self._t0 = time.monotonic()

    def predict(self, obs, *args, **kwargs):
        """The wrapped controller's action, after sleeping ``stall_s`` s once, ``after_s`` s into the run (a controller that hangs)."""
        if self.stalled_at is None and time.monotonic() - self._t0 >= self.after_s:
            self.stalled_at = time.monotonic()
            time.sleep(self.stall_s)
        return self.inner.predict(obs, *args, **kwargs)


def one_run(name: str, faults: str, args, work: Path) -> dict:
    """One deploy against a freshly spawned bench server with the fault spec ``faults`` (``stall``:
    a hanging controller instead); returns its row for docs/BENCH.md: status, loop timing (ms),
    samples lost, and the fault-to-safe time (ms) from the server's event log.
    """
    events = work / f"{name}.events.jsonl"
    extra = ["--faults", faults] if faults and faults != "stall" else []
    proc, url = spawn_bench_server("--fast" if args.fast else "--realtime", "--rig", args.rig,
                                   "--board-watchdog-ms", str(args.board_watchdog_ms), *extra, events=events)
    if args.rt_priority:  # the board outranks the host, as separate hardware would
        os.sched_setscheduler(proc.pid, os.SCHED_FIFO, os.sched_param(args.rt_priority + 5))
    controller = make_controller(args.controller)
    if faults == "stall":
        controller = StallingController(controller)
    loadavg0 = os.getloadavg()[0]
    try:
        opts = DeployOptions(bench=url, controller=args.controller, lab=load_lab(args.rig), out=work / name,
                             hold_s=args.hold, watchdog_s=None if args.watchdog_ms is None else args.watchdog_ms * 1e-3,
                             host_rate_hz=args.host_rate_hz)
        summary, status = deploy(opts, controller)
    finally:
        proc.terminate()  # the server writes its event log as it stops
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
    log = [json.loads(line) for line in events.read_text().splitlines()] if events.exists() else []
    onset = next((e for e in log if e["event"] == "fault_onset"), None)
    safe = next((e for e in log if e["event"] == "safe"), None)
    if faults == "stall":
        onset = {"wall": controller.stalled_at} if controller.stalled_at is not None else None
        safe = next((e for e in log if e["event"] == "board_fault"), None)
    row = {"run": name, "faults": faults, "exit_status": status, "status": summary["status"],
           "safe_stop": summary["safe_stop"], "trip": (summary.get("trip") or {}).get("kind"),
           "lambda66": summary.get("lambda66"), "overruns": summary.get("overruns"),
           "skipped_samples": summary.get("skipped_samples"), "loop_period_p50_ms": summary.get("loop_period_p50_ms"),
           "loop_jitter_p50_ms": summary.get("loop_jitter_p50_ms"),
           "loop_jitter_p99_ms": summary.get("loop_jitter_p99_ms"),
           "max_abs_current_sent_A": summary.get("max_abs_current_sent_A"),
           "lambda66_true": rig_from_mapping(load_preset(args.rig)).hull.lambda66,  # scoring only
           "loadavg_1min": [loadavg0, os.getloadavg()[0]], "controller": args.controller}
    for key in ("host_rate_hz", "board_mode", "deadline_misses", "late_segments", "samples_lost",
                "host_period_p50_ms", "host_period_p99_ms", "board_hold_samples", "segments_sent",
                "identify_error", "watchdog_ms"):
        if key in summary:
            row[key] = summary[key]
    if onset and safe:
        row["fault_to_safe_ms"] = 1e3 * (safe["wall"] - onset["wall"])
    return row


def simulated_reference(args) -> dict:
    """lambda66 of the same scenario in the simulator (same rig, plan, noise seed 0 as the
    emulator): the controller at every sample, and at the host rate through the same board
    loop, without and with a 5-sample link latency (about what the emulator's batches and
    the loopback add)."""
    from addedinertia_env.experiment.protocol import Experiment  # noqa: PLC0415
    from addedinertia_env.experiment.runner import run_experiment  # noqa: PLC0415
    from addedinertia_env.experiment.two_rate import drive_two_rate  # noqa: PLC0415
    from addedinertia_env.identify import IdentificationError, identify  # noqa: PLC0415
    from addedinertia_env.loop.board_loop import TwoRateSimRig  # noqa: PLC0415
    from addedinertia_env.sim.mujoco_rig import MujocoRig  # noqa: PLC0415

    params = rig_from_mapping(load_preset(args.rig))
    plan = load_lab(args.rig).plan(hold_s=args.hold)

    def estimate(rec) -> float | None:
        try:
            return identify([rec], "energy").lambda66
        except IdentificationError:
            return None

    out = {"every_sample": estimate(run_experiment(MujocoRig(params, seed=0), make_controller(args.controller), plan))}
    for latency in (0, 5):
        rig = TwoRateSimRig(MujocoRig(params, seed=0), args.host_rate_hz, latency_samples=latency)
        exp = Experiment(rig, plan)
        exp.start()
        drive_two_rate(exp, make_controller(args.controller), args.host_rate_hz)
        out[f"two_rate_latency_{latency}"] = estimate(exp.record("sim"))
    return out


def main(argv: list[str] | None = None) -> int:
    """Measure the docs/BENCH.md figures (nominal runs, then each fault) and write them as JSON to ``--out``; returns 0."""
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
    p.add_argument("--controller", default="feedforward-pd")
    p.add_argument("--policy", default=None, metavar="ONNX",
                   help="an exported policy instead of --controller (same as --controller onnx:ONNX)")
    p.add_argument("--host-rate-hz", type=float, default=None, help="two-rate mode at this host rate")
    p.add_argument("--repeat", type=int, default=1, help="nominal runs")
    p.add_argument("--load", type=int, default=0, help="busy processes kept running during the runs")
    p.add_argument("--rt-priority", type=int, default=0,
                   help="run the host at SCHED_FIFO this priority and the emulator 5 above (root; 0: normal)")
    args = p.parse_args(argv)
    if args.policy is not None:
        args.controller = f"onnx:{args.policy}"
    if args.rt_priority:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt_priority))
    runs = {f"nominal{k + 1 if args.repeat > 1 else ''}": "" for k in range(args.repeat)}
    runs.update({k: v.format(at=args.at) for k, v in FAULTS.items()})
    if args.host_rate_hz is not None:
        runs["stall"] = "stall"
    if args.only:
        runs = {k: v for k, v in runs.items() if k.rstrip("0123456789") in args.only or k in args.only}
    rows = []
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"],  # ordinary priority
                                preexec_fn=lambda: os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0)))
               for _ in range(args.load)]
    try:
        with tempfile.TemporaryDirectory(prefix="bench-figures-") as tmp:
            for name, faults in runs.items():
                t0 = time.perf_counter()
                rows.append(one_run(name, faults, args, Path(tmp)))
                rows[-1]["wall_s"] = time.perf_counter() - t0
                print(json.dumps(rows[-1]), flush=True)
    finally:
        for b in burners:
            b.terminate()
            b.wait()
    result = {"machine": {"nproc": os.cpu_count(), "cpu": cpu_model(), "loadavg": os.getloadavg()},
              "settings": vars(args), "runs": rows}
    if args.host_rate_hz is not None:
        result["simulated_lambda66"] = simulated_reference(args)
        print(json.dumps(result["simulated_lambda66"]), flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
