"""Paired comparison of one entry against the others in a ``scripts/suite_probe.py`` output, with the
bench's own ranked score and paired bootstrap (addedinertia_env/bench/score.py): each entry's score,
failures, and the mean paired difference ``s_entry - s_other`` with its 95 % interval.

    python scripts/probe_compare.py out/probe.jsonl --entry supply-aware
"""

from __future__ import annotations

import argparse
import json
import sys

from addedinertia_env.bench.score import difference, entry_score


def main() -> None:
    """Print a markdown table: entry, score, 95 % CI, failures, paired difference against ``--entry``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rows", help="JSON lines written by scripts/suite_probe.py")
    ap.add_argument("--entry", required=True, help="the entry every other is paired against")
    a = ap.parse_args()
    by: dict[str, list[dict]] = {}
    with open(a.rows) as f:
        for n, line in enumerate(f, 1):
            try:
                r = json.loads(line)
                by.setdefault(str(r["controller"]), []).append({**r, "suite": "probe", "split": "probe",
                                                               "seed": int(r["seed"])})
            except (json.JSONDecodeError, KeyError, TypeError, ValueError) as e:
                sys.exit(f"{a.rows}:{n}: not a suite_probe row ({e}); expected JSON with controller and seed")
    if a.entry not in by:
        sys.exit(f"--entry {a.entry!r}: not in {a.rows} (entries: {sorted(by)})")
    scores = {name: entry_score(rows) for name, rows in by.items()}
    mine = scores[a.entry]["scenario_scores"]
    print(f"| entry | score | 95 % CI | failures | {a.entry} minus entry (paired, 95 % CI) | n |")
    print("|---|---|---|---|---|---|")
    for name, s in sorted(scores.items(), key=lambda kv: kv[1]["mean_score"]):
        fails = sum(1 for r in by[name] if r.get("rel_error") is None or r.get("failure"))
        lo, hi = s["ci95_score"]
        cell = ""
        if name != a.entry:
            d = difference(mine, s["scenario_scores"])
            star = "*" if d["ci95"][0] > 0 or d["ci95"][1] < 0 else ""
            cell = f"{100 * d['mean']:+.3f} %{star} ({100 * d['ci95'][0]:+.3f} .. {100 * d['ci95'][1]:+.3f})"
        print(f"| `{name}` | {100 * s['mean_score']:.3f} % | {100 * lo:.3f} .. {100 * hi:.3f} % | {fails} | {cell} "
              f"| {len(s['scenario_scores'])} |")


if __name__ == "__main__":
    main()
