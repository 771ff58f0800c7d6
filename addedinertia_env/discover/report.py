"""The readable discovery report: Markdown with figures (residuals by stroke, by amplitude and hold, ACF)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from addedinertia_env.foundation.atomic import atomic_write_text, save_figure
from addedinertia_env.foundation.jsonable import plain
from addedinertia_env.discover import residuals as resid
from addedinertia_env.discover.diagnose import Diagnosis
from addedinertia_env.discover.fit import Fit


def _segment_times(fit: Fit):
    for seg, (run, kind, sl) in zip(fit.model.segments, fit.model.hull_index()):
        rd = fit.model.data.runs[run]
        t = seg.t_steps[1:] - seg.t_start
        yield rd, kind, t, fit.hull_residuals[sl]


def plot_residuals(diag: Diagnosis, folder: Path) -> list[Path]:
    """Write the residual figures (by stroke, by amplitude and hold, autocorrelation) into ``folder``; returns their paths."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    folder.mkdir(parents=True, exist_ok=True)
    out = []

    def saved(fig, name: str) -> None:
        fig.tight_layout()
        save_figure(fig, folder / name, dpi=110)
        out.append(folder / name)

    fits = [("nominal", diag.nominal)] + ([("+".join(diag.causes), diag.extended)] if diag.causes else [])
    # 1. residuals against time, by stroke, each run a line
    fig, axes = plt.subplots(len(fits), 2, figsize=(11, 3.2 * len(fits)), squeeze=False, sharey="row")
    for row, (label, fit) in enumerate(fits):
        for rd, kind, t, r in _segment_times(fit):
            ax = axes[row, 0 if kind == "free" else 1]
            ax.plot(t, r * 1e6, lw=0.9, label=f"alpha {rd.alpha:.3f} rad, hold {rd.hold_s:.1f} s")
        for col, kind in enumerate(("free", "reverse")):
            ax = axes[row, col]
            ax.axhspan(-diag.data.phi_noise * 1e6, diag.data.phi_noise * 1e6, color="0.85", label="noise floor")
            ax.set_title(f"{label} model, {kind} stroke")
            ax.set_xlabel("time from stroke start [s]")
            ax.set_ylabel("hull angle residual [urad]")
        axes[row, 1].legend(fontsize=7)
    saved(fig, "residuals_time.png")
    # 2. residual RMS by run: amplitude and hold
    fig, ax = plt.subplots(figsize=(7, 3.5))
    width = 0.8 / len(fits)
    for k, (label, fit) in enumerate(fits):
        by_run = resid.structure(fit)["by_run"]
        x = np.arange(len(by_run))
        ax.bar(x + k * width, [r["rms"] * 1e6 for r in by_run], width, label=label)
        ax.set_xticks(x + 0.5 * width * (len(fits) - 1),
                      [f"a={r['alpha']:.3f}\nhold {r['hold_s']:.1f}s" for r in by_run], fontsize=8)
    ax.axhline(diag.data.phi_noise * 1e6, color="k", ls="--", lw=0.8, label="noise floor")
    ax.set_ylabel("hull residual RMS [urad]")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    saved(fig, "residuals_by_run.png")
    # 3. autocorrelation
    fig, ax = plt.subplots(figsize=(7, 3.2))
    n = len(diag.nominal.hull_residuals)
    for label, fit in fits:
        acf = resid.autocorrelation(fit)
        ax.plot(np.arange(len(acf)) * diag.data.step_samples * diag.data.dt, acf, marker="o", ms=3, label=label)
    ax.axhspan(-1.96 / np.sqrt(n), 1.96 / np.sqrt(n), color="0.85", label="white noise 95 %")
    ax.set_xlabel("lag [s]")
    ax.set_ylabel("autocorrelation")
    ax.legend(fontsize=8)
    saved(fig, "residuals_acf.png")
    return out


def markdown(diag: Diagnosis, figures: list[Path]) -> str:
    """The readable report (Markdown) of ``diag`` with links to its ``figures``."""
    j = diag.to_json()
    g = j["gain"]
    sn, sx = j["residuals_nominal"], j["residuals_extended"]
    lines = [f"# Discovery report: cause `{diag.cause}`" + (f" (causes: {', '.join(diag.causes)})"
                                                            if len(diag.causes) > 1 else ""), "",
             f"Runs: {', '.join(r.name for r in diag.data.runs)}.", "",
             "## Runs", "", "| run | alpha (rad) | hold (s) | current offset removed (A) | current noise (A) |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['run']} | {r['alpha']:.4f} | {r['hold_s']:.2f} | {r['current_offset']:+.4f} | "
              f"{r['current_noise']:.4f} |" for r in j["runs"]]
    lines += ["", "## Nominal model: what it gets wrong", "",
              f"- hull residual RMS {sn['hull_rms'] * 1e6:.2f} urad = {sn['hull_excess']:.2f} x the encoder noise "
              f"floor ({sn['hull_noise_floor'] * 1e6:.2f} urad); flywheel channel {sn['flywheel_excess']:.2f} x its floor",
              f"- whiteness: lag-1 autocorrelation {sn['lag1']:.2f}, Ljung-Box Q = {sn['ljung_box_q']:.0f} "
              f"(p = {sn['ljung_box_p']:.2g}) over {20} lags",
              f"- by stroke: free {sn['by_phase']['free'] * 1e6:.2f} urad, reverse {sn['by_phase']['reverse'] * 1e6:.2f} urad",
              f"- against amplitude: RMS ratio largest/smallest twist {sn['amplitude_trend']:.2f}; against hold time: "
              f"longest/shortest {sn['hold_trend']:.2f}",
              f"- against motor current (reverse strokes): correlation {sn['corr_current']:+.2f}", "",
              "## Candidates, round by round", "",
              "Each round adds to the model so far the effect that most improves the prediction of held-out runs "
              "(docs/DISCOVERY.md).", "",
              "| round | model so far + cause | predicted drop | fitted size | z | held-out gain | hull RMS (urad) "
              "| lambda66 | verdict |",
              "|---|---|---|---|---|---|---|---|---|"]
    for rnd in j["rounds"]:
        for c in rnd:
            size = ", ".join(f"{k} = {v:.4g}" for k, v in c["params"].items()) or "-"
            ho = "-" if c["heldout_gain"] is None else f"{c['heldout_gain']:.1%}"
            lines.append(f"| {c['round']} | {c['against']} + `{c['cause']}` | {c['predicted_drop']:.3g} | {size} | "
                         f"{_fmt(c['z'], '.1f')} | {ho} | {_fmt(c['residual_rms'] and c['residual_rms'] * 1e6, '.2f')} | "
                         f"{_fmt(c['lambda66'], '.4f')} | {c['reason']} |")
    lines += ["", "## What each named effect is worth", "",
              "| model | lambda66 (kg m^2) | hull RMS (urad) | x noise floor | held-out RMS | lambda66 shift if left out |",
              "|---|---|---|---|---|---|"]
    for row in j["effects_gain"]:
        lines.append(f"| {row['model']} | {row['lambda66']:.4f} | {row['residual_rms'] * 1e6:.2f} | "
                     f"{row['hull_excess']:.2f} | {_fmt(row['heldout_rms'])} | "
                     f"{_fmt(row['lambda66_shift_if_left_out'], '+.4f')} |")
    lines += ["", "## Gain", "",
              "| | nominal | extended |", "|---|---|---|",
              f"| hull residual RMS (urad) | {g['residual_rms_nominal'] * 1e6:.2f} | {g['residual_rms_extended'] * 1e6:.2f} |",
              f"| flywheel residual RMS (mrad) | {g['flywheel_rms_nominal'] * 1e3:.3f} | {g['flywheel_rms_extended'] * 1e3:.3f} |",
              f"| held-out prediction RMS (noise units) | {_fmt(g['heldout_rms_nominal'])} | {_fmt(g['heldout_rms_extended'])} |",
              f"| lambda66 (kg m^2) | {g['lambda66_nominal']:.4f} | {g['lambda66_extended']:.4f} |", "",
              f"Extended model residuals: {sx['hull_excess']:.2f} x noise floor, lag-1 autocorrelation {sx['lag1']:.2f}.",
              "", "## Figures", ""]
    lines += [f"![{p.stem}]({p.name})" for p in figures]
    lines += ["", f"Wall time {diag.wall_s:.1f} s. Method: docs/DISCOVERY.md.", ""]
    return "\n".join(lines)


def _fmt(x, spec: str = ".3f") -> str:
    return "-" if x is None else format(x, spec)


def write_report(diag: Diagnosis, folder: str | os.PathLike) -> Path:
    """Write ``report.md``, its figures and ``discovery.json`` into ``folder`` (atomically); returns the report's path."""
    folder = Path(folder)
    figures = plot_residuals(diag, folder)
    path = folder / "report.md"
    atomic_write_text(path, markdown(diag, figures))
    atomic_write_text(folder / "discovery.json", json.dumps(plain(diag.to_json()), indent=1, allow_nan=False) + "\n")
    return path
