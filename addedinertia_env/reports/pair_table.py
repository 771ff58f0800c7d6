"""Detection of two hidden effects at once, over every pair of the vocabulary, into docs/DISCOVERY.md.

    python -m addedinertia_env.reports.pair_table --seeds 1 --out docs/DISCOVERY.md

(``make pair-table``.) For every pair of registered effects (``sim/effects/``; a new word
joins by itself) and seeds 0..N-1, the standard dataset (:mod:`..discover.dataset`:
twists 0.05 and 0.10 rad x holds 0.5 and 5 s on the project's engine) is simulated with
both effects hidden at sizes drawn from their realistic ranges
(:func:`..discover.pairs.hidden_pair`); ``--none-seeds`` adds datasets with no effect for
the false-alarm rate; ``--quirks`` logs every dataset through two DAQ quirks drawn from
the seed (:func:`..daq.draw_quirks`). :func:`..discover.discover` runs blind; only the
scoring here reads the truth. "Exact": the named set equals the hidden set. "False
alarm": an effect named that was not hidden. The block between
``<!-- pair-table:begin -->`` and ``<!-- pair-table:end -->`` of ``--out`` is replaced.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import zlib
from pathlib import Path

import numpy as np

from addedinertia_env.apps.discovery_dataset import DatasetSpec, simulate_dataset, simulate_pair_dataset
from addedinertia_env.discover.diagnose import discover
from addedinertia_env.discover.pairs import hidden_pair, parse_pair, vocabulary_pairs
from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.records.record import read_record
from addedinertia_env.reports.sections import replace_section

BEGIN, END = "<!-- pair-table:begin -->", "<!-- pair-table:end -->"
QUIRKS_BEGIN, QUIRKS_END = "<!-- pair-table-quirks:begin -->", "<!-- pair-table-quirks:end -->"


def _records(label: str, seed: int, cache: Path | None, make):
    n = len(DatasetSpec().runs)
    if cache is not None:
        folder = cache / f"{label}-{seed}"
        paths = sorted(folder.glob("*.csv"))
        if len(paths) == n:
            return [read_record(p) for p in paths]
        return make(folder)
    return make(None)


def quirky(records, seed: int, label: str = ""):
    """``records`` as a DAQ with two quirks drawn from ``seed`` and ``label`` (the hidden pair:
    each pair of a seed meets its own quirks) would log them, and the quirks."""
    from addedinertia_env.records.daq import apply_quirks, draw_quirks  # noqa: PLC0415

    rng = np.random.default_rng(np.random.SeedSequence([seed, 27, 11, zlib.crc32(label.encode())]))
    quirks = draw_quirks(rng)
    return [apply_quirks(r, quirks, rng) for r in records], quirks.to_dict()


def evaluate(pair: tuple[str, ...], seed: int, cache: Path | None, quirks: bool = False) -> dict:
    """``discover`` on one dataset with ``pair`` hidden (``()``: none); named set, lambda66 errors (truth for scoring only), time."""
    label = "+".join(pair) or "none"
    if pair:
        records = _records(label, seed, cache, lambda out: simulate_pair_dataset(pair, seed, out=out))
        truth_effects = hidden_pair(pair, seed).to_dict()
    else:
        records = _records("none", seed, cache, lambda out: simulate_dataset("none", seed, out=out))
        truth_effects = {}
    q = None
    if quirks:
        records, q = quirky(records, seed, label)
    t0, c0 = time.perf_counter(), time.process_time()
    diag = discover(records)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    truth = records[0].truth_lambda66()  # scoring only
    g = diag.gain()
    named = sorted(diag.causes)
    hidden = sorted(pair)
    return {"pair": label, "seed": seed, "hidden": truth_effects, "quirks": q, "named": named, "cause": diag.cause,
            "exact": named == hidden, "missed": sorted(set(hidden) - set(named)),
            "false_alarm": sorted(set(named) - set(hidden)), "lambda66_true": truth,
            "lambda66_err_nominal": g["lambda66_nominal"] / truth - 1.0,
            "lambda66_err_extended": g["lambda66_extended"] / truth - 1.0,
            "residual_rms_nominal": g["residual_rms_nominal"], "residual_rms_extended": g["residual_rms_extended"],
            "discover_s": wall, "discover_cpu_s": cpu}


def table(rows: list[dict], command: str, wall_s: float, quirks: bool = False) -> str:
    """The marked Markdown block: per pair, exact answers, misses, false alarms, lambda66 errors; totals."""
    pairs = [r for r in rows if r["pair"] != "none"]
    nones = [r for r in rows if r["pair"] == "none"]
    begin, end = (QUIRKS_BEGIN, QUIRKS_END) if quirks else (BEGIN, END)
    lines = [begin, "",
             f"Measured by `{command}` on {machine_line()}; {wall_s / 60:.1f} min in all; `discover` per dataset of "
             f"4 runs: median {np.median([r['discover_s'] for r in rows]):.1f} s wall, "
             f"{np.median([r['discover_cpu_s'] for r in rows]):.1f} s CPU (max {max(r['discover_cpu_s'] for r in rows):.1f} s CPU; "
             "the machine was shared, so wall times are longer than CPU times).", "",
             "| hidden pair | datasets | exact | named (each dataset) | missed | false alarm "
             "| median abs lambda66 error nominal -> extended |",
             "|---|---|---|---|---|---|---|"]
    order = list(dict.fromkeys(r["pair"] for r in rows))
    for label in order:
        rs = [r for r in rows if r["pair"] == label]
        n = len(rs)
        exact = sum(r["exact"] for r in rs)
        named = "; ".join("+".join(r["named"]) or r["cause"] for r in rs)
        missed = sum(bool(r["missed"]) for r in rs)
        fa = sum(bool(r["false_alarm"]) for r in rs)
        en = np.median([abs(r["lambda66_err_nominal"]) for r in rs]) * 100
        ex = np.median([abs(r["lambda66_err_extended"]) for r in rs]) * 100
        lines.append(f"| `{label}` | {n} | **{exact}/{n}** | {named} | {missed}/{n} | {fa}/{n} "
                     f"| {en:.3f} % -> {ex:.3f} % |")
    lines.append("")
    if pairs:
        n = len(pairs)
        lines.append(f"Pairs: exact **{sum(r['exact'] for r in pairs)}/{n}** "
                     f"({100 * np.mean([r['exact'] for r in pairs]):.0f} %); at least one hidden effect missed "
                     f"{sum(bool(r['missed']) for r in pairs)}/{n}; an effect named that was not hidden "
                     f"(false alarm) {sum(bool(r['false_alarm']) for r in pairs)}/{n}.")
    if nones:
        n = len(nones)
        lines.append(f"No effect hidden: `none` named {sum(r['cause'] == 'none' for r in nones)}/{n}, "
                     f"false alarm {sum(bool(r['false_alarm']) for r in nones)}/{n}.")
    if quirks:
        lines += ["", "DAQ quirks per dataset (drawn from the seed): "
                  + "; ".join(f"{r['pair']} seed {r['seed']}: {', '.join(sorted(r['quirks']))}" for r in rows) + "."]
    lines += ["", end]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Regenerate the pair table of docs/DISCOVERY.md (command in the module docstring); returns 0."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1 per pair")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--none-seeds", type=int, default=2, help="datasets with no effect (false alarms)")
    ap.add_argument("--pairs", nargs="*", default=None, help="a+b ... (default: every pair of the vocabulary)")
    ap.add_argument("--quirks", action="store_true", help="log every dataset through two drawn DAQ quirks")
    ap.add_argument("--out", default="docs/DISCOVERY.md")
    ap.add_argument("--jsonl", default="out/pair-table.jsonl", help="one line per dataset")
    ap.add_argument("--cache", default="out/discovery-pairs", help="folder for simulated records ('' = none)")
    args = ap.parse_args(argv)
    pairs = [parse_pair(p) for p in args.pairs] if args.pairs else vocabulary_pairs()
    cache = Path(args.cache) if args.cache else None
    jobs = [(p, s) for s in range(args.first_seed, args.first_seed + args.seeds) for p in pairs]
    jobs += [((), 100 + s) for s in range(args.none_seeds)]
    command = "python -m addedinertia_env.reports.pair_table " + " ".join(sys.argv[1:] if argv is None else argv)
    rows = []
    t0 = time.perf_counter()
    Path(args.jsonl).parent.mkdir(parents=True, exist_ok=True)
    with open(args.jsonl, "w") as f:
        for pair, seed in jobs:
            r = evaluate(pair, seed, cache, quirks=args.quirks)
            rows.append(r)
            f.write(json.dumps(r) + "\n")
            f.flush()
            print(f"{r['pair']} seed {seed}: named {r['named'] or r['cause']} "
                  f"({'exact' if r['exact'] else 'WRONG'}), {r['discover_cpu_s']:.1f} s CPU", flush=True)
    block = table(rows, command.strip(), time.perf_counter() - t0, quirks=args.quirks)
    if args.quirks:
        replace_section(args.out, block, QUIRKS_BEGIN, QUIRKS_END, heading="### The same under DAQ quirks")
    else:
        replace_section(args.out, block, BEGIN, END, heading="## Two effects at once: detection table")
    print(block)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
