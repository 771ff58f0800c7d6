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
    """Median score (with its 95 % interval) against median energy, one point per entry;
    the Pareto front of the ranked entries drawn as a line; references hollow."""
    plt = _axes()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ranked = [e for e in entries if e.get("rank") is not None]
    pts = [(e["median_energy_J"], e["score"]) for e in ranked]
    front = pareto_front(pts)
    if len(front) > 1:
        ax.plot([pts[k][0] for k in front], [max(pts[k][1], FLOOR) * 100 for k in front], "k--", lw=0.8,
                label="Pareto front (entries)")
    for e in entries:
        x, y = e["median_energy_J"], e["score"]
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ci = e.get("ci95_control_error") or e.get("ci95_median")
        y_plot = max(y, FLOOR)
        ref = e.get("rank") is None
        err = None
        if ci and all(math.isfinite(v) for v in ci) and not ref:
            err = [[max(y_plot - max(ci[0], FLOOR), 0) * 100], [max(ci[1] - y_plot, 0) * 100]]
        ax.errorbar([max(x, 1e-3)], [y_plot * 100], yerr=err, fmt="s" if ref else "o", ms=7,
                    mfc="none" if ref else None, capsize=3)
        ax.annotate(e["controller"] + (" (reference)" if ref else ""), (max(x, 1e-3), y_plot * 100),
                    textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("median electric energy integral |u i| dt over hold + reverse stroke, J")
    ax.set_ylabel(score_label + ", %")
    ax.set_title("accuracy against energy (lower left is better)")
    if len(front) > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
