"""Start the bench emulator on loopback: in a thread (tests, inspection of the board) or
as its own ``addedinertia bench-server`` process (what a lab would run)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from addedinertia_env.sim.presets import load_preset, rig_from_mapping

from hw_adapter.board import Board, BoardLimits
from hw_adapter.emulator import EmulatorServer
from hw_adapter.faults import parse_faults


def start_emulator(rig: str = "wigley-2m", faults: str = "", fast: bool = True, seed: int = 0,
                   board_watchdog_ms: int = 50) -> EmulatorServer:
    """An emulator serving in a daemon thread on 127.0.0.1 (free port); ``.board`` is inspectable."""
    params = rig_from_mapping(load_preset(rig))
    board = Board(params, seed=seed, faults=parse_faults(faults), lockstep=fast,
                  limits=BoardLimits(watchdog_ms=board_watchdog_ms))
    return EmulatorServer(board).start()


def spawn_bench_server(*args: str, startup_s: float = 60.0,
                       events: str | Path | None = None) -> tuple[subprocess.Popen, str]:
    """``addedinertia bench-server --port 0 ARGS`` in its own process; returns it and its URL."""
    cmd = [sys.executable, "-c", "import sys; from addedinertia_env.cli import main; sys.exit(main())",
           "bench-server", "--port", "0", *args]
    if events is not None:
        cmd += ["--events", str(events)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    deadline = time.monotonic() + startup_s
    line = proc.stdout.readline()  # the server prints its URL once listening
    if not line or time.monotonic() > deadline:
        proc.kill()
        raise RuntimeError(f"bench-server did not start (exit status {proc.poll()})")
    return proc, json.loads(line)["url"]
