"""What radiation memory does to the measurement: the energy method and discovery on records
made with the ``cummins`` hydrodynamic model on, beside the same runs with it off.

    python -m addedinertia_env.reports.radiation_memory --seeds 3 --out docs/RADIATION_MEMORY.md

For each preset (``wigley-2m``, ``spheroid-7``) and seed, the standard discovery dataset
(:mod:`addedinertia_env.apps.discovery_dataset`: twists 0.05 and 0.10 rad, holds 0.5 and 5 s,
realistic sensors, the dataset's controller, no hidden effect) is simulated twice with the
same noise: with radiation memory on (the preset's lambda66 = A66(0), the BEM cache's
memory model) and off (constant lambda66). Each reverse-symmetric record gets the energy
method (one record at a time, no ``truth`` read); each set of four records gets
``discover``. Scoring reads the records' truth: A66(0), A66 at the natural swing frequency
and A66(inf) (:func:`addedinertia_env.hydro.radiation.truth_block`).

The generated block of the doc (between its markers) holds the command, date, machine,
the summary per preset and reference, the per-record table and discovery's verdicts; the
hand-written text around it explains the model. Written atomically.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import math
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.reports.sections import replace_section

COMMAND = "python -m addedinertia_env.reports.radiation_memory"
PRESETS = ("wigley-2m", "spheroid-7")
REFERENCES = ("A66_zero", "A66_swing", "A66_inf")
BEGIN, END = "<!-- radiation-memory table: begin -->", "<!-- radiation-memory table: end -->"
FLUID_MEMORY_DOC = Path(__file__).resolve().parents[2] / "docs" / "ACCURACY_fluid_memory.md"
SEED0 = 1500


def run_case(preset: str, seed: int, memory: bool, discover_too: bool = True,
             controller: str | None = None) -> dict[str, Any]:
    """One dataset (4 records) on ``preset`` with memory on or off: energy estimates, truth, verdict.

    ``controller``: the reverse stroke's controller (default: the discovery dataset's)."""
    from addedinertia_env.discover import discover  # noqa: PLC0415
    from addedinertia_env.apps.discovery_dataset import DatasetSpec, simulate_dataset  # noqa: PLC0415
    from addedinertia_env.identify import IdentificationError, identify  # noqa: PLC0415

    spec = DatasetSpec(rig=preset, hydrodynamics="cummins" if memory else "constant")
    if controller:
        spec = dataclasses.replace(spec, controller=controller)
    t0 = time.perf_counter()
    records = simulate_dataset("none", seed, spec)
    truth = records[0].meta["truth"]
    hydro = truth.get("hydrodynamics") or {"A66_zero": truth["lambda66"], "A66_swing": truth["lambda66"],
                                           "A66_inf": truth["lambda66"]}
    rows = []
    for rec in records:
        exp = rec.meta["experiment"]
        try:
            est = float(identify([rec], "energy", memory="off").lambda66)
        except IdentificationError as e:
            est, why = math.nan, str(e)
        else:
            why = ""
        rows.append({"alpha": exp["alpha"], "hold": exp["hold_s"], "energy": est, "failure": why})
    out = {"preset": preset, "seed": seed, "memory": memory, "refs": {k: float(hydro[k]) for k in REFERENCES},
           "swing_omega": hydro.get("swing_omega"), "runs": rows, "free_decay": _free_decay(preset, seed, memory)}
    if discover_too:
        diag = discover(records)
        j = diag.to_json()
        fitted = [c for c in j["candidates"] if c["delta_bic"] is not None]  # the screened-out ones have none
        best = max(fitted, key=lambda c: c["delta_bic"]) if fitted else None
        out["discover"] = {"cause": diag.cause, "causes": list(diag.causes),
                           "lambda66_nominal": j["gain"]["lambda66_nominal"],
                           "best_candidate": best["cause"] if best else None,
                           "best_delta_bic": best["delta_bic"] if best else None,
                           "best_reason": best["reason"] if best else None}
    out["wall_s"] = time.perf_counter() - t0
    return out


def _free_decay(preset: str, seed: int, memory: bool) -> float:
    """lambda66 (kg m^2) by the free-decay method from one passive decay (twist 0.10 rad); nan if refused."""
    from addedinertia_env.experiment.free_decay import FreeDecayPlan, run_free_decay  # noqa: PLC0415
    from addedinertia_env.identify import IdentificationError, identify  # noqa: PLC0415
    from addedinertia_env.sim.mujoco_rig import MujocoRig  # noqa: PLC0415
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping  # noqa: PLC0415

    p = rig_from_mapping(load_preset(preset), hydrodynamics="cummins" if memory else "constant")
    rec = run_free_decay(MujocoRig(p, seed=np.random.SeedSequence([seed, 15, 4])), FreeDecayPlan(alpha=0.10),
                         run_id=f"{preset}-decay-{seed}")
    try:
        return float(identify([rec], "free-decay").lambda66)
    except IdentificationError:
        return math.nan


def water_work(preset: str, hold: float, alpha: float = 0.10, seed: int = SEED0,
               controller: str = "feedforward-pd") -> dict[str, Any]:
    """Where the energy method's shift comes from, on the simulator's truth (scoring side).

    One memory-on run with the true state logged; at the boundary angle halfway between the
    neutral and the rest angle ``phi2``: the work of the hull on the water (through the memory)
    over the forward stroke's part (``phi1`` to rest, negative: the water gives energy back)
    and over the reverse stroke's part (rest to ``phi1``), in mJ, their quasi-static value
    ``(A66(swing) - A66(inf)) w1^2 / 2``, and the lambda66 the energy balance implies when
    only these works are not mirrored: ``A66(inf) + (W_rev - W_fwd) / wbar^2`` with
    ``wbar^2 = (w1f^2 + w1r^2) / 2``.
    """
    from addedinertia_env.apps.energy_budget import simulate_with_truth  # noqa: PLC0415
    from addedinertia_env.experiment.protocol import plan_from_preset  # noqa: PLC0415
    from addedinertia_env.sim import forces  # noqa: PLC0415
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping  # noqa: PLC0415

    data = load_preset(preset)
    p = rig_from_mapping(data, hydrodynamics="cummins")
    run = simulate_with_truth(p, controller, plan_from_preset(data, alpha=alpha, hold_s=hold), seed=seed)
    st, phase = run.states, np.asarray(run.record["phase"])
    phi, w, W_in = st["phi"], st["w"], st["radiation_work"]
    held, rev, free = (np.nonzero(phase == name)[0] for name in ("hold", "reverse", "free"))
    k2, k3 = int(held[0]), int(held[-1])
    phi_n = forces.true_neutral(p)
    level = phi_n + 0.5 * (phi[k2] - phi_n)
    d = np.sign(phi[k2] - phi_n)
    k1 = int(free[0] + np.nonzero(d * (phi[free[0]:k2] - level) >= 0)[0][0])
    k4 = int(k3 + np.nonzero(-d * (phi[k3:rev[-1]] - level) >= 0)[0][0])
    wbar2 = 0.5 * (w[k1] ** 2 + w[k4] ** 2)
    a_inf, a_swing = float(forces.hull_armature(p)), forces.true_lambda66(p)
    fwd, rev_w = float(W_in[k2] - W_in[k1]), float(W_in[k4] - W_in[k3])
    return {"preset": preset, "hold": hold, "alpha": alpha, "fwd_mJ": 1e3 * fwd, "rev_mJ": 1e3 * rev_w,
            "quasi_static_mJ": 1e3 * 0.5 * (a_swing - a_inf) * wbar2,
            "hold_mJ": 1e3 * float(W_in[k3] - W_in[k2]),
            "implied": a_inf + (rev_w - fwd) / wbar2, "A66_swing": a_swing}


def _options(args: argparse.Namespace | None) -> str:
    """The non-default options of the command, as typed."""
    if args is None:
        return ""
    out = ""
    if args.seed0 != SEED0:
        out += f" --seed0 {args.seed0}"
    if args.controller:
        out += f" --controller {args.controller}"
    if args.no_discover:
        out += " --no-discover"
    return out


def _pct(x: float) -> str:
    return "failed" if not math.isfinite(x) else f"{100 * x:+.3f} %"


def _errors(case: dict[str, Any], ref: str) -> list[float]:
    r = case["refs"][ref]
    return [(row["energy"] - r) / r for row in case["runs"] if math.isfinite(row["energy"])]


def fluid_memory_line() -> str:
    """The energy method's summary row for the ad hoc ``fluid_memory`` effect, from its accuracy doc."""
    if not FLUID_MEMORY_DOC.exists():
        return "(docs/ACCURACY_fluid_memory.md not found)"
    for line in FLUID_MEMORY_DOC.read_text().splitlines():
        if line.startswith("| energy |"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            return (f"median |error| {cells[1]}, 90th percentile {cells[2]}, 95 % interval covers the truth "
                    f"{cells[3]}")
    return "(no energy row in docs/ACCURACY_fluid_memory.md)"


def render(cases: list[dict[str, Any]], seeds: list[int], wall: float, cpu: float,
           works: list[dict[str, Any]] | None = None, args: argparse.Namespace | None = None) -> str:
    """The generated block (Markdown) from the cases."""
    now = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [BEGIN, "", "Generated by a command; do not edit by hand. To regenerate:", "", "```",
             f"{COMMAND} --seeds {len(seeds)}{_options(args)} --out docs/RADIATION_MEMORY.md", "```", "",
             f"- Date: {now}", f"- Machine: {machine_line()}; the machine was shared with other jobs.",
             f"- Run time: {wall:.0f} s wall clock, {cpu:.0f} s CPU (this process).",
             f"- Datasets: the standard discovery dataset (4 reverse-symmetric runs: twist 0.05/0.10 rad x hold "
             f"0.5/5 s, realistic sensors, no hidden effect) per preset and seed, seeds {seeds[0]}..{seeds[-1]}; "
             "each with radiation memory on and, with the same noise, off. Reverse-stroke controller: "
             f"`{(args.controller if args and args.controller else 'feedforward-pd')}`.", "",
             "### Energy method: error against each reference", "",
             "Median (and largest) error of the energy method, one record at a time, relative to A66(0) "
             "(= the preset's lambda66), to A66 at the natural swing frequency (the truth with memory on) and "
             "to A66(inf) (the armature with memory on).", "",
             "| preset | memory | records | vs A66(0) | vs A66(swing) | vs A66(inf) | A66(0) / A66(swing) / A66(inf) (kg m^2) |",
             "|---|---|---|---|---|---|---|"]
    for preset in PRESETS:
        for memory in (True, False):
            sel = [c for c in cases if c["preset"] == preset and c["memory"] == memory]
            if not sel:
                continue
            cells = []
            for ref in REFERENCES:
                errs = [e for c in sel for e in _errors(c, ref)]
                if errs:
                    big = max(errs, key=abs)
                    cells.append(f"{_pct(float(np.median(errs)))} (max {_pct(big)})")
                else:
                    cells.append("failed")
            n = sum(len(_errors(c, "A66_zero")) for c in sel)
            total = sum(len(c["runs"]) for c in sel)
            r = sel[0]["refs"]
            refs = " / ".join(f"{r[k]:.4f}" for k in REFERENCES)
            lines.append(f"| {preset} | {'on' if memory else 'off'} | {n}/{total} | {' | '.join(cells)} | {refs} |")
    lines += ["", "Memory off, the three references are one number (lambda66): the rows show the method's own error "
              "on these runs, which the memory-on rows carry too (same noise).", "",
              "For comparison, the free-decay method (one passive decay from 0.10 rad per seed; it measures the "
              "swing period, so with memory on it should find A66 at the natural frequency):", "",
              "| preset | memory | decays | vs A66(0) | vs A66(swing) | vs A66(inf) |", "|---|---|---|---|---|---|"]
    for preset in PRESETS:
        for memory in (True, False):
            sel = [c for c in cases if c["preset"] == preset and c["memory"] == memory]
            vals = [(c["free_decay"], c["refs"]) for c in sel if math.isfinite(c.get("free_decay", math.nan))]
            if not sel:
                continue
            cells = [_pct(float(np.median([v / r[ref] - 1.0 for v, r in vals]))) if vals else "failed"
                     for ref in REFERENCES]
            lines.append(f"| {preset} | {'on' if memory else 'off'} | {len(vals)}/{len(sel)} | {' | '.join(cells)} |")
    lines += ["",
              f"Beside it, the ad hoc `fluid_memory` effect (a first-order water state, a hidden effect), energy "
              f"method: {fluid_memory_line()} (docs/ACCURACY_fluid_memory.md, 8 drawn hulls, `lqr` controller).", "",
              "### Per record (memory on minus memory off, same noise)", "",
              "| preset | seed | alpha (rad) | hold (s) | energy, memory on (kg m^2) | memory off (kg m^2) | shift on - off |"
              " on vs A66(swing) |",
              "|---|---|---|---|---|---|---|---|"]
    for preset in PRESETS:
        for seed in seeds:
            on = next((c for c in cases if c["preset"] == preset and c["seed"] == seed and c["memory"]), None)
            off = next((c for c in cases if c["preset"] == preset and c["seed"] == seed and not c["memory"]), None)
            if on is None or off is None:
                continue
            for a, b in zip(on["runs"], off["runs"]):
                shift = (a["energy"] - b["energy"]) / b["energy"]
                err = (a["energy"] - on["refs"]["A66_swing"]) / on["refs"]["A66_swing"]
                lines.append(f"| {preset} | {seed} | {a['alpha']:.3f} | {a['hold']:.1f} | {a['energy']:.4f} | "
                             f"{b['energy']:.4f} | {_pct(shift)} | {_pct(err)} |")
    if works:
        lines += ["", "### Where the shift comes from: the water's work, forward and reverse (truth side)", "",
                  "One memory-on run per row (twist 0.10 rad, seed "
                  f"{SEED0}), boundary angle halfway to the rest angle. Work of the hull on the water through the "
                  "memory: forward part (boundary to rest; negative: the water gives energy back) and "
                  "reverse part (rest to boundary; none is done during the hold, the hull is braked). A mirror-symmetric water would give equal and opposite works, "
                  "both the quasi-static `(A66(swing) - A66(inf)) w1^2 / 2`. Implied lambda66: "
                  "`A66(inf) + (W_rev - W_fwd) / wbar^2`, what the energy balance gives when only this work is not "
                  "mirrored.", "",
                  "| preset | hold (s) | forward (mJ) | reverse (mJ) | quasi-static (mJ) | implied lambda66 "
                  "| vs A66(swing) |", "|---|---|---|---|---|---|---|"]
        for r in works:
            lines.append(f"| {r['preset']} | {r['hold']:.1f} | {r['fwd_mJ']:+.2f} | "
                         f"{r['rev_mJ']:+.2f} | {r['quasi_static_mJ']:.2f} | {r['implied']:.4f} | "
                         f"{_pct(r['implied'] / r['A66_swing'] - 1.0)} |")
    lines += ["", "### Discovery's verdict", "",
              "`addedinertia discover` on each dataset (4 records; the verdict is a word of the effect vocabulary). "
              "lambda66 (nominal) is the nominal gray-box model's fit, a whole-record estimate.", "",
              "| preset | seed | memory | verdict | lambda66 nominal (kg m^2) | vs A66(swing) | strongest candidate "
              "(delta BIC) |", "|---|---|---|---|---|---|---|"]
    for c in cases:
        d = c.get("discover")
        if not d:
            continue
        verdict = d["cause"] + (f" ({' + '.join(d['causes'])})" if len(d["causes"]) > 1 else "")
        err = (d["lambda66_nominal"] - c["refs"]["A66_swing"]) / c["refs"]["A66_swing"]
        bic = f"{d['best_candidate']} ({d['best_delta_bic']:.1f})" if d["best_candidate"] else "-"
        lines.append(f"| {c['preset']} | {c['seed']} | {'on' if c['memory'] else 'off'} | {verdict} | "
                     f"{d['lambda66_nominal']:.4f} | {_pct(err)} | {bic} |")
    lines += ["", END]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the cases and write the doc's generated block; returns 0 (2 on bad arguments)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3, help="datasets per preset and memory setting (default 3)")
    ap.add_argument("--seed0", type=int, default=SEED0, help=f"first seed (default {SEED0})")
    ap.add_argument("--out", default="docs/RADIATION_MEMORY.md", help="the doc to update")
    ap.add_argument("--no-discover", action="store_true", help="energy method only (faster)")
    ap.add_argument("--controller", default=None, help="reverse-stroke controller (default: the discovery dataset's, "
                                                       "feedforward-pd)")
    args = ap.parse_args(argv)
    if args.seeds < 1:
        print(f"--seeds {args.seeds}: expected at least 1", file=sys.stderr)
        return 2
    t0, c0 = time.perf_counter(), time.process_time()
    seeds = list(range(args.seed0, args.seed0 + args.seeds))
    cases = []
    for preset in PRESETS:
        for seed in seeds:
            for memory in (True, False):
                case = run_case(preset, seed, memory, discover_too=not args.no_discover, controller=args.controller)
                cases.append(case)
                print(f"{preset} seed {seed} memory {'on' if memory else 'off'}: energy "
                      f"{[round(r['energy'], 4) for r in case['runs']]} refs {case['refs']} "
                      f"discover {case.get('discover', {}).get('cause')} ({case['wall_s']:.0f} s)", file=sys.stderr,
                      flush=True)
    works = [water_work(preset, hold, controller=args.controller or "feedforward-pd")
             for preset in PRESETS for hold in (0.5, 5.0)]
    block = render(cases, seeds, time.perf_counter() - t0, time.process_time() - c0, works, args)
    path = replace_section(args.out, block, BEGIN, END, heading="## Measured: the energy method and discovery "
                                                                "with memory on")
    print(f"written to {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
