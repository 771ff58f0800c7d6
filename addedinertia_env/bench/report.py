"""A whole leaderboard document from bench rows: header (how it was made), table, verdict, figures.

``build(rows, files, command, fmt, out)`` returns the text of a Markdown document or a
self-contained HTML page and writes its figures beside ``out`` (``figures/``).
"""

from __future__ import annotations

import datetime
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.bench.leaderboard import abs_errors, summarise
from addedinertia_env.bench.render import render_html, render_markdown
from addedinertia_env.bench.verdict import MIN_EPISODES


def preamble(rows: list[dict], command: str) -> str:
    """How the leaderboard was made: the command actually run, the rows' own commands, the
    suite, the machine, the score."""
    suites = sorted({f"{r['suite']}/{r.get('split', '?')}" for r in rows})
    run_commands = sorted({str(r["command"]) for r in rows if r.get("command")})
    commits = sorted({str(r.get("commit", "unknown")) for r in rows})
    from addedinertia_env.bench.versions import check_versions  # noqa: PLC0415

    version = check_versions({"rows": rows})
    paired = any(r["controller"] == "oracle" for r in rows)
    lines = [f"Produced {datetime.date.today().isoformat()} by `{command}`.",
             f"Rows from commit(s) {', '.join(commits)}, made by: "
             + ("; ".join(f"`{c}`" for c in run_commands) if run_commands else "(the rows do not record it)") + ".",
             f"Suite/split: {', '.join(suites)} ({_suite_notes(rows)}). Machine: {machine_line()}. "
             f"Score version: `{version}` (bench/versions.py).",
             ("Error e = lambda66 estimate / truth - 1 of the patent's energy method as written, its balance corrected "
              "for the work of the water's memory identified from the records (`identify(records, 'energy', "
              "asymmetry_correction=False, memory='auto')`'s `lambda66_energy_corrected`; the suite's `ranked: "
              "memory-corrected`: the method as a lab would use it in water that remembers)" if any(r.get("ranked_score") == "memory-corrected" for r in rows)
              else "Error e = lambda66 estimate / truth - 1 of the patent's energy method as written "
              "(`identify(records, 'energy', asymmetry_correction=False)`)")
             + "; `corrected` = the default identification "
             "(dissipation mismatch corrected with a damping law fitted to the free stroke). A failed run or "
             "identification counts as an infinite error."]
    from addedinertia_env.bench.score import CAP  # noqa: PLC0415

    lines.append(f"Ranked score ({version}, bench/score.py): the mean over the scenarios of min(|e|, "
                 f"{100 * CAP:.0f} %), a failed run or identification counting {100 * CAP:.0f} %, with a 95 % "
                 "bootstrap interval of the mean (2000 resamples of the scenarios, seed 0). Tie rule: an entry whose "
                 "paired 95 % interval of the mean difference of scores against its group's leader (same scenarios, "
                 "same sensor noise) includes zero joins the group; ties are listed by energy.")
    if paired:
        lines.append("Beside it, not ranked: the control error |e_entry - e_oracle|, paired by scenario, its median "
                     "with a 95 % paired bootstrap interval; paired tests between entries: median of | c_A | - | c_B | "
                     "with its bootstrap interval and the Wilcoxon signed-rank p.")
    lines.append("Wear per episode (mean over cycles): sign changes of the commanded current (hysteresis 2 % of "
                 "i_max) and chatter (RMS of its sample-to-sample change) over hold + reverse stroke (bench/wear.py).")
    lines.append("IQM = mean of the middle 50 %; energy = integral of |u i| dt over hold + reverse stroke. "
                 "ILC learns for 2 unscored cycles, then is scored.")
    coverage = _coverage(rows)
    if coverage:
        lines.append(coverage)
    small = sorted({n for n in (sum(r["controller"] == c for r in rows) for c in {r["controller"] for r in rows})
                    if n < MIN_EPISODES})
    if small:
        lines.append(f"WARNING: some intervals rest on fewer than {MIN_EPISODES} episodes ({small}); they are "
                     "wide and unreliable.")
    return "\n".join(lines)


def _coverage(rows: list[dict]) -> str:
    """A sentence when the rows cover only part of their suite's split (``--seeds N``)."""
    from addedinertia_env.sim.presets import ConfigError  # noqa: PLC0415
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    parts = []
    for suite, split in sorted({(str(r["suite"]), str(r.get("split", "?"))) for r in rows}):
        try:
            total = len(load_suite(suite).seeds(split))
        except (ConfigError, OSError, ValueError):
            continue
        used = len({r["seed"] for r in rows if r["suite"] == suite and r.get("split") == split})
        if used < total:
            parts.append(f"{suite}/{split}: {used} of its {total} scenarios (the first {used}; `--seeds {used}`)")
    if not parts:
        return ""
    return ("REDUCED: " + "; ".join(parts) + ", to spare the shared CPU; the intervals are wider than with the "
            "whole split.")


def _suite_notes(rows: list[dict]) -> str:
    """Where each suite is defined, with its one-line description."""
    from addedinertia_env.bench.suites import SUITE_DIR, load_suite  # noqa: PLC0415

    notes = []
    for name in sorted({str(r["suite"]) for r in rows}):
        path = SUITE_DIR / f"{name}.yaml"
        if path.exists():
            notes.append(f"`configs/suites/{name}.yaml`: {load_suite(name).description}")
        else:
            notes.append(f"{name}: not a suite of this version")
    return "; ".join(notes)


def breakdown(rows: list[dict], order: list[str], key: str) -> str:
    """Median |error| per controller and per value of ``key`` (Markdown)."""
    values = sorted({str(r.get(key)) for r in rows})
    lines = ["| controller | " + " | ".join(f"{key} = {v}" for v in values) + " |", "|" + "---|" * (len(values) + 1)]
    for name in order:
        cells = []
        for v in values:
            rs = [r for r in rows if r["controller"] == name and str(r.get(key)) == v]
            cells.append(f"{100 * float(np.median(abs_errors(rs))):.3f} % (n={len(rs)})" if rs else "-")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def figures_for(rows: list[dict], entries: list[dict], out: Path) -> dict[str, Path]:
    """The Pareto figure and the per-episode figures, in ``out``'s folder ``figures/``."""
    from addedinertia_env.bench.plots import plot_error_vs_energy, plot_pareto, plot_per_scenario  # noqa: PLC0415

    fig_dir = out.parent / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    stem = out.stem.lower()
    order = [e["controller"] for e in entries]
    paired = any(e.get("median_abs_control_error") is not None for e in entries)
    label = "median |control error| vs oracle" if paired else "median |error|"
    return {
        "Pareto figure: accuracy against energy": plot_pareto(entries, fig_dir / f"{stem}-pareto.png", label),
        "|error| against energy, per episode": plot_error_vs_energy(rows, order, fig_dir / f"{stem}-error-energy.png"),
        "per-scenario |error|": plot_per_scenario(rows, order, fig_dir / f"{stem}-per-scenario.png"),
    }


def aggregate_section(rows: list[dict], entries: list[dict], out: Path | None) -> str:
    """rliable's aggregate statistics over the runs x scenarios score matrix (Markdown): the IQM with its
    stratified-bootstrap interval and the probability of improvement over the best classical entry per
    controller, and the performance profiles figure (beside ``out``, when given)."""
    from addedinertia_env.bench.leaderboard import scores  # noqa: PLC0415
    from addedinertia_env.bench.ranking import best  # noqa: PLC0415
    from addedinertia_env.bench.statistics import (
        RLIABLE_REPS,
        improvement_over,
        iqm_with_ci,
        plot_performance_profiles,
        score_matrix,
    )  # noqa: PLC0415

    what, per = scores(rows)
    scenarios, matrices = score_matrix(per)
    if not scenarios:
        return ""
    iqms = iqm_with_ci(matrices)
    classical = best(entries, "classical")
    ref = classical["controller"] if classical is not None and classical["controller"] in matrices else None
    poi = improvement_over(matrices, ref) if ref else {}
    pct = lambda v: "inf" if v == float("inf") else f"{100 * v:.3f} %"  # noqa: E731
    lines = [f"\n## Aggregate statistics (rliable)\n",
             f"Over the {len(scenarios)} scenarios every controller ran, score = {what}, lower is better; "
             f"`addedinertia bench leaderboard ... --format scores --out FILE.npz` writes the matrix. IQM with a 95 % "
             f"stratified-bootstrap interval ({RLIABLE_REPS} resamples, seed 0); probability of improvement "
             f"P(score < the best classical entry's{f', {ref}' if ref else ''}), Mann-Whitney per scenario averaged "
             "over scenarios, with its interval (Agarwal et al. 2021).", "",
             "| controller | IQM | IQM 95 % CI | P(improvement over best classical) | its 95 % CI |", "|---|---|---|---|---|"]
    for e in entries:
        name = e["controller"]
        if name not in iqms:
            continue
        v, lo, hi = iqms[name]
        p = poi.get(name)
        lines.append(f"| {name} | {pct(v)} | {pct(lo)} .. {pct(hi)} | " + (f"{p[0]:.3f} | {p[1]:.3f} .. {p[2]:.3f} |"
                                                                          if p else "- | - |"))
    if out is not None:
        fig_dir = out.parent / "figures"
        path = plot_performance_profiles(matrices, fig_dir / f"{out.stem.lower()}-profiles.png", what.split(" (")[0])
        rel = path.relative_to(out.parent)
        lines += ["", f"![performance profiles: fraction of runs with error above tau]({rel})"]
    return "\n".join(lines) + "\n"


def build(rows: list[dict], command: str, fmt: str = "md", out: Path | None = None,
          title: str = "Controller leaderboard") -> tuple[str, list[dict[str, Any]]]:
    """``(text, entries)`` of the leaderboard in ``fmt`` (``md`` or ``html``); figures only with ``out``."""
    entries = summarise(rows)
    pre = preamble(rows, command)
    if fmt == "html":
        return render_html(entries, rows, title, pre), entries
    figures = figures_for(rows, entries, out) if out is not None else {}
    order = [e["controller"] for e in entries]
    text = f"# {title}\n\n" + render_markdown(entries, figures, out.parent if out else None, pre)
    for key, label in (("sensor_quality", "sensor quality"), ("preset", "rig preset")):
        if len({str(r.get(key)) for r in rows}) > 1 or key == "preset":
            text += f"\n## Median |error| (as written) by {label}\n\n" + breakdown(rows, order, key) + "\n"
    text += aggregate_section(rows, entries, out)
    return text, entries
