"""Columns of a run record, appended one reading at a time: shared by every experiment kind."""

from __future__ import annotations

from typing import Any

import numpy as np

from addedinertia_env.records.record import FORMAT, RunRecord
from addedinertia_env.rig.interface import Rig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.sensors import Reading

LOG_COLUMNS = ("t", "phase", "phi", "psi", "u", "i", "i_cmd", "u_cmd", "brake")
PASSIVE = MotorCommand("passive", 0.0)


class SampleLog:
    """The samples of one experiment as lists, turned into a :class:`RunRecord` at the end."""

    def __init__(self) -> None:
        self.columns: dict[str, list] = {k: [] for k in LOG_COLUMNS}
        self.last: Reading | None = None

    def add(self, r: Reading, cmd: MotorCommand | None, phase: str) -> Reading:
        """Append reading ``r`` in ``phase`` with the command ``cmd`` in force (its current in A or
        voltage in V in ``i_cmd`` / ``u_cmd``, 0 otherwise); returns ``r``.
        """
        c = self.columns
        c["t"].append(r.t)
        c["phase"].append(phase)
        c["phi"].append(r.phi)
        c["psi"].append(r.psi)
        c["u"].append(r.u)
        c["i"].append(r.i)
        c["brake"].append(1.0 if r.brake else 0.0)
        c["i_cmd"].append(cmd.value if cmd is not None and cmd.mode == "current" else 0.0)
        c["u_cmd"].append(cmd.value if cmd is not None and cmd.mode == "voltage" else 0.0)
        self.last = r
        return r

    def tail(self, column: str, n: int) -> np.ndarray:
        """The last ``n`` values of ``column``."""
        return np.asarray(self.columns[column][-n:])

    def record(self, rig: Rig, experiment: dict[str, Any], run_id: str) -> RunRecord:
        """The record so far; a simulated rig adds its ``truth`` block (for scoring only)."""
        samples = {k: np.asarray(v, dtype=str if k == "phase" else float) for k, v in self.columns.items()}
        return make_record(samples, rig, experiment, run_id)


def make_record(samples: dict[str, np.ndarray], rig: Rig, experiment: dict[str, Any], run_id: str) -> RunRecord:
    """A :class:`RunRecord` of ``samples`` (the :data:`LOG_COLUMNS`) taken on ``rig`` (a :class:`Rig`: its
    ``source``, ``known`` and ``truth()``): the one place where a record's metadata is assembled."""
    meta: dict[str, Any] = {"format": FORMAT, "run_id": run_id, "source": getattr(rig, "source", "sim"),
                            "rig": rig.known.to_block(), "experiment": experiment}
    truth = getattr(rig, "truth", None)
    value = truth() if callable(truth) else None  # computed once
    if value is not None:
        meta["truth"] = value
    return RunRecord(samples=samples, meta=meta)
