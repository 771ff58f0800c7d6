"""Leaderboard figures: |lambda66 error| against energy, and per-scenario errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .leaderboard import abs_errors


def _axes():
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


FLOOR = 1e-5  # |error| plotted at least this (log axis)


def plot_error_vs_energy(rows: list[dict], order: list[str], path: Path) -> Path:
    plt = _axes()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name in order:
        rs = [r for r in rows if r["controller"] == name and r.get("energy_J") is not None]
        err = np.clip(abs_errors(rs), FLOOR, None)
        ok = np.isfinite(err)
        ax.scatter(np.array([r["energy_J"] for r in rs])[ok], err[ok] * 100, s=14, label=name, alpha=0.7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("electric energy through the motor (hold + reverse), J")
    ax.set_ylabel("|lambda66 error|, %")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.legend(fontsize=8)
    ax.set_title("error against energy, one point per episode")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_per_scenario(rows: list[dict], order: list[str], path: Path) -> Path:
    plt = _axes()
    seeds = sorted({r["seed"] for r in rows})
    pos = {s: k for k, s in enumerate(seeds)}
    fig, ax = plt.subplots(figsize=(max(7, 0.22 * len(seeds)), 4.5))
    markers = "os^vD<>px*"
    for j, name in enumerate(order):
        rs = [r for r in rows if r["controller"] == name]
        err = abs_errors(rs)
        x = np.array([pos[r["seed"]] for r in rs]) + 0.08 * (j - len(order) / 2)
        y = np.where(np.isfinite(err), np.clip(err, FLOOR, None), math.nan) * 100
        ax.scatter(x, y, s=14, marker=markers[j % len(markers)], label=name)
        fails = ~np.isfinite(err)
        if fails.any():
            ax.scatter(x[fails], np.full(fails.sum(), 100.0), marker="x", color="r", s=20)
    ax.set_yscale("log")
    ax.set_xticks(range(len(seeds)))
    ax.set_xticklabels([str(s) for s in seeds], rotation=90, fontsize=6)
    ax.set_xlabel("scenario seed (failures drawn as red x at 100 %)")
    ax.set_ylabel("|lambda66 error|, %")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.legend(fontsize=7, ncol=3)
    ax.set_title("per-scenario error")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
