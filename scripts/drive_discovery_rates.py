"""Detection and false-alarm rates of discovery's drive words, and each flaw's bias on lambda66.

For every flaw of :data:`addedinertia_env.apps.drive_discovery.FLAWS` and seed: the standard
discovery dataset on a drive with that flaw drawn at a realistic size; the drive words named
(:func:`addedinertia_env.discover.drive_flaws.candidate`, blind: no ``truth``) and the energy
method's lambda66 error per run (scored against ``truth``). Prints one JSON line per dataset
and a Markdown table (docs/DISCOVERY.md, docs/DRIVE.md).

    PYTHONPATH=$PWD python scripts/drive_discovery_rates.py --seeds 10 > out/drive_discovery_rates.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from addedinertia_env.apps.drive_discovery import FLAWS, draw_drive, simulate_drive_dataset
from addedinertia_env.discover.drive_flaws import candidate


def one(flaw: str, seed: int, controller: str | None, energy: bool) -> dict:
    """One dataset: the words named, the drive drawn, the energy method's errors (%)."""
    t0 = time.perf_counter()
    records = simulate_drive_dataset(flaw, seed, controller)
    ev = candidate([r.without_truth() for r in records])
    row = {"flaw": flaw, "seed": seed, "controller": controller or "default", "named": ev["named"],
           "drive": draw_drive(flaw, seed).to_dict(), "why": ev["why"]}
    if energy:
        from addedinertia_env.identify import identify  # noqa: PLC0415

        errs = []
        for r in records:
            try:
                errs.append(100.0 * (identify([r.without_truth()], "energy").lambda66 / r.meta["truth"]["lambda66"] - 1))
            except Exception as e:  # noqa: BLE001 - a failed estimate is a result here
                errs.append(None)
                row.setdefault("energy_failures", []).append(f"{r.name}: {e}")
        row["energy_error_pct"] = errs
    row["wall_s"] = time.perf_counter() - t0
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--flaws", nargs="*", default=list(FLAWS))
    ap.add_argument("--controller", default=None, help="default: the standard dataset's (feedforward-pd)")
    ap.add_argument("--no-energy", action="store_true", help="skip the energy method's errors")
    a = ap.parse_args()
    rows = []
    for flaw in a.flaws:
        for seed in range(a.first_seed, a.first_seed + a.seeds):
            row = one(flaw, seed, a.controller, not a.no_energy)
            rows.append(row)
            print(json.dumps(row), flush=True)
    print("\n| hidden flaw | datasets | named as hidden | any other drive word | energy-method error, median (range) |",
          file=sys.stderr)
    print("|---|---|---|---|---|", file=sys.stderr)
    for flaw in a.flaws:
        rs = [r for r in rows if r["flaw"] == flaw]
        hit = sum((flaw in r["named"]) if flaw != "none" else (not r["named"]) for r in rs)
        other = sum(any(w != flaw for w in r["named"]) for r in rs)
        errs = [e for r in rs for e in r.get("energy_error_pct", []) if e is not None]
        err = (f"{np.median(errs):+.2f} % ({min(errs):+.1f} .. {max(errs):+.1f} %)" if errs else "-")
        label = "nothing named" if flaw == "none" else f"`{flaw}` named"
        print(f"| {flaw} | {len(rs)} | {label}: {hit}/{len(rs)} | {other}/{len(rs)} | {err} |", file=sys.stderr)


if __name__ == "__main__":
    main()
