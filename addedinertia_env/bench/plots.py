"""Leaderboard figures: |lambda66 error| against energy, and per-scenario errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from addedinertia_env.foundation.atomic import save_figure
from addedinertia_env.bench.leaderboard import abs_errors


def _axes():
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


FLOOR = 1e-5  # |error| plotted at least this (log axis)


def plot_error_vs_energy(rows: list[dict], order: list[str], path: Path) -> Path:
    """Scatter |lambda66 error| (%) against the motor energy (J), one point per episode, a colour per controller in ``order``; writes the PNG ``path`` and returns it."""
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
    return save_figure(fig, path, dpi=110)


def plot_per_scenario(rows: list[dict], order: list[str], path: Path) -> Path:
    """Plot |lambda66 error| (%) per scenario seed for each controller in ``order`` (failures as red x at 100 %); writes the PNG ``path`` and returns it."""
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
    return save_figure(fig, path, dpi=110)


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the non-dominated points ``(energy, error)`` (no other point is at least as
    good in both and better in one), sorted by energy."""
    keep = []
    for k, (x, y) in enumerate(points):
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        dominated = any((x2 <= x and y2 <= y) and (x2 < x or y2 < y)
                        for j, (x2, y2) in enumerate(points) if j != k and math.isfinite(x2) and math.isfinite(y2))
        if not dominated:
            keep.append(k)
    return sorted(keep, key=lambda k: points[k][0])


def plot_pareto(entries: list[dict], path: Path, score_label: str) -> Path:
    """Left: every row, references included (log-log). Right: the ranked entries alone, median
    score with its 95 % interval against median energy, the Pareto front of the entries
    dashed (lower left is better)."""
    plt = _axes()
    fig, (ax_all, ax) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1, 1.6]})
    finite = [e for e in entries if math.isfinite(e["median_energy_J"]) and math.isfinite(e["score"])]
    for e in finite:
        ref = e.get("rank") is None
        x, y = max(e["median_energy_J"], 1e-3), max(e["score"], FLOOR) * 100
        ax_all.plot([x], [y], "s" if ref else "o", mfc="none" if ref else None, ms=7)
        if ref:
            ax_all.annotate(e["controller"], (x, y), textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax_all.set_xscale("log")
    ax_all.set_yscale("log")
    ax_all.set_xlabel("median energy, J (log; 0 J drawn at 1e-3)")
    ax_all.set_ylabel(score_label + ", % (log; 0 drawn at 0.001 %)")
    ax_all.set_title("all rows (squares: references)", fontsize=10)
    ranked = [e for e in finite if e.get("rank") is not None]
    pts = [(e["median_energy_J"], e["score"]) for e in ranked]
    front = pareto_front(pts)
    if len(front) > 1:
        ax.plot([pts[k][0] for k in front], [100 * pts[k][1] for k in front], "k--", lw=0.8, label="Pareto front")
        ax.legend(fontsize=8)
    for e in ranked:
        x, y = e["median_energy_J"], e["score"]
        ci = e.get("ci95_control_error") or e.get("ci95_median")
        err = None
        if ci and all(math.isfinite(v) for v in ci):
            err = [[100 * max(y - ci[0], 0)], [100 * max(ci[1] - y, 0)]]
        ax.errorbar([x], [100 * y], yerr=err, fmt="o", ms=6, capsize=3)
        ax.annotate(e["controller"].replace("onnx:", "").split("/")[-1], (x, 100 * y), textcoords="offset points",
                    xytext=(5, 3), fontsize=8)
    ax.set_xlabel("median electric energy integral |u i| dt, hold + reverse stroke, J")
    ax.set_ylabel(score_label + ", %")
    ax.set_title("entries: median and paired 95 % interval", fontsize=10)
    fig.suptitle("accuracy against energy (lower left is better)")
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
