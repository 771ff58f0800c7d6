"""A run record written as the experiment goes, so a fault or a crash never loses it.

The JSON (``addedinertia-run/1``, ``docs/RUN_RECORD.md``) is written at the
start with ``experiment.status = "running"`` and rewritten at the end with
``"complete"`` or ``"aborted: <reason>"`` (atomically, via ``record.write``'s helper).
CSV rows are appended as samples arrive and flushed at least every ``flush_s``. A
record cut short is still readable by :func:`addedinertia_env.records.record.read_record`; its
status says it is partial. A process killed outright leaves ``"running"``: partial too.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any, Callable

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.foundation.jsonable import plain
from addedinertia_env.records.record import FORMAT
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.sensors import Reading

COLUMNS = ("t", "phase", "phi", "psi", "u", "i", "i_cmd", "u_cmd", "brake")


class IncrementalRecord:
    """``DIR/RUN_ID.csv`` + ``.json``; rows appended by :meth:`append`, JSON by :meth:`start` / :meth:`finish`."""

    def __init__(self, out_dir: str | Path, run_id: str, phase: Callable[[], str] = lambda: "idle",
                 flush_s: float = 0.05):
        self.csv_path = Path(out_dir) / f"{run_id}.csv"
        self.json_path = self.csv_path.with_suffix(".json")
        self.run_id = run_id
        self.phase = phase
        self.flush_s = flush_s
        self.rows = 0
        self.last_t = -math.inf
        self.out_of_order = 0  # samples not written because their time did not advance
        self._file = None
        self._last_flush = 0.0

    def start(self, meta: dict[str, Any]) -> None:
        """Write the JSON metadata (status ``running``) and the CSV header; rows follow with :meth:`append`."""
        self.csv_path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"format": FORMAT, "run_id": self.run_id, **meta}
        meta.setdefault("experiment", {})["status"] = "running"
        atomic_write_text(self.json_path, json.dumps(plain(meta), indent=2, allow_nan=False) + "\n")
        self._file = open(self.csv_path, "w", newline="")  # noqa: SIM115 - kept open for the run
        self._file.write(",".join(COLUMNS) + "\n")
        self._file.flush()

    def append(self, r: Reading, cmd: MotorCommand | None) -> None:
        """Append reading ``r`` with the command in force (its current in A or voltage in V); rows
        out of time order are counted and dropped from the file, and the file is flushed every ``flush_s`` s.
        """
        if self._file is None:
            return
        if not r.t > self.last_t:
            self.out_of_order += 1
            return
        self.last_t = r.t
        i_cmd = cmd.value if cmd is not None and cmd.mode == "current" else 0.0
        u_cmd = cmd.value if cmd is not None and cmd.mode == "voltage" else 0.0
        self._file.write(f"{r.t!r},{self.phase()},{r.phi!r},{r.psi!r},{r.u!r},{r.i!r},{float(i_cmd)!r},"
                         f"{float(u_cmd)!r},{1 if r.brake else 0}\n")
        self.rows += 1
        now = time.perf_counter()
        if now - self._last_flush >= self.flush_s:
            self._file.flush()
            self._last_flush = now

    def finish(self, meta: dict[str, Any], status: str) -> Path:
        """Close the CSV and write the final JSON with ``experiment.status = status``."""
        if self._file is not None:
            self._file.flush()
            self._file.close()
            self._file = None
        meta = {"format": FORMAT, "run_id": self.run_id, **meta}
        meta.setdefault("experiment", {})["status"] = status
        atomic_write_text(self.json_path, json.dumps(plain(meta), indent=2, allow_nan=False) + "\n")
        return self.csv_path
