"""Figures of a hull study: A66(omega), B66(omega) at two resolutions, and K(t)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from addedinertia_env.foundation.atomic import save_figure
from addedinertia_env.hydro.retardation import retardation_function


def plot_study(data: dict, path: str | os.PathLike, swing_omega: float | None = None, caption: str = "") -> Path:
    """Three panels (A66, B66 against omega; K against t), written atomically as PNG."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    w_swing = swing_omega if swing_omega is not None else data.get("swing_omega")
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    fine = data["resolutions"]["fine"]
    for label, style in (("coarse", "--"), ("fine", "-")):
        r = data["resolutions"][label]
        if not r["omega"]:
            continue
        n = r["mesh"]["panels"]
        axes[0].plot(r["omega"], r["A66"], style, label=f"{label}: {n} panels")
        axes[1].plot(r["omega"], r["B66"], style, label=f"{label}: {n} panels")
    zf, inf = fine["zero_frequency"]["A66"], (fine.get("infinite_frequency") or {}).get("A66")
    axes[0].axhline(zf, color="k", lw=0.8, ls=":", label=f"A66(0) = {zf:.3g} (rigid lid)")
    if inf is not None:
        axes[0].axhline(inf, color="0.5", lw=0.8, ls=":", label=f"A66(inf) = {inf:.3g}")
    for ax in axes[:2]:
        if w_swing:
            ax.axvline(w_swing, color="tab:green", lw=0.8, label=f"swing {w_swing:.3g} rad/s")
        if fine.get("irregular_frequency"):
            ax.axvline(fine["irregular_frequency"], color="tab:red", lw=0.8, ls="-.",
                       label=f"1st irregular freq. {fine['irregular_frequency']:.3g} (lid added)")
        ax.set_xlabel("omega [rad/s]")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("A66 [kg m^2]")
    axes[1].set_ylabel("B66 [N m s]")
    if len(fine["omega"]) >= 3:
        t = np.linspace(0.0, 4.0, 801)
        K = retardation_function(fine["omega"], fine["B66"], t)["K"]
        axes[2].plot(t, K)
    axes[2].set_xlabel("t [s]")
    axes[2].set_ylabel("K(t) [N m] (Cummins, yaw)")
    axes[2].axhline(0.0, color="k", lw=0.5)
    if caption:
        fig.text(0.01, 0.005, caption, fontsize=7, color="0.3")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return save_figure(fig, path, dpi=100)
