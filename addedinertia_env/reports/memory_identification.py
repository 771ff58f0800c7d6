"""Figures of docs/RADIATION_MEMORY.md, "Identified from the rig's own records".

Two steps, so that the slow one can run where the CPU is:

    python -m addedinertia_env.reports.memory_identification run ROWS.jsonl LABEL=GLOB ...
    python -m addedinertia_env.reports.memory_identification run-whole-record ROWS.jsonl LABEL=GLOB ...
    python -m addedinertia_env.reports.memory_identification render ROWS.jsonl [--answers PREFIX=answers.json ...]

``run`` identifies each hull's records together (``identify(records, "energy", memory=True)``:
free decays beside reverse runs) and appends one JSON line per hull with the result and,
for scoring only, the simulated truth (``lambda66`` = A66(0), ``A66_swing``, ``A66_inf``).
``render`` prints the markdown tables: errors before (the energy balance alone) and after
(memory identified and corrected), A66(inf), interval coverage and half-width / |error|.
Labels group rows: the text before the last ``-`` (``cum-wigley-2m-s3`` -> ``cum-wigley-2m``).
Foreign-lab truth comes from an ``answers.json`` given with ``--answers fl2=PATH`` (rows
labelled ``fl2-NN`` read ``case-NN``); it is read here to score, never by the estimators.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import statistics
import sys
import time
from pathlib import Path


def run(rows_path: str, specs: list[str]) -> None:
    """Identify each record set of ``specs`` with and without the memory step and append one JSON row per
    set to ``rows_path`` (a resumable log of the table's raw numbers)."""
    from addedinertia_env.identify import identify  # noqa: PLC0415
    from addedinertia_env.records.record import read_record  # noqa: PLC0415

    with open(rows_path, "a") as out:
        for spec in specs:
            label, _, pattern = spec.partition("=")
            files = sorted(glob.glob(pattern))
            recs = [read_record(f) for f in files]
            t0 = time.process_time()
            try:
                res = identify(recs, "energy", memory=True).to_json()
                res.pop("sampling", None)
            except Exception as e:  # noqa: BLE001 - a refusal is a row too
                res = {"error": f"{type(e).__name__}: {e}"}
            truth = recs[0].meta.get("truth") if recs else None
            row = {"label": label, "files": files, "cpu_s": time.process_time() - t0, "result": res,
                   "truth": {k: truth.get(k) for k in ("lambda66", "A66_swing", "A66_inf")} if truth else None}
            out.write(json.dumps(row) + "\n")
            out.flush()
            print(label, round(row["cpu_s"], 1), res.get("lambda66"), res.get("memory"), file=sys.stderr)


def run_whole_record(rows_path: str, specs: list[str]) -> None:
    """The whole-record method on each record set of ``specs``, without the memory state (``memory="off"``)
    and with it (the default); one JSON row per set (``"method": "whole-record"``) appended to ``rows_path``."""
    from addedinertia_env.identify import identify  # noqa: PLC0415
    from addedinertia_env.records.record import read_record  # noqa: PLC0415

    keep = ("memory", "A66_inf", "verdict", "residual_excess", "adequate")
    with open(rows_path, "a") as out:
        for spec in specs:
            label, _, pattern = spec.partition("=")
            files = sorted(glob.glob(pattern))
            recs = [read_record(f) for f in files]
            row = {"label": label, "method": "whole-record", "files": files}
            for mode in ("off", "auto"):
                t0 = time.process_time()
                try:
                    res = identify(recs, "whole-record", memory=mode)
                    row[mode] = {"lambda66": res.lambda66, "ci95": list(res.ci95),
                                 **{k: res.details.get(k) for k in keep}}
                except Exception as e:  # noqa: BLE001 - a refusal is a row too
                    row[mode] = {"error": f"{type(e).__name__}: {e}"}
                row[mode]["cpu_s"] = time.process_time() - t0
            truth = recs[0].meta.get("truth") if recs else None
            row["truth"] = {k: truth.get(k) for k in ("lambda66", "A66_swing", "A66_inf")} if truth else None
            out.write(json.dumps(row) + "\n")
            out.flush()
            print(label, row["off"].get("lambda66"), row["auto"].get("lambda66"), row["auto"].get("memory"),
                  file=sys.stderr)


def render_whole_record(rows: list[dict], answers: dict[str, dict]) -> str:
    """The whole-record method's lambda66 without and with the memory state, per hull (Markdown)."""
    lines = ["| hull | water | memory found | lambda66 true (A66(0)) | without the memory state | with it | "
             "interval covers (with) | residual / noise floor (without -> with) | A66(inf) (with) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        t = _truth(r, answers)
        off, on = r["off"], r["auto"]
        if t is None or "error" in off or "error" in on:
            lines.append(f"| {r['label']} | - | {on.get('error') or off.get('error') or 'no truth'} | | | | | | |")
            continue
        a0 = t["lambda66"]
        memory_water = t.get("A66_inf") is not None
        lo, hi = on["ci95"]
        e_inf = on["A66_inf"] / t["A66_inf"] - 1 if memory_water and on.get("A66_inf") is not None else None
        lines.append(f"| {r['label']} | {'memory' if memory_water else 'memory-free'} | {on.get('memory')} | {a0:.4f} | "
                     f"{_pct(off['lambda66'] / a0 - 1)} | {_pct(on['lambda66'] / a0 - 1)} | "
                     f"{'yes' if lo <= a0 <= hi else 'no'} | {off.get('residual_excess', 0):.1f} -> "
                     f"{on.get('residual_excess', 0):.1f} | {_pct(e_inf, '+.1f')} |")
    return "\n".join(lines) + "\n"


def _truth(row: dict, answers: dict[str, dict]) -> dict | None:
    if row.get("truth"):
        return row["truth"]
    prefix, _, case = row["label"].rpartition("-")
    a = answers.get(prefix, {}).get(f"case-{case}")
    if a is None:
        return None
    return {"lambda66": a["lambda66"], "A66_swing": a.get("A66_swing"), "A66_inf": a.get("A66_inf"),
            "cause": a.get("cause")}


def _pct(x: float | None, fmt: str = "+.3f") -> str:
    return "-" if x is None else f"{100 * x:{fmt}} %"


def render(rows_path: str, answers_specs: list[str]) -> str:
    """The Markdown table of lambda66 before and after the memory correction from the rows of :func:`run`,
    scored against the answers (``PREFIX=answers.json``) or the records' truth."""
    answers = {}
    for spec in answers_specs:
        prefix, _, path = spec.partition("=")
        data = json.loads(Path(path).read_text())
        answers[prefix] = data.get("cases", data)
    rows = [json.loads(line) for line in Path(rows_path).read_text().splitlines() if line.strip()]
    whole = {r["label"]: r for r in rows if r.get("method") == "whole-record"}
    rows = [r for r in rows if r.get("method") != "whole-record"]
    seen = {}
    for r in rows:  # the last row of a label wins (a rerun)
        seen[r["label"]] = r
    lines = ["| hull | water | memory found | lambda66 true (A66(0)) | before | after | memory fit A66(0) | "
             "A66(inf) | 95 % interval covers | half-width / abs error | CPU s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    groups: dict[str, list] = {}
    for label, r in seen.items():
        t = _truth(r, answers)
        res = r["result"]
        if t is None or "error" in res:
            lines.append(f"| {label} | - | {res.get('error', 'no truth')} | | | | | | | | |")
            continue
        a0 = t["lambda66"]
        memory_water = t.get("A66_inf") is not None
        before = res.get("lambda66_uncorrected", res["lambda66"])
        after, ci_after = res["lambda66"], res["ci95"]
        if "lambda66_uncorrected" in res and "lambda66_energy_corrected" not in res:
            # a row made before identify combined the two estimates: the same function on its pieces
            from addedinertia_env.identify.memory_energy import combine  # noqa: PLC0415

            after, ci_after = combine(res["A66_zero_memory_fit"], res["A66_zero_memory_fit_ci95"])
        e_b, e_a = before / a0 - 1, after / a0 - 1
        fit0 = res.get("A66_zero_memory_fit")
        e_f = fit0 / a0 - 1 if fit0 is not None else None
        e_inf = res["A66_inf"] / t["A66_inf"] - 1 if memory_water and res.get("A66_inf") is not None else None
        lo, hi = ci_after
        covers = lo <= a0 <= hi
        ratio = 0.5 * (hi - lo) / abs(after - a0) if after != a0 else float("inf")
        lines.append(f"| {label} | {'memory' if memory_water else 'memory-free'} | {res.get('memory')} | {a0:.4f} | "
                     f"{_pct(e_b)} | {_pct(e_a)} | {_pct(e_f)} | {_pct(e_inf, '+.1f')} | {'yes' if covers else 'no'} | "
                     f"{ratio:.1f} | {r['cpu_s']:.0f} |")
        groups.setdefault((label.rpartition("-")[0], "memory" if memory_water else "memory-free"), []).append((e_b, e_a, e_f, e_inf, covers, 0.5 * (hi - lo) / a0))
    summary = ["| group | water | hulls | median abs error before | median abs error after | median abs error, memory fit | "
               "median abs error A66(inf) | covered | median half-width / median abs error |",
               "|---|---|---|---|---|---|---|---|---|"]
    for g, v in groups.items():
        med = statistics.median
        eb, ea = med(abs(x[0]) for x in v), med(abs(x[1]) for x in v)
        ef = [abs(x[2]) for x in v if x[2] is not None]
        ei = [abs(x[3]) for x in v if x[3] is not None]
        cov = sum(x[4] for x in v)
        hw = med(x[5] for x in v)
        summary.append(f"| {g[0]} | {g[1]} | {len(v)} | {_pct(eb, '.3f')} | {_pct(ea, '.3f')} | "
                       f"{_pct(med(ef), '.3f') if ef else '-'} | {_pct(med(ei), '.1f') if ei else '-'} | "
                       f"{cov}/{len(v)} | {hw / ea if ea > 0 else float('inf'):.1f} |")
    out = "\n".join(summary) + "\n\nPer hull:\n\n" + "\n".join(lines) + "\n"
    if whole:
        out += "\nThe whole-record method (``run-whole-record``), without and with the memory state:\n\n"
        out += render_whole_record(list(whole.values()), answers)
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line: ``run ROWS SPEC...`` or ``render ROWS [--answers PREFIX=FILE]``; returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("rows")
    r.add_argument("specs", nargs="+", metavar="LABEL=GLOB")
    w = sub.add_parser("run-whole-record")
    w.add_argument("rows")
    w.add_argument("specs", nargs="+", metavar="LABEL=GLOB")
    d = sub.add_parser("render")
    d.add_argument("rows")
    d.add_argument("--answers", action="append", default=[], metavar="PREFIX=answers.json")
    args = ap.parse_args(argv)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if args.cmd == "run":
        run(args.rows, args.specs)
    elif args.cmd == "run-whole-record":
        run_whole_record(args.rows, args.specs)
    else:
        print(render(args.rows, args.answers))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
