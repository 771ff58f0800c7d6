"""Cost of the environment per step, against the bare experiment loop it wraps.

``python -m addedinertia_env.envs.benchmark [--repeats 1 10] [--samples 1200]`` prints
one JSON object: for the bare loop (``Experiment.step`` with a constant command, no
observation) and for ``env.step`` at each action repeat, the CPU time (``time.process_time``, robust to a shared machine) per rig sample
and per agent step, in microseconds, measured on one nominal scenario (wigley-2m,
realistic sensors, hold 0.5 s) with a constant zero action. Reset (the free stroke)
is timed too. Numbers are medians over ``--trials`` runs.
"""

from __future__ import annotations

from addedinertia_env.foundation.machine import machine_info

import argparse
import json
import statistics
import time

import numpy as np

from addedinertia_env.experiment.protocol import Experiment
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.envs.reverse_stroke import ReverseStrokeEnv, simulated_rig

SCENARIO = {"randomize": False, "hold_s": 0.5, "scenario_seed": 0}


def _bare(samples: int) -> float:
    """Seconds per sample of ``Experiment.step`` alone."""
    env = ReverseStrokeEnv(**SCENARIO)
    env.reset(seed=0)
    exp = Experiment(simulated_rig(env.scenario), env.scenario.plan)
    exp.start()
    cmd = MotorCommand("current", 0.0)
    n = 0
    t0 = time.process_time()
    while exp.needs_control and n < samples:
        exp.step(cmd)
        n += 1
    return (time.process_time() - t0) / n


def _env(repeat: int, samples: int) -> tuple[float, float, float]:
    """(seconds per reset, per agent step, per rig sample) of ``env.step``, zero action."""
    env = ReverseStrokeEnv(action_repeat=repeat, **SCENARIO)
    t0 = time.process_time()
    env.reset(seed=0)
    t_reset = time.process_time() - t0
    action = np.zeros(1, dtype=np.float32)
    steps = max(1, samples // repeat)
    t0 = time.process_time()
    done = 0
    for _ in range(steps):
        _, _, terminated, _, _ = env.step(action)
        done += 1
        if terminated:  # the last step also scores the episode (identification): not a step cost
            raise SystemExit(f"--samples {samples} reaches the end of the episode; use fewer (at most 1400)")
    dt = time.process_time() - t0
    return t_reset, dt / done, dt / (done * repeat)


def main(argv: list[str] | None = None) -> int:
    """Print the environment's cost per step against the bare experiment loop (microseconds) as JSON; returns 0."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, nargs="+", default=[1, 10], help="action repeats to time")
    ap.add_argument("--samples", type=int, default=1200, help="rig samples per timing (below one episode: 1497)")
    ap.add_argument("--trials", type=int, default=3)
    args = ap.parse_args(argv)
    bare = statistics.median(_bare(args.samples) for _ in range(args.trials))
    out = {"bare_experiment_us_per_sample": 1e6 * bare, "env": {}}
    for r in args.repeats:
        runs = [_env(r, args.samples) for _ in range(args.trials)]
        reset, per_step, per_sample = (statistics.median(x) for x in zip(*runs))
        out["env"][str(r)] = {"action_repeat": r, "us_per_agent_step": 1e6 * per_step,
                              "us_per_sample": 1e6 * per_sample,
                              "overhead_us_per_agent_step": 1e6 * (per_step - r * bare),
                              "reset_s": reset}
    out["machine"] = machine_info()
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
