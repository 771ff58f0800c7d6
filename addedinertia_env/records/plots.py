"""Figures of a run: the free stroke, the hold, the reverse stroke, current and flywheel speed."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from addedinertia_env.foundation.atomic import save_figure
from addedinertia_env.records.record import RunRecord

PHASE_COLOURS = {"idle": "0.85", "free": "#cfe8ff", "hold": "#ffe7b3", "reverse": "#d6f5d6"}


def plot_run(record: RunRecord, path: str | os.PathLike, title: str = "") -> Path:
    """Three stacked panels over time with the phases shaded; written atomically as PNG."""
    return save_figure(run_figure(record, title), path, dpi=110)


def run_figure(record: RunRecord, title: str = ""):
    """The figure of :func:`plot_run` (a matplotlib Figure; the caller closes it)."""
    import matplotlib  # noqa: PLC0415 - plotting is optional at import time

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    t, phase = record.t, record.phase
    omega = np.gradient(record["psi"], t)
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    panels = [(record["phi"], "hull yaw phi [rad]"), (record["i"], "motor current i [A]"),
              (omega, "flywheel rate Omega [rad/s]")]
    for ax, (y, label) in zip(axes, panels):
        _shade(ax, t, phase)
        ax.plot(t, y, lw=0.8, color="k")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in PHASE_COLOURS.values()]
    axes[0].legend(handles, list(PHASE_COLOURS), loc="upper right", ncol=4, fontsize=8)
    axes[0].set_title(title or f"run {record.run_id}")
    fig.tight_layout()
    return fig


def _shade(ax, t: np.ndarray, phase: np.ndarray) -> None:
    change = np.nonzero(phase[1:] != phase[:-1])[0] + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(t) - 1]])
    for a, b in zip(starts, ends):
        ax.axvspan(t[a], t[b], color=PHASE_COLOURS.get(str(phase[a]), "white"), lw=0)
