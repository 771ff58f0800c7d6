"""Which part of lambda66's interval budget makes it conservative per run? (docs/INTERVALS.md, issue 26)

Two halves.

``rows ROWS-free.jsonl``: the memory-free rows of ``interval_calibration run`` carry each reverse run's value,
1-sigma and its parts (``details.per_run``, ``per_run_sigma``, ``per_run_sigma_parts``). The row's interval is
rebuilt from them as ``identify`` builds it (the runs' inverse-variance mean, widened by the Birge ratio,
``identify/common.pooled_interval``; checked against the row's ``ci95``), then again under each rule: one part
left out of every run's sigma, or the Birge widening left out. Each rule's median per-row ``|z|`` (``z = error /
(half-width / 1.96)``) and coverage are printed per group.

``memory --sets SETS [--foreign PATH/foreign-lab-2.tar.xz]``: for water with memory the rows keep only the
reported interval, so each run's memory fit is made again (``identify/memory.identify_memory``, about 10 CPU-s a
run) and its A66(0) interval split into what holds it: the families' Akaike mixture, the reported family's
stratified jackknife ``t(dof) x sd_J``, and the fit's resolution; each alone is scored like the rules above.

``reference``: what median |z| a *coverage-calibrated* interval gives when its sigma is estimated with few degrees
of freedom (Monte Carlo, exact budget): Student's t with 1-4 dof, and the Birge widening of two runs. The 0.674
of the table is for a known sigma; an interval whose width is read from the data with few degrees of freedom is
wider in the median at the same coverage.

The truth (rows' ``truth``, the labs' ``answers.json``) is read to score only.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

Z95 = 1.959963984540054
PARTS = ("rate", "current", "common", "trend")  # slope_noise is kg m^2 per rad, not a part of the sigma


def _groups(label: str, water: str, cause: str | None) -> list[str]:
    from addedinertia_env.reports.interval_calibration import ENERGY_TRANSPARENT_CAUSES  # noqa: PLC0415

    if water == "memory-free" and cause is not None and cause not in ENERGY_TRANSPARENT_CAUSES:
        return []
    if label.startswith(("cum-", "con-")):
        sub = label.rsplit("-", 2)[0][4:]
        seed = int(label.rsplit("-h", 1)[1])
        held = "held-out h14-h18" if seed >= 14 else "chosen-on h1-h13+labs"
    else:
        sub, held = label.split("-case")[0], "chosen-on h1-h13+labs"
    return [water, f"{water}: {sub}", f"{water}: {held}"]


def pooled_half(values, sigmas, birge: bool = True) -> float:
    """The half-width of ``identify/common.pooled_interval`` (kg m^2), optionally without the Birge widening."""
    v, s = np.asarray(values, float), np.maximum(np.asarray(sigmas, float), 1e-300)
    w = 1.0 / s**2
    sigma = math.sqrt(1.0 / w.sum())
    if birge and len(v) > 1:
        mean = float(np.sum(w * v) / w.sum())
        sigma *= math.sqrt(max(float(np.sum(w * (v - mean) ** 2)) / (len(v) - 1), 1.0))
    return 1.96 * sigma  # pooled_interval's z


def _print_table(title: str, scores: dict[str, dict[str, list[float]]], rules: list[str]) -> None:
    print(f"\n{title}")
    print("| group | runs | " + " | ".join(rules) + " |")
    print("|---|---|" + "---|" * len(rules))
    for g in sorted(scores, key=lambda k: (k.count(":"), k)):
        n = len(scores[g][rules[0]])
        cells = []
        for r in rules:
            z = np.abs(np.array(scores[g][r]))
            cells.append(f"{np.median(z):.2f}, {int(np.sum(z <= Z95))}/{n}")
        print(f"| {g} | {n} | " + " | ".join(cells) + " |")


def rows_study(path: str) -> None:
    rows = {}
    for line in Path(path).read_text().splitlines():
        if line.strip():
            r = json.loads(line)
            rows[r["label"]] = r  # a rerun's row wins, as interval_calibration's render
    rules = ["reported", "no Birge"] + [f"no {p}" for p in PARTS]
    scores: dict[str, dict[str, list[float]]] = {}
    largest: dict[str, int] = {}
    birge_fired, n_pooled = [], 0
    chi2_pairs: list[tuple[float, str]] = []
    single: dict[str, list[float]] = {}
    for r in rows.values():
        res, truth = r["result"], r.get("truth") or {}
        groups = _groups(r["label"], r["water"], truth.get("cause"))
        if not groups or "per_run" not in res or not truth.get("lambda66") or res.get("memory", "none") != "none":
            continue
        a0, v, s = truth["lambda66"], res["per_run"], res["per_run_sigma"]
        parts = res["per_run_sigma_parts"]
        half = 0.5 * (res["ci95"][1] - res["ci95"][0])
        rebuilt = pooled_half(v, s)
        if abs(rebuilt / half - 1) > 1e-6:
            raise SystemExit(f"{path}: {r['label']}: ci95 half-width {half!r} is not the pooled one {rebuilt!r}")
        for p, sg in zip(parts, s):
            rss = math.sqrt(sum(p[k] ** 2 for k in PARTS))
            if abs(rss / sg - 1) > 1e-6:
                raise SystemExit(f"{path}: {r['label']}: parts' root sum of squares {rss!r} is not per_run_sigma {sg!r}")
            top = max(PARTS, key=lambda k: p[k])
            largest[top] = largest.get(top, 0) + 1
        if len(v) > 1:
            n_pooled += 1
            b = pooled_half(v, s) / pooled_half(v, s, birge=False)
            if b > 1 + 1e-12:
                birge_fired.append((r["label"], b))
        err = res["lambda66"] - a0
        if r["label"].startswith("con-"):  # the drawn hulls split by the budget's own reading (no truth)
            mostly = all(p["common"] ** 2 >= 0.9 * sg**2 for p, sg in zip(parts, s))
            groups = groups + [f"memory-free: drawn, sigma {'>= 90 % common' if mostly else 'the others'}"]
        if len(v) == 2:  # two reverse runs of one hull: their scatter against their own sigmas, no truth
            chi2_pairs.append(((v[0] - v[1]) ** 2 / (s[0] ** 2 + s[1] ** 2), r["label"]))
        for g in groups:  # each reverse run alone, against its own sigma
            for vi, si in zip(v, s):
                single.setdefault(g, []).append((vi - a0) / si)
        halves = {"reported": half, "no Birge": pooled_half(v, s, birge=False)}
        for k in PARTS:
            sk = [math.sqrt(max(sum(p[j] ** 2 for j in PARTS if j != k), 1e-300)) for p in parts]
            halves[f"no {k}"] = pooled_half(v, sk)
        for g in groups:
            for rule, h in halves.items():
                scores.setdefault(g, {}).setdefault(rule, []).append(err / (h / Z95))
    _print_table("memory-free water: median |z| (0.674 calibrated), covered; rules on every run's sigma", scores, rules)
    print("\neach reverse run alone, (its value - truth) / its own sigma (per_run, per_run_sigma):")
    for g in sorted(single, key=lambda k: (k.count(":"), k)):
        z = np.abs(np.array(single[g]))
        print(f"  {g}: {len(z)} runs, median |z| {np.median(z):.2f}, rms z {np.sqrt(np.mean(z**2)):.2f}, "
              f"within 1.96: {int(np.sum(z <= Z95))}/{len(z)}")
    c = np.array([x for x, _ in chi2_pairs])
    print(f"\ntwo reverse runs of a hull, chi2 = (v1 - v2)^2 / (s1^2 + s2^2) (1 dof if their sigmas are right and "
          f"their errors independent; median 0.455, P(> 1) = 0.317): {len(c)} pairs, median {np.median(c):.3f}, "
          f"> 1 in {int(np.sum(c > 1))}")
    print(f"\nlargest part of a run's sigma (runs): {largest}")
    print(f"Birge widening fired on {len(birge_fired)} of {n_pooled} pooled rows: "
          + ", ".join(f"{lab} x{b:.2f}" for lab, b in birge_fired))


def memory_study(sets: Path, foreign: list[str], seeds: int, rows_path: str | None = None) -> None:
    from addedinertia_env.identify.cluster_jackknife import t95  # noqa: PLC0415
    from addedinertia_env.identify.memory import RESOLUTION, family_intervals, identify_memory  # noqa: PLC0415
    from addedinertia_env.records.record import read_record  # noqa: PLC0415
    from addedinertia_env.reports.interval_calibration import memory_runs  # noqa: PLC0415

    stored = {}
    if rows_path:  # the stored rows: a run they refused is skipped, and the reported interval checked against theirs
        for line in Path(rows_path).read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if r["water"] == "memory":
                    key = r["label"] if not r["label"].startswith("cum-") else (
                        r["label"].split("-")[1] + "-" + r["label"].split("-")[2], r["label"].rsplit("-h", 1)[1])
                    stored[key] = r

    def stored_row(label: str):
        if not label.startswith("cum-"):
            return stored.get(label)
        parts = label.split("-")
        return stored.get((parts[1] + "-" + parts[2], label.rsplit("-h", 1)[1]))

    rules = ["reported", "mixture alone", "jackknife alone", "resolution alone", "mixture|resolution"]
    scores: dict[str, dict[str, list[float]]] = {}
    setter: dict[str, int] = {}
    for label, files, a0 in memory_runs(sets, seeds, foreign):
        row = stored_row(label) if rows_path else None
        if rows_path and (row is None or "lambda66" not in row["result"]):
            print(f"{label}: not in the rows or refused there: skipped", flush=True)
            continue
        if row is not None:
            label = row["label"]  # the rows' label (with the controller), for the groups
        recs = [read_record(f).without_truth() for f in files]
        try:
            mem = identify_memory(recs)
        except Exception as e:  # noqa: BLE001 - a refused run is reported and skipped
            print(f"{label}: refused ({type(e).__name__})", flush=True)
            continue
        if not mem.identified:
            print(f"{label}: no memory fit", flush=True)
            continue
        v = mem.A_zero
        lo, hi = family_intervals(mem.best, mem.accepted, mem.weights, mem.n_stretches)["A66_zero"]
        h_mix = 0.5 * (hi - lo)  # half the interval's length, as interval_calibration scores it (it may be asymmetric)
        sd_j, dof = mem.best.sigma.get("A66_zero_jackknife", math.nan), mem.best.sigma.get("A66_zero_jackknife_dof", 0)
        h_jack = t95(int(dof)) * sd_j if math.isfinite(sd_j) and dof >= 1 else 0.0
        h_res = RESOLUTION * abs(mem.A_zero - mem.A_inf)
        lo_r, hi_r = mem.ci95["A66_zero"]
        h_rep = 0.5 * (hi_r - lo_r)
        if row is not None:
            lo_s, hi_s = row["result"]["ci95"]
            if abs(0.5 * (hi_s - lo_s) / h_rep - 1) > 1e-6 or row["result"]["lambda66"] != v:
                print(f"{label}: the memory fit's A66(0) {v!r} +- {h_rep!r} is not the row's "
                      f"{row['result']['lambda66']!r} +- {0.5 * (hi_s - lo_s)!r}", flush=True)
        halves = {"reported": h_rep, "mixture alone": h_mix, "jackknife alone": max(h_jack, 1e-300),
                  "resolution alone": h_res,
                  "mixture|resolution": 0.5 * (max(hi, v + h_res) - min(lo, v - h_res))}
        top = max(("mixture alone", "jackknife alone", "resolution alone"), key=lambda k: halves[k])
        setter[top] = setter.get(top, 0) + 1
        err = v - a0
        print(f"{label}: error {100 * err / a0:+.4f} %, half-widths " + ", ".join(
            f"{k} {100 * h / a0:.4f} %" for k, h in halves.items()) + f", jackknife dof {int(dof)}", flush=True)
        for g in _groups(label, "memory", None):
            for rule, h in halves.items():
                scores.setdefault(g, {}).setdefault(rule, []).append(err / (h / Z95))
    _print_table("water with memory: median |z| (0.674 calibrated), covered; each part of the A66(0) interval alone",
                 scores, rules)
    print(f"\nwhat sets the reported width (runs): {setter}")


def lag_sensitivity(sets: Path, rows_path: str, seeds: int, factor: float) -> None:
    """What-if, not the estimator: the smooth-current scale's timing budget (``energy_calibration.RULE_LAG_UNCERTAINTY``,
    a tenth of a sample taken as 1-sigma) times ``factor`` (1 / sqrt(3): the tenth read as the half-width of a
    rectangular distribution, JCGM 100:2008 section 4.3.7), each drawn memory-free hull identified again as
    ``interval_calibration run`` does; lambda66 compared with the stored row's, z scored as above."""
    from addedinertia_env.identify import energy_calibration  # noqa: PLC0415
    from addedinertia_env.reports.interval_calibration import identify_row  # noqa: PLC0415

    stored = {}
    for line in Path(rows_path).read_text().splitlines():
        if line.strip():
            r = json.loads(line)
            stored[r["label"]] = r
    energy_calibration.RULE_LAG_UNCERTAINTY *= factor
    scores: dict[str, dict[str, list[float]]] = {}
    moved = 0
    for preset in ("wigley-2m", "spheroid-7"):
        for seed in range(1, seeds + 1):
            label = next((k for k in stored if k.startswith(f"con-{preset}-") and k.endswith(f"-h{seed}")), None)
            base = sets / "constant" / preset / f"h{seed}"
            files = [base / "rev-a" / "run-0000.csv", base / "rev-b" / "run-0000.csv", base / "decay" / "run-0000.csv"]
            if label is None or not all(f.exists() for f in files) or "error" in stored[label]["result"]:
                continue
            old, new = stored[label]["result"], identify_row(label, "memory-free", files, None)["result"]
            if "error" in new:
                print(f"{label}: refused now ({new['error'][:80]})")
                continue
            a0 = stored[label]["truth"]["lambda66"]
            moved += new["lambda66"] != old["lambda66"]
            h_old, h_new = 0.5 * (old["ci95"][1] - old["ci95"][0]), 0.5 * (new["ci95"][1] - new["ci95"][0])
            err = new["lambda66"] - a0
            print(f"{label}: lambda66 {'same' if new['lambda66'] == old['lambda66'] else 'MOVED'}, half-width "
                  f"{100 * h_old / a0:.4f} -> {100 * h_new / a0:.4f} %, z {err / (h_old / Z95):+.2f} -> "
                  f"{err / (h_new / Z95):+.2f}", flush=True)
            for g in _groups(label, "memory-free", None):
                scores.setdefault(g, {}).setdefault("stored", []).append(err / (h_old / Z95))
                scores.setdefault(g, {}).setdefault(f"timing x{factor:.3f}", []).append(err / (h_new / Z95))
    _print_table("drawn memory-free hulls: the smooth-current scale's timing budget scaled (what-if)", scores,
                 ["stored", f"timing x{factor:.3f}"])
    print(f"lambda66 moved on {moved} rows")


def reference(n: int = 400_000, seed: int = 1) -> None:
    """Median |z| of coverage-calibrated intervals whose sigma is estimated (exact budget, Monte Carlo)."""
    from scipy import stats  # noqa: PLC0415

    rng = np.random.default_rng(seed)
    print("\nreference: median |z| and coverage of an interval that is right on average (exact budget)")
    e = rng.standard_normal(n)
    print(f"  known sigma, 1.96 sigma: median |z| {np.median(np.abs(e)):.3f}, covered {np.mean(np.abs(e) <= Z95):.3f}")
    for dof in (1, 2, 3, 4, 8):
        sd = np.sqrt(rng.chisquare(dof, n) / dof)  # an estimated sigma with dof degrees of freedom
        half = stats.t.ppf(0.975, dof) * sd
        z = Z95 * e / half
        print(f"  Student's t, {dof} dof: median |z| {np.median(np.abs(z)):.3f}, covered {np.mean(np.abs(z) <= Z95):.3f}")
    chi2 = rng.chisquare(1, n)  # two runs pooled with exact sigmas: chi2 of their scatter has 1 dof, independent of the mean
    z = e / np.sqrt(np.maximum(chi2, 1.0))
    print(f"  two runs, Birge widening max(1, sqrt(chi2/1)): median |z| {np.median(np.abs(z)):.3f}, "
          f"covered {np.mean(np.abs(z) <= Z95):.3f}, widened in {np.mean(chi2 > 1):.2f} of rows")
    for r in (1.0, 0.75, 0.5):  # the union of a calibrated normal interval and a t(2) jackknife of the same error
        sd = np.sqrt(rng.chisquare(2, n) / 2)
        half = np.maximum(Z95 * r, stats.t.ppf(0.975, 2) * sd)
        z = Z95 * e / half
        print(f"  union of a normal interval ({r:.2f} x the true sigma) and a t(2) jackknife: "
              f"median |z| {np.median(np.abs(z)):.3f}, covered {np.mean(np.abs(z) <= Z95):.3f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("rows")
    a.add_argument("rows")
    b = sub.add_parser("memory")
    b.add_argument("--sets", required=True, type=Path)
    b.add_argument("--foreign", action="append", default=[])
    b.add_argument("--seeds", type=int, default=18)
    b.add_argument("--rows", help="the stored rows (interval_calibration run's): skip what they refused, check the rest")
    c = sub.add_parser("lag-sensitivity")
    c.add_argument("--sets", required=True, type=Path)
    c.add_argument("--rows", required=True)
    c.add_argument("--seeds", type=int, default=18)
    c.add_argument("--factor", type=float, default=1 / math.sqrt(3))
    sub.add_parser("reference")
    args = ap.parse_args(argv)
    if args.cmd == "rows":
        rows_study(args.rows)
    elif args.cmd == "memory":
        memory_study(args.sets, args.foreign, args.seeds, args.rows)
    elif args.cmd == "lag-sensitivity":
        lag_sensitivity(args.sets, args.rows, args.seeds, args.factor)
    else:
        reference()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
