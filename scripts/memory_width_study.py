"""What sets the width of lambda66's interval in water with memory (docs/INTERVALS.md, issue 26).

For each memory run of the interval calibration (the drawn hulls' sets that
``python -m addedinertia_env.reports.interval_calibration run`` keeps under SETS, and each reverse run of
foreign-lab-2's memory cases with the case's free decays), the interval is rebuilt under these rules from the
same fits, and each rule's coverage and ratio (median half-width / median |error|; 2.9 is calibrated) printed:

- ``union+floor``: the union over the families within 1.25 of the best residual, floored by the corrected
  balance's disagreement (``1.96 x |d| / 2``; the code before issue 26's model averaging);
- ``mixture+floor``: the Akaike-weighted mixture (identify/model_average.py), the same floor (session 11's code);
- ``mixture``: the mixture alone;
- ``mixture+test``: the floor only where the disagreement exceeds both intervals together (then ``|d|``);
- ``mixture|jackknife``: the mixture, widened to hold the reported family's stratified jackknife over the
  stretches of free motion (identify/cluster_jackknife.py; the code now: the memory fit's interval, reported);
- ``mixture|jackknife+floor``: that with the floor as well;
- ``jackknife (unstratified)``: the mixture widened to the plain delete-one-stretch jackknife (t, g - 1 dof), the
  decay left out too.

    python scripts/memory_width_study.py --sets SETS --foreign PATH/foreign-lab-2.tar.xz [--seeds 13] [--first 1]

The truth (the records' ``truth`` block, the lab's ``answers.json``) is read to score only. About 10 CPU-s a run.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from addedinertia_env.identify import identify
from addedinertia_env.identify.cluster_jackknife import t95
from addedinertia_env.identify.memory import (FAMILY_RSS_TOLERANCE, Z95, MemoryData, family_intervals, identify_memory,
                                              jackknife_refits)
from addedinertia_env.identify.memory_energy import corrected_energy
from addedinertia_env.records.record import read_record
from addedinertia_env.reports.interval_calibration import memory_runs

RULES = ("union+floor", "mixture+floor", "mixture", "mixture+test", "mixture|jackknife", "mixture|jackknife+floor",
         "jackknife (unstratified)")


def half_widths(files: list[Path]) -> dict | None:
    """The reported value, the corrected balance, and each rule's half-width (kg m^2) for one run's records."""
    recs = [read_record(f).without_truth() for f in files]
    mem = identify_memory(recs)
    if not mem.identified:
        return None
    # the corrected balance as identify makes it (memory_energy.with_memory), from this one memory fit
    reverse = [r for r in recs if r.experiment.get("kind") != "free-decay"]
    corrected = corrected_energy(reverse, identify(reverse, "energy", memory="off").details, mem)
    if corrected is None:
        return None
    ec, (lo_e, hi_e) = corrected.value, corrected.ci95
    v = mem.A_zero
    passive = [f for f in mem.fits if f.passive]
    kept = [f for f in passive if f.rss <= FAMILY_RSS_TOLERANCE * min(g.rss for g in passive)]
    union = (min(f.A_zero - Z95 * f.sigma["A66_zero"] for f in kept), max(f.A_zero + Z95 * f.sigma["A66_zero"] for f in kept))
    lo, hi = family_intervals(mem.best, mem.accepted, mem.weights, mem.n_stretches)["A66_zero"]  # the mixture alone
    h_union, h_mix = max(v - union[0], union[1] - v), max(v - lo, hi - v)
    lo_j, hi_j = mem.ci95["A66_zero"]  # the memory fit's interval: the mixture holding the stratified jackknife
    h_jack = max(v - lo_j, hi_j - v)
    refits = jackknife_refits(MemoryData(recs), mem.best, mem.swing_omega)
    plain = np.array([q[1] for q in refits.values()])
    g = len(plain)
    h_plain = t95(g - 1) * math.sqrt((g - 1) / g * np.sum((plain - plain.mean()) ** 2)) if g >= 3 else 0.0
    h_e, d = max(ec - lo_e, hi_e - ec), abs(ec - v)
    return {"value": v, "half": {"union+floor": max(h_union, 0.5 * Z95 * d), "mixture+floor": max(h_mix, 0.5 * Z95 * d),
                                 "mixture": h_mix,
                                 "mixture+test": max(h_mix, d) if d > math.hypot(h_mix, h_e) else h_mix,
                                 "mixture|jackknife": h_jack, "mixture|jackknife+floor": max(h_jack, 0.5 * Z95 * d),
                                 "jackknife (unstratified)": max(h_mix, h_plain)}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", required=True, type=Path)
    ap.add_argument("--seeds", type=int, default=13, help="the last drawn hull's seed")
    ap.add_argument("--first", type=int, default=1,
                    help="the first drawn hull's seed (14: the hulls drawn after the rule was chosen)")
    ap.add_argument("--foreign", action="append", default=[])
    args = ap.parse_args()
    err, half = [], {r: [] for r in RULES}
    for label, files, a0 in memory_runs(args.sets, args.seeds, args.foreign, args.first):
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
        print(f"{r:24s} runs {len(e)}  median |error| {100 * np.median(e):.4f} %  median half-width "
              f"{100 * np.median(h):.4f} %  ratio {np.median(h) / np.median(e):.1f}  covered {int(np.sum(e <= h))}/{len(e)}")


if __name__ == "__main__":
    main()
