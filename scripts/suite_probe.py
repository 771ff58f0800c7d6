"""Probe a suite before committing it: a few scenarios of one split, each controller on the same
scenarios and sensor noise; one JSON row per episode (rel_error, failure, wear) on stdout.

    python scripts/suite_probe.py drive-v1 --split tuning --count 6 --jobs 2 \
        --controllers zero pd feedforward-pd "drive-aware@prespin_fraction=0.2" > out/probe.jsonl
"""

from __future__ import annotations

import argparse
import json

from addedinertia_env.bench.runner import run_tasks
from addedinertia_env.bench.suites import load_suite


def main() -> None:
    """Run the probe; print one JSON row per episode."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("--split", default="tuning")
    ap.add_argument("--first", type=int, default=0, help="index of the first scenario of the split")
    ap.add_argument("--count", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--controllers", nargs="+", required=True, help='"name" or "name@knob=value,..."')
    a = ap.parse_args()
    suite = load_suite(a.suite)
    scenarios = suite.scenarios(a.split)[a.first:a.first + a.count]
    tasks = []
    for sc in scenarios:
        for c in a.controllers:
            name, _, knobs = c.partition("@")
            kwargs = {k: float(v) for k, v in (kv.split("=") for kv in knobs.split(",") if kv)}
            tasks.append(suite.task(sc, name, kwargs or None))
    keys = ("controller", "controller_kwargs", "seed", "preset", "rel_error", "failure", "current_sign_changes",
            "chatter_a", "wall_s")
    run_tasks(tasks, jobs=a.jobs, progress=False,
              on_row=lambda r: print(json.dumps({k: r.get(k) for k in keys}), flush=True))


if __name__ == "__main__":
    main()
