"""Are the energy method's 95 % intervals sized to its error? (docs/INTERVALS.md, issue 26).

A calibrated 95 % interval covers the truth in about 95 % of runs, and for a Gaussian error
its half-width ``1.96 sigma`` is about 2.9 times the median absolute error ``0.674 sigma``.
This report measures both, per water, over many simulated hulls and the other labs' records:

    python -m addedinertia_env.reports.interval_calibration run ROWS.jsonl --sets DIR [--seeds 9]
        [--foreign PATH/foreign-lab.tar.xz --foreign PATH/foreign-lab-2.tar.xz]
    python -m addedinertia_env.reports.interval_calibration render ROWS.jsonl [--before OLD.jsonl]
        [--out docs/INTERVALS.md]

``run`` simulates, for each water (``cummins``: radiation memory, ``constant``: none), preset
(``wigley-2m``, ``spheroid-7``) and seed, one hull drawn from the preset by the seed (the
benchmark's scenarios), run by ``lqr`` or ``pd`` (alternating): two reverse-symmetric runs
(the drawn twist and 0.6 of it) and one free decay, into ``DIR`` (kept: a rerun resumes), and identifies
each set as a user would (``identify(records, "energy", memory=True)``); every foreign
case's reverse runs are identified one at a time with the case's free decays beside them.
One JSON line per run goes to ``ROWS`` (labels already there are skipped), with the
truth for scoring only (the simulated record's ``truth``, or the lab's ``answers.json``);
the estimators never see it. ``render`` prints (or writes between the doc's markers) the
table: per water, runs, median |error| against A66(0), median half-width, their ratio, the
median of each run's ``|error| / (half-width / 1.96)`` (``|z|``: 0.674 for calibrated Gaussian
intervals whatever each run's own sigma, where the ratio of the two medians reads 2.9 only when the
runs share one sigma) and the coverage, and with ``--before`` the same for rows made by earlier code.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tarfile
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

PRESETS = ("wigley-2m", "spheroid-7")
WATERS = {"cummins": "memory", "constant": "memory-free"}
CONTROLLERS = ("lqr", "pd")
# The other labs' causes the energy method reads through by itself (the torque scale and the current's lag
# are calibrated on the flywheel; the rotor's dry friction is not the hull's): their cases are memory-free
# water as the method sees it. The other causes bias the model-free balance by design (discovery's job).
ENERGY_TRANSPARENT_CAUSES = {"none", "sensor_delay", "torque_constant", "bearing_coulomb"}
Z95 = 1.959963984540054  # two-sided 95 % point of the normal
CALIBRATED_RATIO = Z95 / 0.6744897501960817  # half-width / median |error| of a calibrated Gaussian interval
BEGIN, END = "<!-- interval-calibration:begin -->", "<!-- interval-calibration:end -->"
COMMAND = ("python -m addedinertia_env.reports.interval_calibration run ROWS-mem.jsonl --sets SETS --seeds 18 "
           "--water cummins \\\n    --foreign PATH/foreign-lab-2.tar.xz\n"
           "python -m addedinertia_env.reports.interval_calibration run ROWS-free.jsonl --sets SETS --seeds 18 "
           "--water constant \\\n    --foreign PATH/foreign-lab.tar.xz --foreign PATH/foreign-lab-2.tar.xz\n"
           "cat ROWS-free.jsonl ROWS-mem.jsonl > ROWS.jsonl\n"
           "python -m addedinertia_env.reports.interval_calibration render ROWS.jsonl --before BEFORE.jsonl "
           "--out docs/INTERVALS.md")


# --- the statistics -------------------------------------------------------------------------------
@dataclass
class Calibration:
    """How a set of runs' 95 % intervals fit their errors (relative numbers: fractions of the truth)."""

    runs: int
    median_abs_error: float
    median_half_width: float
    ratio: float  # median half-width / median |error|; 2.91 for a calibrated Gaussian interval
    covered: int
    coverage: float
    coverage_ci: tuple[float, float]  # 95 % Wilson interval of the coverage over these runs
    median_abs_z: float  # median over runs of |error| / (half-width / 1.96); 0.674 for calibrated Gaussian intervals


def calibration(errors, half_widths) -> Calibration:
    """The calibration of intervals ``value +- half_width`` whose values are off the truth by ``errors``
    (any consistent unit; a run covers when ``|error| <= half_width``). Raises ValueError on empty,
    mismatched or non-finite input."""
    e, h = np.abs(np.asarray(errors, float)), np.asarray(half_widths, float)
    if e.shape != h.shape or e.ndim != 1 or not len(e):
        raise ValueError(f"calibration(): expected two 1-D sequences of the same non-zero length, got {e.shape} "
                         f"and {h.shape}")
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(h)) and np.all(h >= 0)):
        raise ValueError("calibration(): errors and half-widths must be finite, half-widths >= 0")
    n, k = len(e), int(np.sum(e <= h))
    med_e, med_h = float(np.median(e)), float(np.median(h))
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero half-width: z infinite (or 0 for a zero error)
        z = np.where(h > 0, Z95 * e / np.where(h > 0, h, 1.0), np.where(e > 0, math.inf, 0.0))
    return Calibration(n, med_e, med_h, med_h / med_e if med_e > 0 else math.inf, k, k / n, wilson(k, n),
                       float(np.median(z)))


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson's 95 % score interval of a proportion ``k / n``."""
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, mid - half), min(1.0, mid + half)


# --- the runs -------------------------------------------------------------------------------------
def hull_specs(seeds: int) -> list[dict]:
    """Every simulated hull: water x preset x seed (1..``seeds``), the controller alternating with the seed.

    Each seed draws its own hull from the preset (:func:`~addedinertia_env.experiment.scenarios.make_scenario`:
    lambda66 / J_hull, period, damping, flywheel, torque constant, twist, hold, sensor quality). A preset's
    fixed hull would not do: its seeds redraw the sensor noise but not the passive free stroke, whose
    encoder quantisation pattern (the energy method's largest error) is then the same in every run."""
    return [{"preset": p, "hydrodynamics": h, "controller": CONTROLLERS[s % len(CONTROLLERS)], "seed": s}
            for h in WATERS for p in PRESETS for s in range(1, seeds + 1)]


def label_of(spec: dict) -> str:
    """A simulated set's row label: water (cummins or constant added inertia), preset, controller, hull seed."""
    return f"{'cum' if spec['hydrodynamics'] == 'cummins' else 'con'}-{spec['preset']}-{spec['controller']}-h{spec['seed']}"


def simulate_set(spec: dict, root: Path) -> list[Path]:
    """The records of one drawn hull under ``root`` (kept when already there): two reverse runs (the
    scenario's twist and 0.6 of it) and one free decay, each with its own sensor noise."""
    import dataclasses  # noqa: PLC0415

    from addedinertia_env.apps.simulate import simulate_to_dir  # noqa: PLC0415
    from addedinertia_env.experiment.scenarios import make_scenario  # noqa: PLC0415

    sc = make_scenario(spec["seed"], spec["preset"], hydrodynamics=spec["hydrodynamics"])
    base = root / spec["hydrodynamics"] / spec["preset"] / f"h{spec['seed']}"
    n = 1000 * spec["seed"]
    alpha = sc.plan.alpha
    jobs = [(base / "rev-a", "reverse-symmetric", sc.plan, n + 1),
            (base / "rev-b", "reverse-symmetric", dataclasses.replace(sc.plan, alpha=0.6 * alpha), n + 2),
            (base / "decay", "free-decay", sc.plan, n + 3)]
    paths = []
    for out, kind, plan, seed in jobs:
        signature = {"rig": spec["preset"], "scenario_seed": spec["seed"], "hydrodynamics": spec["hydrodynamics"],
                     "kind": kind, "alpha": plan.alpha, "seed": seed, "controller": spec["controller"]}
        paths += simulate_to_dir(sc.rig, out, controller=spec["controller"], plan=plan, seed=seed, kind=kind,
                                 signature=signature)
    return paths


def identify_row(label: str, water: str, files: list[Path], truth: dict | None) -> dict:
    """One run: ``identify(records, "energy", memory=True)`` on ``files`` and the truth beside it (scoring only)."""
    from addedinertia_env.identify import identify  # noqa: PLC0415
    from addedinertia_env.records.record import read_record  # noqa: PLC0415

    recs = [read_record(f) for f in files]
    if truth is None:
        t = next((r.meta.get("truth") for r in recs if r.meta.get("truth")), None) or {}
        truth = {k: t.get(k) for k in ("lambda66", "A66_swing", "A66_inf")}
    t0 = time.process_time()
    try:
        res = identify(recs, "energy", memory=True).to_json()
        res.pop("sampling", None)
        res.get("details", {}).pop("intervals", None)
    except Exception as e:  # noqa: BLE001 - a refusal is a row too
        res = {"error": f"{type(e).__name__}: {e}"}
    return {"label": label, "water": water, "files": [str(f) for f in files], "cpu_s": time.process_time() - t0,
            "result": res, "truth": truth}


def lab_reverse_runs(archive: Path):
    """Each reverse run of each case of a lab's archive (extracted to a temporary folder for the time of the
    iteration), as ``(case folder, reverse run's CSV, that case's free decays' CSVs, the case's answers)``; the
    answers are read to score only."""
    with tempfile.TemporaryDirectory() as tmp:
        with tarfile.open(archive) as tar:
            tar.extractall(tmp, filter="data")
        answers_path = next(Path(tmp).rglob("answers.json"))
        answers = json.loads(answers_path.read_text())
        answers = answers.get("cases", answers)
        for case in sorted(p for p in answers_path.parent.iterdir() if p.is_dir()):
            runs = sorted(case.glob("*.csv"))
            kinds = {p: json.loads(p.with_suffix(".json").read_text())["experiment"]["kind"] for p in runs}
            decays = [p for p in runs if kinds[p] == "free-decay"]
            for p in runs:
                if kinds[p] == "reverse-symmetric":
                    yield case, p, decays, answers[case.name]


def memory_runs(sets: Path, seeds: int, foreign: list[str], first: int = 1):
    """``(label, files, A66(0))`` of every memory run the table counts, for the studies that rebuild its widths
    (scripts/memory_width_study.py, scripts/interval_parts_study.py): the drawn hulls' kept sets under ``sets``
    (seeds ``first`` to ``seeds``, each preset; a set not simulated yet is skipped), then each memory case's reverse
    runs of each lab archive in ``foreign`` with the case's free decays; labels as the table's rows. A66(0) is read
    from the records' truth or the lab's answers, to score only."""
    from addedinertia_env.records.record import read_record  # noqa: PLC0415

    for preset in PRESETS:
        for s in range(first, seeds + 1):
            base = sets / "cummins" / preset / f"h{s}"
            files = [base / "rev-a" / "run-0000.csv", base / "rev-b" / "run-0000.csv", base / "decay" / "run-0000.csv"]
            if all(f.exists() for f in files):
                yield f"cum-{preset}-h{s}", files, read_record(files[0]).meta["truth"]["lambda66"]
    for archive in foreign:
        for case, p, decays, a in lab_reverse_runs(Path(archive)):
            if a.get("A66_inf") is not None:
                yield f"{Path(archive).name.split('.')[0]}-{case.name}-{p.stem}", [p, *decays], a["lambda66"]


def foreign_rows(archive: Path, done: set[str]):
    """Rows of a lab's archive: each reverse run of each case with that case's free decays beside it."""
    lab = archive.name.split(".")[0]
    for case, p, decays, a in lab_reverse_runs(archive):
        memory = a.get("A66_inf") is not None
        water = "memory" if memory else "memory-free"
        truth = {"lambda66": a["lambda66"], "A66_swing": a.get("A66_swing"), "A66_inf": a.get("A66_inf"),
                 "cause": a["cause"]}
        label = f"{lab}-{case.name}-{p.stem}"
        if label in done:
            continue
        row = identify_row(label, water, [p, *decays], truth)
        row["files"] = [f"{lab}/{case.name}/{Path(f).name}" for f in row["files"]]
        yield row


def run(rows_path: str, sets: str, seeds: int, foreign: list[str], waters: tuple[str, ...] = tuple(WATERS)) -> None:
    """Append one row per run not yet in ``rows_path`` (simulating the hull sets under ``sets`` as needed)."""
    done = set()
    Path(rows_path).parent.mkdir(parents=True, exist_ok=True)
    if Path(rows_path).exists():
        done = {json.loads(line)["label"] for line in Path(rows_path).read_text().splitlines() if line.strip()}
    from addedinertia_env.foundation.machine import machine_line  # noqa: PLC0415

    with open(rows_path, "a") as out:
        def put(row):
            row["machine"] = machine_line()
            out.write(json.dumps(row) + "\n")
            out.flush()
            res = row["result"]
            print(row["label"], f"{row['cpu_s']:.1f} s", res.get("lambda66"), res.get("ci95"),
                  res.get("details", {}).get("memory", res.get("error")), file=sys.stderr)

        for spec in hull_specs(seeds):
            label = label_of(spec)
            if label in done or spec["hydrodynamics"] not in waters:
                continue
            t0 = time.process_time()
            files = simulate_set(spec, Path(sets))
            row = identify_row(label, WATERS[spec["hydrodynamics"]], files, None)
            row["simulate_cpu_s"] = time.process_time() - t0 - row["cpu_s"]
            put(row)
        for archive in foreign:
            for row in foreign_rows(Path(archive), done):
                put(row)


# --- the table ------------------------------------------------------------------------------------
def group_of(row: dict) -> str | None:
    """The table's group of a row: ``memory``, ``memory-free`` (own presets and the labs' cases the energy
    method reads through), or None for a lab's case with a cause that biases the balance by design."""
    cause = (row.get("truth") or {}).get("cause")
    if row["water"] == "memory-free" and cause is not None and cause not in ENERGY_TRANSPARENT_CAUSES:
        return None
    return row["water"]


def scored(rows: list[dict]) -> dict[str, list[tuple[str, float, float]]]:
    """Per group and subgroup: (label, relative error, relative half-width) of every row that gave an estimate."""
    out: dict[str, list] = {}
    for r in rows:
        g = group_of(r)
        res, t = r["result"], r.get("truth") or {}
        if g is None or "error" in res or not t.get("lambda66"):
            continue
        a0 = t["lambda66"]
        lo, hi = res["ci95"]
        err = res["lambda66"] / a0 - 1
        half = 0.5 * (hi - lo) / a0
        sub = r["label"].rsplit("-", 2)[0] if r["label"].startswith(("cum-", "con-")) else r["label"].split("-case")[0]
        sub = sub.replace("cum-", "").replace("con-", "")
        for key in (g, f"{g}: {sub}"):
            out.setdefault(key, []).append((r["label"], err, half))
    return out


def _pct(x: float, digits: int = 3) -> str:
    return f"{100 * x:.{digits}f} %"


def table(rows: list[dict], before: list[dict] | None = None) -> str:
    """The Markdown table of :func:`calibration` per water (and per subgroup), with earlier rows beside."""
    now, old = scored(rows), scored(before) if before else {}
    head = ("| water | runs | median abs error | median half-width | ratio (2.9 calibrated) | median \\|z\\| "
            "(0.67 calibrated) | covered | coverage (95 % CI) |")
    lines = [head, "|---|---|---|---|---|---|---|---|"]
    refused = sum(1 for r in rows if "error" in r["result"])
    for key in sorted(now, key=lambda k: (":" in k, k)):
        c = calibration([e for _, e, _ in now[key]], [h for _, _, h in now[key]])
        name = f"**{key}**" if ":" not in key else key
        cell = (f"| {name} | {c.runs} | {_pct(c.median_abs_error)} | {_pct(c.median_half_width)} | {c.ratio:.1f} | "
                f"{c.median_abs_z:.2f} | {c.covered}/{c.runs} | {100 * c.coverage:.0f} % ({100 * c.coverage_ci[0]:.0f}-"
                f"{100 * c.coverage_ci[1]:.0f} %) |")
        if key in old:
            b = calibration([e for _, e, _ in old[key]], [h for _, _, h in old[key]])
            cell += (f" before: {_pct(b.median_abs_error)}, {_pct(b.median_half_width)}, ratio {b.ratio:.1f}, "
                     f"\\|z\\| {b.median_abs_z:.2f}, {b.covered}/{b.runs} |")
        lines.append(cell)
    if before:
        lines[0] += " before (median abs error, half-width, ratio, median \\|z\\|, covered) |"
        lines[1] += "---|"
        cells = lambda ln: ln.count("|") - ln.count("\\|")  # an escaped pipe is text, not a cell's edge
        lines = [ln if cells(ln) == cells(lines[0]) else ln + " - |" for ln in lines]
    cpu = [r["cpu_s"] for r in rows]
    note = (f"\n{len(rows)} runs, {refused} refused (their reasons are in the rows); identify: median "
            f"{statistics.median(cpu):.1f} CPU-s per run" if cpu else "")
    left = {}
    for r in rows:
        if group_of(r) is None and "error" not in r["result"]:
            a0 = r["truth"]["lambda66"]
            lo, hi = r["result"]["ci95"]
            e = r["result"]["lambda66"] / a0 - 1
            left.setdefault(r["truth"]["cause"], []).append((e, lo <= a0 <= hi))
    if left:
        note += ("\n\nLeft out (another lab's hidden effects that bias the model-free balance by design; `discover` "
                 "names them): " + "; ".join(f"`{c}` {len(v)} runs, errors {min(x for x, _ in v) * 100:+.2f} to "
                                           f"{max(x for x, _ in v) * 100:+.2f} %, covered {sum(k for _, k in v)}"
                                           for c, v in sorted(left.items())) + ".")
    return "\n".join(lines) + note + "\n"


def render(rows_path: str, before_path: str | None, out: str | None, command: str) -> str:
    """The calibration table (runs, median |error|, median half-width, their ratio, coverage per water)
    from the newest row of each set in ``rows_path``, beside ``before_path``'s; written between the
    markers of ``out`` when given, and returned."""
    rows = _latest(rows_path)
    before = _latest(before_path) if before_path else None
    machine = rows[0].get("machine", "unknown machine") if rows else "no rows"
    block = (f"{BEGIN}\n\nMade with:\n\n```\n{command}\n```\n\non {machine}.\n\n{table(rows, before)}\n{END}\n")
    if out:
        from addedinertia_env.reports.sections import replace_section  # noqa: PLC0415

        replace_section(out, block, BEGIN, END)
    return block


def _latest(path: str) -> list[dict]:
    rows: dict[str, dict] = {}
    for line in Path(path).read_text().splitlines():
        if line.strip():
            r = json.loads(line)
            rows[r["label"]] = r  # a rerun's row wins
    return list(rows.values())


def main(argv: list[str] | None = None) -> int:
    """Command line: ``run ROWS --sets DIR ...`` or ``render ROWS ...``; returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("rows")
    r.add_argument("--sets", required=True, help="folder for the simulated records (kept; a rerun resumes)")
    r.add_argument("--seeds", type=int, default=18, help="drawn hulls per preset and water")
    r.add_argument("--foreign", action="append", default=[], metavar="ARCHIVE.tar.xz")
    r.add_argument("--water", action="append", choices=list(WATERS), default=None,
                   help="only this simulated water (repeatable; default: both)")
    d = sub.add_parser("render")
    d.add_argument("rows")
    d.add_argument("--before", default=None, help="rows made by earlier code, for the before column")
    d.add_argument("--out", default=None, help="doc to write the block into (between its markers)")
    d.add_argument("--command", default=COMMAND, help="the command line the doc names")
    args = ap.parse_args(argv)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if args.cmd == "run":
        if args.seeds < 1:
            print(f"--seeds {args.seeds}: expected at least 1", file=sys.stderr)
            return 2
        run(args.rows, args.sets, args.seeds, args.foreign, tuple(args.water or WATERS))
    else:
        print(render(args.rows, args.before, args.out, args.command))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
