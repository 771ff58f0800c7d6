"""Which candidate drive flaw makes control decide? (issue 28, drive-v2 study)

Runs a suite's scenarios with one candidate flaw applied on top of the drawn drive, every controller
on the same scenarios and sensor noise, and prints one JSON row per episode (the signed error of the
energy method as written, failures, the largest voltage the drive asked for against the supply, the
largest flywheel rate). Candidates (each a command-line option, combinable):

* ``--delay-ms D``: the link's round trip: the command the controller computes from sample k reaches
  the drive D ms later (held meanwhile), as a host on a USB link sees it (1 ms USB frames, an FTDI
  bridge's latency timer 1-16 ms);
* ``--supply V``: the supply's voltage (the drive clips its terminal voltage to it);
* ``--imax A``: the driver's current limit (a bench supply that cannot deliver more);
* ``--flywheel KGM2``, ``--alpha RAD``: the flywheel's inertia and the twist, which set how fast the
  flywheel turns through the reverse stroke (its back-EMF).

    PYTHONPATH=$PWD python scripts/drive_flaw_probe.py drive-v1 --count 4 --delay-ms 2 \
        --controllers pd pid lqr feedforward-pd oracle zero > out/probe_delay2.jsonl
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json

import numpy as np

from addedinertia_env.bench.runner import build_rig, cycle_seed, episode_controller
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.identify import identify


class DelayedController:
    """``inner`` with its commands applied ``delay`` samples late (the first ``delay`` samples hold the
    first command): the link's round trip between the host and the drive."""

    def __init__(self, inner, delay: int):
        self.inner, self.delay = inner, int(delay)
        self.queue: collections.deque = collections.deque()

    def reset(self, context):
        """Reset the inner controller and empty the link."""
        self.queue.clear()
        if hasattr(self.inner, "reset"):
            self.inner.reset(context)

    def predict(self, obs, deterministic=True):
        """The command computed ``delay`` samples ago."""
        action, state = self.inner.predict(obs, deterministic=deterministic)
        self.queue.append(np.array(action, copy=True))
        while len(self.queue) > self.delay + 1:
            self.queue.popleft()
        return self.queue[0], state


def main() -> None:
    """Run every (scenario, controller); one JSON row per episode."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite")
    ap.add_argument("--split", default="tuning")
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--count", type=int, default=4)
    ap.add_argument("--controllers", nargs="+", required=True)
    ap.add_argument("--delay-ms", type=float, default=0.0)
    ap.add_argument("--supply", type=float, default=None, help="V")
    ap.add_argument("--flywheel", type=float, default=None, help="J_flywheel, kg m^2")
    ap.add_argument("--alpha", type=float, default=None, help="twist, rad")
    ap.add_argument("--imax", type=float, default=None, help="the driver's current limit, A (a supply that cannot deliver more)")
    a = ap.parse_args()
    suite = load_suite(a.suite)
    for sc in suite.scenarios(a.split)[a.first:a.first + a.count]:
        motor = sc.rig.motor
        if a.supply is not None:
            motor = dataclasses.replace(motor, u_max=a.supply)
        if a.imax is not None:
            motor = dataclasses.replace(motor, i_max=a.imax)
        if a.flywheel is not None:
            motor = dataclasses.replace(motor, J_flywheel=a.flywheel)
        sc = dataclasses.replace(sc, rig=sc.rig.replace(motor=motor))
        if a.alpha is not None:
            sc = dataclasses.replace(sc, plan=dataclasses.replace(sc.plan, alpha=a.alpha))
        for c in a.controllers:
            name, _, knobs = c.partition("@")
            kwargs = {k: float(v) for k, v in (kv.split("=") for kv in knobs.split(",") if kv)}
            task = suite.task(sc, name, kwargs or None)
            rig = build_rig(task.scenario, seed=cycle_seed(task.scenario, 0))
            ctrl = episode_controller(name, task.controller_kwargs, rig)
            delay = int(round(a.delay_ms * 1e-3 / rig.dt))
            if delay:
                ctrl = DelayedController(ctrl, delay)
            row = {"seed": sc.seed, "controller": c, "delay_ms": a.delay_ms, "supply": motor.u_max, "i_max": motor.i_max,
                   "J_flywheel": motor.J_flywheel, "alpha": task.scenario.plan.alpha}
            try:
                rec = run_experiment(rig, ctrl, task.scenario.plan)
                s = rec.samples
                t, psi, i = (np.asarray(s[k], float) for k in ("t", "psi", "i"))
                drv = sc.rig.drive
                kt = motor.k_t * (drv.gear_ratio if drv is not None else 1.0)
                rate = np.gradient(psi, t)
                row.update(rate_max=float(np.abs(rate).max()),
                           volt_need_max=float(np.max(np.abs(kt * rate) + motor.R * np.abs(i))),
                           i_max_seen=float(np.abs(i).max()),
                           sign_changes=int(np.sum(np.diff(np.sign(np.asarray(s["i_cmd"], float))) != 0)))
                r = identify([rec.without_truth()], "energy", asymmetry_correction=False, interval_details=False)
                row.update(e=r.lambda66 / rec.meta["truth"]["lambda66"] - 1.0, failure=None)
            except Exception as ex:  # noqa: BLE001 - a failed episode is a row with its reason
                row.update(e=None, failure=f"{type(ex).__name__}: {str(ex)[:160]}")
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
