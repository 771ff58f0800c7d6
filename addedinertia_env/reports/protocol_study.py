"""The protocol's part in the memory bias (issue 26 item 5): how the hold, the release, the
window of boundary angles and the twist change the energy method's error against A66(0)
in water that remembers, before and after the memory correction.

    python -m addedinertia_env.reports.protocol_study --seeds 2 --free-seeds 8 --out docs/RADIATION_MEMORY.md

For each memory preset (``wigley-2m-memory``, ``spheroid-7-memory``: the BEM cache's
Cummins water, A66(0) = the preset's lambda66) and seed, one factor of the preset's plan
is moved at a time from its value (twist 0.10 rad, hold 2 s, boundary angles 25-75 % of
the stroke): the hold (0 s: the brake is set and let go in the same sample, so the reverse
stroke starts at once; 0.1, 0.5, 5, 10 s), the twist (0.05, 0.14 rad) and the window of
boundary angles (10-40 %, 50-90 %: analysis only, on the plan's own records). Every point is
one reverse-symmetric run (``lqr``), read twice: by the energy balance alone
(``identify([run], "energy")``, the method as written: "before") and with the memory
identified from the run and a free decay of the same hull (0.10 rad, one per preset and
seed) and corrected for (``identify([run, decay], "energy", memory=True)``: "after").
The simulator's truth (A66(0)) is read only here, to score. The same hulls in memory-free
water (``wigley-2m``, ``spheroid-7``, more seeds: they are cheap) at the plan, no hold and
0.1 s show the method's own accuracy there. One forced-oscillation run per memory preset
(:data:`FORCED_PLAN`) gives A66 at three drive frequencies against the truth curve and
A66(0) extrapolated from them, with its tank time.

The rows are kept in a JSON-lines log (``--rows``): a killed study resumes where it
stopped. The generated block of the doc (between its markers) holds the command, the date,
the machine, and per preset and point: the tank time of one run, the median and largest
error before and after, and how often the 95 % interval covers A66(0).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.reports.sections import replace_section

COMMAND = "python -m addedinertia_env.reports.protocol_study"
PRESETS = ("wigley-2m-memory", "spheroid-7-memory")
BEGIN, END = "<!-- protocol-study table: begin -->", "<!-- protocol-study table: end -->"
CONTROLLER = "lqr"
DEFAULT_WINDOW = (0.25, 0.75)
# The plan every factor is moved from (the presets' plan before this study; stated, so the
# rows do not depend on the presets' defaults, which now follow the recommendation).
BASE = {"alpha": 0.10, "hold_s": 2.0}
# (factor, level label, overrides of the plan, window of boundary angles)
POINTS: tuple[tuple[str, str, dict[str, float], tuple[float, float]], ...] = (
    ("plan", "twist 0.10 rad, hold 2 s, window 25-75 %", {}, DEFAULT_WINDOW),
    ("hold", "0 s (no hold)", {"hold_s": 0.0}, DEFAULT_WINDOW),
    ("hold", "0.1 s", {"hold_s": 0.1}, DEFAULT_WINDOW),
    ("hold", "0.5 s", {"hold_s": 0.5}, DEFAULT_WINDOW),
    ("hold", "5 s", {"hold_s": 5.0}, DEFAULT_WINDOW),
    ("hold", "10 s", {"hold_s": 10.0}, DEFAULT_WINDOW),
    ("twist", "0.05 rad", {"alpha": 0.05}, DEFAULT_WINDOW),
    ("twist", "0.14 rad", {"alpha": 0.14}, DEFAULT_WINDOW),
    ("window", "10-40 % (far from the release)", {}, (0.10, 0.40)),
    ("window", "50-90 % (near the release)", {}, (0.50, 0.90)),
)
DECAY_ALPHA = 0.10  # rad
# The same hulls in memory-free water: the points a recommendation could change, to show the
# method's own accuracy is kept there.
FREE_PRESETS = ("wigley-2m", "spheroid-7")
FREE_LEVELS = ("twist 0.10 rad, hold 2 s, window 25-75 %", "0 s (no hold)", "0.1 s")


def _key(preset: str, seed: int, factor: str, level: str) -> str:
    return f"{preset}|{seed}|{factor}|{level}"


def _read_rows(path: Path) -> list[dict]:
    if not path.exists():
        return []
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError as e:
                raise SystemExit(f"{path}: line {n} is not JSON ({e}); expected rows written by this study "
                                 "(delete the line or the file to redo them)") from None
    return rows


def _simulate(preset: str, seed: int, overrides: dict[str, float], kind: str = "reverse-symmetric"):
    from addedinertia_env.apps.simulate import simulate_run  # noqa: PLC0415
    from addedinertia_env.experiment.protocol import plan_from_preset  # noqa: PLC0415
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping  # noqa: PLC0415

    data = load_preset(preset)
    rig = rig_from_mapping(data)
    if kind == "free-decay":
        from addedinertia_env.experiment.free_decay import FreeDecayPlan  # noqa: PLC0415

        return simulate_run(rig, CONTROLLER, FreeDecayPlan(alpha=DECAY_ALPHA), seed=seed, kind=kind, run_id="decay")
    plan = plan_from_preset(data, **overrides)
    return simulate_run(rig, CONTROLLER, plan, seed=seed, run_id="run")


def study_point(run, decay, window: tuple[float, float]) -> dict[str, Any]:
    """One run read before (the balance alone) and after (memory identified and corrected);
    the errors against the run's own truth (A66(0)), in %."""
    from addedinertia_env.identify import IdentificationError, identify  # noqa: PLC0415

    truth = run.meta["truth"]
    a0 = float(truth["lambda66"])
    row: dict[str, Any] = {"A66_zero": a0, "A66_swing": truth.get("A66_swing"), "A66_inf": truth.get("A66_inf"),
                           "tank_s": float(run.t[-1] - run.t[0])}
    try:
        before = identify([run], "energy", fractions=window, memory="off")
        row["before"] = float(before.lambda66)
    except IdentificationError as e:
        row["before"], row["why"] = math.nan, str(e)[:200]
        return row
    after = identify([run, decay], "energy", fractions=window, memory=True)
    row.update(after=float(after.lambda66), after_ci95=[float(x) for x in after.ci95],
               memory=str(after.details.get("memory")), memory_bias=after.details.get("memory_bias"))
    row["err_before"] = 100.0 * (row["before"] / a0 - 1.0)
    row["err_after"] = 100.0 * (row["after"] / a0 - 1.0)
    row["covered"] = bool(after.ci95[0] <= a0 <= after.ci95[1])
    row["half_width"] = 100.0 * 0.5 * (after.ci95[1] - after.ci95[0]) / a0
    return row


FORCED_PLAN = {"alpha": 0.06, "ratios": (0.5, 0.7, 1.3), "periods": 3, "settle_s": 40.0, "measure_s": 30.0}


def forced_row(preset: str, seed: int) -> dict[str, Any]:
    """One forced-oscillation run at 0.5, 0.7 and 1.3 x the swing frequency: A66 per frequency
    against the truth curve, A66(0) extrapolated from the two low ones, tank time."""
    from addedinertia_env.apps.simulate import simulate_run  # noqa: PLC0415
    from addedinertia_env.experiment.forced import ForcedPlan  # noqa: PLC0415
    from addedinertia_env.identify import IdentificationError  # noqa: PLC0415
    from addedinertia_env.identify.forced_memory import extrapolate_zero, forced_points  # noqa: PLC0415
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping  # noqa: PLC0415

    rig = rig_from_mapping(load_preset(preset))
    rec = simulate_run(rig, CONTROLLER, ForcedPlan(**FORCED_PLAN), seed=seed, kind="forced-oscillation", run_id="forced")
    a0 = rig.hull.lambda66
    curve = (lambda w: a0 * float(rig.hydrodynamics.added_inertia_ratio(w)[0])) if rig.hydrodynamics else (lambda w: a0)
    points = forced_points([rec])
    row: dict[str, Any] = {"A66_zero": a0, "tank_s": float(rec.t[-1] - rec.t[0]),
                           "points": [{"omega": p.omega, "ratio": p.omega / p.swing_omega, "A66": p.A66,
                                       "err": 100.0 * (p.A66 / curve(p.omega) - 1.0),
                                       "half_width": 100.0 * 1.96 * p.sigma / curve(p.omega),
                                       "tank_s": p.measured_s + FORCED_PLAN["settle_s"]} for p in points]}
    try:
        z = extrapolate_zero(points)
    except IdentificationError as e:
        row["why"] = str(e)[:200]
    else:
        row.update(after=z["A66_zero"], err_after=100.0 * (z["A66_zero"] / a0 - 1.0),
                   covered=bool(z["ci95"][0] <= a0 <= z["ci95"][1]), half_width=100.0 * 0.5 * (z["ci95"][1] - z["ci95"][0]) / a0)
    return row


def run_study(rows_path: Path, presets, seeds, free_seeds=()) -> list[dict]:
    """Simulate and read every point not yet in ``rows_path``; appends one JSON line per point
    (memory presets: ``seeds``; memory-free presets: ``free_seeds``)."""
    rows = _read_rows(rows_path)
    done = {r["key"] for r in rows}
    rows_path.parent.mkdir(parents=True, exist_ok=True)
    for preset in presets:
        for seed in (seeds if preset in PRESETS else free_seeds):
            points = POINTS if preset in PRESETS else [p for p in POINTS if p[1] in FREE_LEVELS]
            todo = [p for p in points if _key(preset, seed, p[0], p[1]) not in done]
            if not todo:
                continue
            decay = _simulate(preset, 10_000 + seed, {}, kind="free-decay")
            plan_run = None
            for factor, level, overrides, window in todo:
                c0 = time.process_time()
                if overrides:
                    run = _simulate(preset, seed, {**BASE, **overrides})
                else:
                    plan_run = plan_run or _simulate(preset, seed, dict(BASE))
                    run = plan_run
                row = {"key": _key(preset, seed, factor, level), "preset": preset, "seed": seed, "factor": factor,
                       "level": level, "overrides": overrides, "window": list(window)}
                row.update(study_point(run, decay, window))
                row["cpu_s"] = time.process_time() - c0
                with rows_path.open("a") as f:
                    f.write(json.dumps(row) + "\n")
                rows.append(row)
                print(f"{row['key']}: before {row.get('err_before', math.nan):+.3f} %, "
                      f"after {row.get('err_after', math.nan):+.3f} % ({row.get('memory')}), "
                      f"{row['cpu_s']:.1f} CPU s", file=sys.stderr, flush=True)
        if preset in PRESETS and _key(preset, seeds[0], "forced", "0.5/0.7/1.3 x swing") not in done:
            c0 = time.process_time()
            row = {"key": _key(preset, seeds[0], "forced", "0.5/0.7/1.3 x swing"), "preset": preset, "seed": seeds[0],
                   "factor": "forced", "level": "0.5/0.7/1.3 x swing"}
            row.update(forced_row(preset, seeds[0]))
            row["cpu_s"] = time.process_time() - c0
            with rows_path.open("a") as f:
                f.write(json.dumps(row) + "\n")
            rows.append(row)
            print(f"{row['key']}: A66(0) {row.get('err_after', math.nan):+.3f} %, {row['cpu_s']:.1f} CPU s",
                  file=sys.stderr, flush=True)
    return rows


def _median(xs) -> float:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return float(np.median(xs)) if xs else math.nan


def _largest(xs) -> float:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return max(xs, key=abs) if xs else math.nan


def render(rows: list[dict], seeds: int, free_seeds: int = 8) -> str:
    """The doc's generated block from the study's rows."""
    lines = [BEGIN, "", "Generated by a command; do not edit by hand. To regenerate:", "", "```",
             f"{COMMAND} --seeds {seeds} --free-seeds {free_seeds} --out docs/RADIATION_MEMORY.md", "```", "",
             f"- Date: {dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M} UTC",
             f"- Machine: {machine_line()}; shared with other jobs, so CPU seconds, not wall time, measure the cost.",
             f"- Controller `{CONTROLLER}`; seeds 1..{seeds} per point in water with memory, 1..{free_seeds} in memory-free "
             "water (sensor noise); one free decay "
             f"({DECAY_ALPHA:.2f} rad) per preset and seed beside every run for the memory's identification.",
             "- Errors against A66(0) (the truth's `lambda66`): median over the seeds (largest in brackets). "
             "\"tank s\": the run's recorded length (twist and reset by the operator not counted). "
             "\"covered\": the corrected estimate's 95 % interval holds A66(0).", ""]
    cpu = [r.get("cpu_s", 0.0) for r in rows]
    if cpu:
        lines.append(f"- Cost: {sum(cpu):.0f} CPU s in all, median {np.median(cpu):.1f} CPU s per point "
                     "(simulation and both readings; rows kept from an earlier, resumed run count with their own CPU time).")
        lines.append("")
    lines += ["| preset | factor | level | tank s per run | before: error vs A66(0) | after: error vs A66(0) "
              "| after: median half-width | covered | memory found |",
              "|---|---|---|---|---|---|---|---|---|"]
    for preset in PRESETS + FREE_PRESETS:
        for factor, level, _, _ in POINTS:
            sel = [r for r in rows if r["preset"] == preset and r["factor"] == factor and r["level"] == level]
            if not sel:
                continue
            ok = [r for r in sel if "err_after" in r]
            eb = [r.get("err_before") for r in sel]
            ea = [r.get("err_after") for r in ok]
            cov = sum(1 for r in ok if r.get("covered"))
            found = sum(1 for r in ok if r.get("memory") not in (None, "none") and
                        not str(r.get("memory")).startswith("not identifiable"))
            lines.append(f"| {preset} | {factor} | {level} | {_median([r['tank_s'] for r in sel]):.1f} "
                         f"| {_median(eb):+.3f} % ({_largest(eb):+.3f} %) | {_median(ea):+.3f} % ({_largest(ea):+.3f} %) "
                         f"| {_median([r.get('half_width') for r in ok]):.3f} % | {cov}/{len(sel)} | {found}/{len(sel)} |")
    forced = [r for r in rows if r["factor"] == "forced"]
    if forced:
        f = FORCED_PLAN
        lines += ["", f"Forced runs (`simulate --kind forced-oscillation`, seed {forced[0]['seed']}, twist {f['alpha']} rad, "
                  f"drive at {', '.join(str(x) for x in f['ratios'])} x the half swing's frequency, {f['settle_s']:g} s settle "
                  f"then at least {f['measure_s']:g} s measured per frequency; identify/forced_memory.py): A66 at each drive "
                  "frequency against the simulator's truth curve A66(omega), and A66(0) extrapolated from the frequencies "
                  "under the swing.", "",
                  "| preset | drive / swing | omega (rad/s) | A66 error vs truth curve | 95 % half-width | tank s |",
                  "|---|---|---|---|---|---|"]
        for r in forced:
            for p in r["points"]:
                lines.append(f"| {r['preset']} | {p['ratio']:.2f} | {p['omega']:.3f} | {p['err']:+.3f} % "
                             f"| {p['half_width']:.3f} % | {p['tank_s']:.0f} |")
            if "err_after" in r:
                lines.append(f"| {r['preset']} | A66(0), extrapolated | 0 | {r['err_after']:+.3f} % | "
                             f"{r['half_width']:.3f} % ({'covers' if r['covered'] else 'misses'}) "
                             f"| {r['tank_s']:.0f} (whole run) |")
    lines += ["", END]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the study (resuming from ``--rows``) and write the doc's block; exit 2 on bad arguments."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="seeds 1..N per point")
    ap.add_argument("--presets", nargs="+", default=list(PRESETS + FREE_PRESETS), choices=PRESETS + FREE_PRESETS)
    ap.add_argument("--free-seeds", type=int, default=8, help="seeds 1..N per point in memory-free water (cheap)")
    ap.add_argument("--rows", default="out/protocol_study/rows.jsonl", help="JSON-lines log of finished points (resumed)")
    ap.add_argument("--out", default=None, help="doc to write the block into (default: print it)")
    args = ap.parse_args(argv)
    for name in ("seeds", "free_seeds"):
        if not 1 <= getattr(args, name) <= 50:
            ap.error(f"--{name.replace('_', '-')} {getattr(args, name)}: expected 1 to 50")
    seeds, free = list(range(1, args.seeds + 1)), list(range(1, args.free_seeds + 1))
    rows = [r for r in run_study(Path(args.rows), args.presets, seeds, free) if r["preset"] in args.presets
            and r["seed"] in (seeds if r["preset"] in PRESETS else free)]
    block = render(rows, args.seeds, args.free_seeds)
    if args.out:
        replace_section(args.out, block, BEGIN, END, heading="## Measured: the protocol's part")
        print(f"wrote {args.out}", file=sys.stderr)
    else:
        sys.stdout.write(block)
    return 0


if __name__ == "__main__":
    sys.exit(main())
