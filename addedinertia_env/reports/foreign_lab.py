"""The other lab's development set in docs/DISCOVERY.md: cause, lambda66, interval, time, per case.

    python -m addedinertia_env.reports.foreign_lab --data PATH/foreign-lab.tar.xz --out docs/DISCOVERY.md

(``make foreign-lab-table``.) The archive is unpacked into a temporary folder; for every
case (one hull: three free decays and three reverse-symmetric runs) it runs, blind:

* ``discover`` on all six runs together (free decays and reverse runs, one parameter set);
* ``identify --method whole-record`` on the three reverse runs, the model extended by the
  cause(s) ``discover`` named (nominal for ``none``/``unexplained``);
* ``identify --method energy`` on each reverse run (the model-free method).

Only the scoring columns read ``answers.json``. The table replaces the block between
``<!-- foreign-lab-table:begin -->`` and ``<!-- foreign-lab-table:end -->`` of ``--out``.
"""

from __future__ import annotations

import argparse
import json
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

from addedinertia_env.discover import discover
from addedinertia_env.identify import identify
from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.records.record import read_record
from addedinertia_env.reports.sections import replace_section

BEGIN, END = "<!-- foreign-lab-table:begin -->", "<!-- foreign-lab-table:end -->"
COMMAND = "python -m addedinertia_env.reports.foreign_lab --data PATH/foreign-lab.tar.xz --out docs/DISCOVERY.md"


def evaluate_case(folder: Path) -> dict:
    """Everything blind on one case folder; returns the estimates (no truth read here)."""
    records = [read_record(p) for p in sorted(folder.glob("*.csv"))]
    t0 = time.perf_counter()
    diag = discover(records)
    t1 = time.perf_counter()
    reverse = [r for r in records if r.experiment["kind"] == "reverse-symmetric"]
    effect = "+".join(diag.causes) or None
    wr = identify(reverse, "whole-record", effect=effect)
    t2 = time.perf_counter()
    energy = [identify([r], "energy").lambda66 for r in reverse]
    g = diag.gain()
    return {"case": folder.name, "cause": diag.cause, "causes": diag.causes,
            "skipped": diag.data.skipped,
            "current_sampling": diag.data.current_mode_report.get("used"),
            "lambda66_nominal": g["lambda66_nominal"], "lambda66_extended": g["lambda66_extended"],
            "whole_record": wr.lambda66, "ci95": list(wr.ci95), "crb": wr.details["crb"],
            "interval_kind": wr.details["interval"], "adequate": wr.details["adequate"],
            "energy": energy, "discover_s": t1 - t0, "whole_record_s": t2 - t1}


def markers(archive: str | Path) -> tuple[str, str]:
    """The doc markers of a lab's table, from its archive's name (``foreign-lab.tar.xz`` -> ``foreign-lab-table``)."""
    stem = Path(archive).name.split(".")[0]
    return f"<!-- {stem}-table:begin -->", f"<!-- {stem}-table:end -->"


def named_right(row: dict, answer: dict) -> bool:
    """Whether every cause of the lab's answer was named, and nothing else."""
    named = row["causes"] or [row["cause"]]
    return sorted(named) == sorted(answer["cause"].split("+"))


def table(rows: list[dict], answers: dict, wall_s: float, command: str = COMMAND,
          begin: str = BEGIN, end: str = END) -> str:
    """The marked Markdown block of the foreign-lab cases: named cause, lambda66 errors (% of the lab's answer), interval coverage, time."""
    lines = [begin, "",
             f"Measured by `{command}` on {machine_line()}; {wall_s / 60:.1f} min in all. "
             "lambda66 errors are against the lab's `answers.json` (read for scoring only). "
             "whole-record: the three reverse runs, the model extended by the named cause(s); "
             "interval = 95 %, its half-width and the Cramer-Rao bound as % of lambda66. "
             "energy: median over the three reverse runs.", "",
             "| case | true cause | named (`causes`) | skipped | current read as | lambda66 nominal | lambda66 extended "
             "| whole-record (half-width, CRB) | covers | energy | discover time |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    hits = covers = 0
    wr_err, en_err = [], []
    for r in rows:
        a = answers[r["case"]]
        truth = a["lambda66"]
        err = lambda x: 100.0 * (x / truth - 1.0)  # noqa: E731
        lo, hi = r["ci95"]
        cover = lo <= truth <= hi
        hits += named_right(r, a)
        covers += cover
        wr_err.append(abs(err(r["whole_record"])))
        e = float(np.median([err(x) for x in r["energy"]]))
        en_err.append(abs(e))
        named = " + ".join(f"`{c}`" for c in r["causes"]) or f"`{r['cause']}`"
        lines.append(f"| {r['case']} | `{a['cause']}` | {named} | {len(r['skipped'])} | {r['current_sampling']} "
                     f"| {err(r['lambda66_nominal']):+.3f} % | {err(r['lambda66_extended']):+.4f} % "
                     f"| {err(r['whole_record']):+.4f} % (+-{100 * (hi - lo) / 2 / truth:.3f} %, "
                     f"CRB {100 * r['crb'] / truth:.4f} %) | {'yes' if cover else '**no**'} | {e:+.3f} % "
                     f"| {r['discover_s']:.0f} s |")
    lines += ["", f"Named right: **{hits}/{len(rows)}**; whole-record within 0.05 %: "
              f"{sum(x < 0.05 for x in wr_err)}/{len(rows)} (median {np.median(wr_err):.4f} %), interval covers "
              f"{covers}/{len(rows)}; energy method median abs error {np.median(en_err):.3f} % "
              "(per case medians; the energy method is model-free, so an effect such as fluid memory or a "
              "torque-constant error biases it where the extended gray-box model does not).", "", end]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Regenerate ``the foreign-lab table of docs/DISCOVERY.md`` (the command is in the module docstring; ``--data`` is the lab's archive); ``argv`` as on the command line; returns 0."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, metavar="PATH",
                    help="the lab's archive (.tar.xz; the developers' foreign-lab.tar.xz development set)")
    ap.add_argument("--out", default="docs/DISCOVERY.md")
    ap.add_argument("--jsonl", default="out/foreign-lab.jsonl", help="one line per case")
    ap.add_argument("--cases", nargs="*", default=None, help="only these case folders")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        with tarfile.open(args.data) as tar:
            tar.extractall(tmp, filter="data")
        root = next(Path(tmp).rglob("answers.json")).parent
        answers = json.loads((root / "answers.json").read_text())
        answers = answers.get("cases", answers)
        Path(args.jsonl).parent.mkdir(parents=True, exist_ok=True)
        with open(args.jsonl, "w") as f:
            for folder in sorted(p for p in root.iterdir() if p.is_dir()):
                if args.cases and folder.name not in args.cases:
                    continue
                row = evaluate_case(folder)
                rows.append(row)
                f.write(json.dumps(row) + "\n")
                f.flush()
                print(f"{row['case']}: {row['cause']} ({row['discover_s']:.0f} s)", flush=True)
    begin, end = markers(args.data)
    command = f"python -m addedinertia_env.reports.foreign_lab --data {args.data} --out {args.out}"
    block = table(rows, answers, time.perf_counter() - t0, command, begin, end)
    replace_section(args.out, block, begin, end, heading=f"### {Path(args.data).name.split('.')[0]}")
    print(block)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
