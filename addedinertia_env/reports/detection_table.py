"""Detection and false-alarm rates of ``discover`` per hidden effect, written into docs/DISCOVERY.md.

    python -m addedinertia_env.reports.detection_table --seeds 10 --out docs/DISCOVERY.md

(``make detection-table``.) For every effect of the vocabulary and for ``none``, seeds
0..N-1 each simulate the standard dataset (:mod:`.dataset`) with that effect hidden at a
size drawn from its realistic range (``sim/effects/``); :func:`.diagnose.discover` runs blind on the records;
only the scoring here reads the truth. The table replaces the block between the markers
``<!-- detection-table:begin -->`` and ``<!-- detection-table:end -->`` of the output file
(or the whole file if it has no markers). Simulated records are cached under ``--cache``
so that a re-run only re-analyses.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.records.record import read_record
from addedinertia_env.sim.effects import EFFECT_NAMES
from addedinertia_env.apps.discovery_dataset import DatasetSpec, hidden_effect, simulate_dataset
from addedinertia_env.discover.diagnose import discover
from addedinertia_env.reports.sections import replace_section

BEGIN, END = "<!-- detection-table:begin -->", "<!-- detection-table:end -->"
ROWS = ("none",) + EFFECT_NAMES


def dataset_records(effect: str, seed: int, cache: Path | None):
    """The records of one simulated discovery dataset (``effect`` hidden, ``seed``).

    With a ``cache`` folder, records already there are read instead of simulated again, and
    new ones are written there.
    """
    spec = DatasetSpec()
    if cache is not None:
        folder = cache / f"{effect}-{seed}"
        paths = sorted(folder.glob("*.csv"))
        if len(paths) == len(spec.runs):
            return [read_record(p) for p in paths]
        return simulate_dataset(effect, seed, spec, out=folder)
    return simulate_dataset(effect, seed, spec)


def evaluate(effect: str, seed: int, cache: Path | None) -> dict:
    """Run ``discover`` on one dataset; returns the named cause, the gain of the extended model,
    the lambda66 errors (fractions; truth read for scoring only) and the times (s).
    """
    t0 = time.perf_counter()
    records = dataset_records(effect, seed, cache)
    t1 = time.perf_counter()
    diag = discover(records)
    t2 = time.perf_counter()
    truth = records[0].truth_lambda66()  # scoring only
    g = diag.gain()
    return {"effect": effect, "seed": seed, "truth_effect": hidden_effect(effect, seed).to_dict(),
            "cause": diag.cause, "lambda66_true": truth, **g,
            "lambda66_err_nominal": g["lambda66_nominal"] / truth - 1.0,
            "lambda66_err_extended": g["lambda66_extended"] / truth - 1.0,
            "sim_s": t1 - t0, "discover_s": t2 - t1}


def table(rows: list[dict], seeds: int, wall_s: float) -> str:
    """The marked Markdown block of detection and false-alarm rates and the confusion table, from the rows of :func:`evaluate`."""
    lines = [BEGIN, "",
             f"Measured by `python -m addedinertia_env.reports.detection_table --seeds {seeds} --out docs/DISCOVERY.md`"
             f" on {machine_line()}; {wall_s / 60:.1f} min in all, median `discover` "
             f"{np.median([r['discover_s'] for r in rows]):.1f} s per dataset of 4 runs.", "",
             "| hidden effect | seeds | detected | wrong effect named | missed (`none`) | `unexplained` "
             "| median residual RMS nominal -> extended (urad) | median held-out gain "
             "| median abs lambda66 error nominal -> extended |",
             "|---|---|---|---|---|---|---|---|---|"]
    for effect in ROWS:
        rs = [r for r in rows if r["effect"] == effect]
        if not rs:
            continue
        n = len(rs)
        hit = sum(r["cause"] == effect for r in rs)
        none = sum(r["cause"] == "none" for r in rs)
        unex = sum(r["cause"] == "unexplained" for r in rs)
        wrong = n - hit - unex - (0 if effect == "none" else none)
        if effect == "none":
            detected = f"{hit}/{n} correct `none`"
            wrong_txt = f"**false alarm {wrong}/{n}**"
            missed = "-"
        else:
            detected = f"**{hit}/{n}**"
            wrong_txt = f"{wrong}/{n}"
            missed = f"{none}/{n}"
        rn = np.median([r["residual_rms_nominal"] for r in rs]) * 1e6
        rx = np.median([r["residual_rms_extended"] for r in rs]) * 1e6
        ho = np.median([r["heldout_gain"] or 0.0 for r in rs])
        en = np.median([abs(r["lambda66_err_nominal"]) for r in rs]) * 100
        ex = np.median([abs(r["lambda66_err_extended"]) for r in rs]) * 100
        lines.append(f"| `{effect}` | {n} | {detected} | {wrong_txt} | {missed} | {unex}/{n} | {rn:.1f} -> {rx:.1f} "
                     f"| {ho:.0%} | {en:.3f} % -> {ex:.3f} % |")
    lines += ["", "Confusion (rows: hidden, columns: named):", "",
              "| hidden \\ named | " + " | ".join(f"`{c}`" for c in ROWS + ("unexplained",)) + " |",
              "|---" * (len(ROWS) + 2) + "|"]
    for effect in ROWS:
        rs = [r for r in rows if r["effect"] == effect]
        if rs:
            lines.append(f"| `{effect}` | " + " | ".join(str(sum(r["cause"] == c for r in rs))
                                                          for c in ROWS + ("unexplained",)) + " |")
    lines += ["", END]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Regenerate ``the detection table of docs/DISCOVERY.md`` (the command is in the module docstring; also one JSON line per dataset in ``--jsonl``); ``argv`` as on the command line; returns 0."""
    from tqdm import tqdm  # noqa: PLC0415

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 per effect")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--effects", nargs="*", default=list(ROWS), choices=list(ROWS))
    ap.add_argument("--out", default="docs/DISCOVERY.md")
    ap.add_argument("--jsonl", default="out/detection-table.jsonl", help="one line per dataset")
    ap.add_argument("--cache", default="out/discovery-datasets", help="folder for simulated records ('' = none)")
    args = ap.parse_args(argv)
    cache = Path(args.cache) if args.cache else None
    jobs = [(e, s) for s in range(args.first_seed, args.first_seed + args.seeds) for e in args.effects]
    rows = []
    t0 = time.perf_counter()
    Path(args.jsonl).parent.mkdir(parents=True, exist_ok=True)
    with open(args.jsonl, "w") as f, tqdm(jobs, unit="dataset") as bar:
        for effect, seed in bar:
            bar.set_postfix_str(f"{effect} seed {seed}")
            r = evaluate(effect, seed, cache)
            rows.append(r)
            f.write(json.dumps(r) + "\n")
            f.flush()
    block = table(rows, args.seeds, time.perf_counter() - t0)
    replace_section(args.out, block, BEGIN, END)
    print(block)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
