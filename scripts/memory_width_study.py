"""What sets the width of lambda66's interval in water with memory (docs/INTERVALS.md, issue 26).

For each memory run of the interval calibration (the drawn hulls' sets that
``python -m addedinertia_env.reports.interval_calibration run`` keeps under SETS, and each reverse run of
foreign-lab-2's memory cases with the case's free decays), the interval is rebuilt under four rules from the
same fits, and each rule's coverage and ratio (median half-width / median |error|; 2.9 is calibrated) printed:

- ``union+floor``: the union over the families within 1.25 of the best residual, floored by the corrected
  balance's disagreement (``1.96 x |d| / 2``; the code before issue 26's model averaging);
- ``mixture+floor``: the Akaike-weighted mixture (identify/model_average.py), the same floor (the code now);
- ``mixture``: the mixture alone;
- ``mixture+test``: the floor only where the disagreement exceeds both intervals together (then ``|d|``).

    python scripts/memory_width_study.py --sets SETS --foreign PATH/foreign-lab-2.tar.xz [--seeds 13]

The truth (the records' ``truth`` block, the lab's ``answers.json``) is read to score only. About 3 CPU-s a run.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from addedinertia_env.identify import identify
from addedinertia_env.identify.memory import FAMILY_RSS_TOLERANCE, Z95, identify_memory
from addedinertia_env.identify.model_average import mixture_interval
from addedinertia_env.records.record import read_record
from addedinertia_env.reports.interval_calibration import lab_reverse_runs

RULES = ("union+floor", "mixture+floor", "mixture", "mixture+test")


def half_widths(files: list[Path]) -> dict | None:
    """The reported value, the corrected balance, and each rule's half-width (kg m^2) for one run's records."""
    recs = [read_record(f).without_truth() for f in files]
    mem = identify_memory(recs)
    if not mem.identified:
        return None
    res = identify(recs, "energy", memory=True)
    ec = res.details.get("lambda66_energy_corrected")
    if ec is None:
        return None
    v = mem.A_zero
    passive = [f for f in mem.fits if f.passive]
    kept = [f for f in passive if f.rss <= FAMILY_RSS_TOLERANCE * min(g.rss for g in passive)]
    union = (min(f.A_zero - Z95 * f.sigma["A66_zero"] for f in kept), max(f.A_zero + Z95 * f.sigma["A66_zero"] for f in kept))
    lo, hi = mem.ci95["A66_zero"]
    h_union, h_mix = max(v - union[0], union[1] - v), max(v - lo, hi - v)
    lo_e, hi_e = res.details["lambda66_energy_corrected_ci95"]
    h_e, d = max(ec - lo_e, hi_e - ec), abs(ec - v)
    return {"value": v, "half": {"union+floor": max(h_union, 0.5 * Z95 * d), "mixture+floor": max(h_mix, 0.5 * Z95 * d),
                                 "mixture": h_mix,
                                 "mixture+test": max(h_mix, d) if d > math.hypot(h_mix, h_e) else h_mix}}


def runs(sets: Path, seeds: int, foreign: list[str]):
    """(label, files, A66(0)) of every memory run: the drawn hulls' sets, then each lab's memory cases."""
    for preset in ("wigley-2m", "spheroid-7"):
        for s in range(1, seeds + 1):
            base = sets / "cummins" / preset / f"h{s}"
            files = [base / "rev-a" / "run-0000.csv", base / "rev-b" / "run-0000.csv", base / "decay" / "run-0000.csv"]
            if all(f.exists() for f in files):
                yield f"cum-{preset}-h{s}", files, read_record(files[0]).meta["truth"]["lambda66"]
    for archive in foreign:
        for case, p, decays, a in lab_reverse_runs(Path(archive)):
            if a.get("A66_inf") is not None:
                yield f"{case.name}-{p.stem}", [p, *decays], a["lambda66"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", required=True, type=Path)
    ap.add_argument("--seeds", type=int, default=13)
    ap.add_argument("--foreign", action="append", default=[])
    args = ap.parse_args()
    err, half = [], {r: [] for r in RULES}
    for label, files, a0 in runs(args.sets, args.seeds, args.foreign):
        try:
            got = half_widths(files)
        except Exception as e:  # noqa: BLE001 - a refused run is reported and skipped
            print(f"{label}: refused ({type(e).__name__})")
            continue
        if got is None:
            print(f"{label}: no memory correction")
            continue
        err.append(abs(got["value"] / a0 - 1))
        for r in RULES:
            half[r].append(got["half"][r] / a0)
        print(f"{label}: error {100 * (got['value'] / a0 - 1):+.4f} %, half-widths "
              + ", ".join(f"{r} {100 * got['half'][r] / a0:.4f} %" for r in RULES), flush=True)
    e = np.array(err)
    for r in RULES:
        h = np.array(half[r])
        print(f"{r:14s} runs {len(e)}  median |error| {100 * np.median(e):.4f} %  median half-width "
              f"{100 * np.median(h):.4f} %  ratio {np.median(h) / np.median(e):.1f}  covered {int(np.sum(e <= h))}/{len(e)}")


if __name__ == "__main__":
    main()
