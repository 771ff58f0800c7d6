"""Probe a suite before committing it: a few scenarios of one split, each controller on the same
scenarios and sensor noise; one JSON row per episode (rel_error, failure, wear) on stdout.

    python scripts/suite_probe.py drive-v1 --split tuning --count 6 --jobs 2 \
        --controllers zero pd feedforward-pd "drive-aware@prespin_fraction=0.2" > out/probe.jsonl

``--without cogging`` (or ``backlash``, ``mesh``, ``drag``, ``driver``) runs the same scenarios with
that flaw of the drawn drive switched off, the rest as drawn (the flaw's effect on each entry).
``--supply 12`` (``--flywheel 0.05``) runs them on that supply voltage, V (flywheel inertia, kg m^2) instead of the drawn one (a constructed weak-supply
variant, e.g. of the tuning split, to develop against the supply without touching held-out seeds).
"""

from __future__ import annotations

import argparse
import dataclasses
import json

from addedinertia_env.bench.runner import run_tasks
from addedinertia_env.bench.suites import load_suite

# --without NAME: the DriveParams fields set to their neutral values
SWITCHES = {"cogging": {"cogging_torque": 0.0}, "backlash": {"backlash": 0.0}, "mesh": {"gear_efficiency": 1.0},
            "drag": {"gear_drag": 0.0}, "driver": {"driver_time_constant": 0.0}}


def without(scenario, flaws: list[str]):
    """``scenario`` with the drive flaws ``flaws`` switched off (its name says which)."""
    if not flaws:
        return scenario
    d = scenario.rig.drive
    if d is None:
        raise SystemExit(f"--without {flaws}: scenario {scenario.name} has no drive block")
    for f in flaws:
        d = dataclasses.replace(d, **SWITCHES[f])
    return dataclasses.replace(scenario, rig=scenario.rig.replace(drive=d))


def _value(text: str):
    """A knob's value: a number where it reads as one, else the word (``smith-pd@inertia=prior``)."""
    try:
        return float(text)
    except ValueError:
        return text


def main() -> None:
    """Run the probe; print one JSON row per episode."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("--split", default="tuning", help="tuning, test, or train (seeds outside both)")
    ap.add_argument("--first", type=int, default=0, help="index of the first scenario of the split")
    ap.add_argument("--count", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--controllers", nargs="+", required=True, help='"name" or "name@knob=value,..."')
    ap.add_argument("--without", nargs="*", default=[], choices=sorted(SWITCHES),
                    help="drive flaws switched off in every scenario")
    ap.add_argument("--supply", type=float, default=None, help="supply voltage, V, replacing the drawn one")
    ap.add_argument("--flywheel", type=float, default=None, help="flywheel inertia, kg m^2, replacing the drawn one")
    a = ap.parse_args()
    suite = load_suite(a.suite)
    if a.split == "train":  # seeds outside both splits (suite.split_seed): never a tuning or test scenario
        scenarios = [suite.scenario(suite.split_seed("train", k)) for k in range(a.first, a.first + a.count)]
    else:
        scenarios = suite.scenarios(a.split)[a.first:a.first + a.count]
    tasks = []
    for sc in scenarios:
        sc = without(sc, a.without)
        if a.supply is not None:
            motor = sc.rig.motor
            if not a.supply > motor.R * motor.i_max:
                raise SystemExit(f"--supply {a.supply:g} V: expected more than R i_max = {motor.R * motor.i_max:g} V")
            sc = dataclasses.replace(sc, rig=sc.rig.replace(motor=dataclasses.replace(motor, u_max=a.supply)))
        if a.flywheel is not None:
            if not a.flywheel > 0:
                raise SystemExit(f"--flywheel {a.flywheel:g} kg m^2: expected a positive inertia")
            motor = dataclasses.replace(sc.rig.motor, J_flywheel=a.flywheel)
            sc = dataclasses.replace(sc, rig=sc.rig.replace(motor=motor))
        for c in a.controllers:
            name, _, knobs = c.partition("@")
            kwargs = {k: _value(v) for k, v in (kv.split("=") for kv in knobs.split(",") if kv)}
            tasks.append(suite.task(sc, name, kwargs or None))
    keys = ("controller", "controller_kwargs", "seed", "preset", "rel_error", "failure", "current_sign_changes",
            "chatter_a", "wall_s")
    run_tasks(tasks, jobs=a.jobs, progress=False,
              on_row=lambda r: print(json.dumps({**{k: r.get(k) for k in keys}, "without": a.without, "supply": a.supply, "flywheel": a.flywheel}), flush=True))


if __name__ == "__main__":
    main()
