"""What the oracle knows that a controller does not, and what each piece is worth on hard-v0.

The benchmark's oracle (:class:`~addedinertia_env.experiment.oracle.OracleController`) tracks
the reference by computed torque on the simulator's truth: the true state (no reading
delay, no noise), the true inertia ``J`` (added inertia included), the true ``k_t``, the true
spring and hull torques. A student distilled from it (:mod:`addedinertia_env.learning.dagger`)
sees none of these. This report takes them away one at a time and scores each degraded
oracle by the benchmark's paired control error against the real one, on held-aside
training-split scenarios (never the test split), beside ``pd``, ``pid`` and ``pid`` without
its flywheel pre-spin in the hold (the oracle commands nothing there):

* ``omega_c``: the tracking bandwidth (the benchmark's oracle: 40 rad/s);
* ``feedback``: on the true state, or on the observation (the delayed, noisy tracking
  and rate errors every controller gets);
* ``J``: the true inertia, or the context's prior (the free stroke's, +-20 % here);
* ``k_t``: the true torque constant, or the data sheet's.

``python -m addedinertia_env.reports.oracle_ablation --scenarios 48 --out docs/figures/oracle_ablation.json``
prints a Markdown table (docs/LEARNING.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.experiment.oracle import OracleController
from addedinertia_env.sim import forces

FIRST = 800_000_000  # held-aside training scenarios (as the DAgger runs' validation)


class DegradedOracle(OracleController):
    """The oracle with some of its knowledge replaced by what a controller has (module doc)."""

    def __init__(self, rig, omega_c: float = 40.0, feedback: str = "true", J: str = "true", k_t: str = "true"):
        super().__init__(rig, omega_c)
        self.feedback, self.J_source, self.k_t_source = feedback, J, k_t

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """The degraded oracle's action (fraction of ``i_max``), ``(action, state)``."""
        p, s, ctx = self.rig.params, self.rig.true_state(), self.ctx
        ref = ctx.reference
        t = s.t + 0.5 * ctx.dt
        if t < ref.t_begin:
            return np.zeros(1, dtype=np.float32), state
        if self.feedback == "true":
            e, e_rate = float(ref.phi(t)) - s.phi, float(ref.rate(t)) - s.w
        else:
            o = ctx.layout.decode(np.asarray(observation, dtype=float))
            e, e_rate = o["tracking_error"], o["rate_error"]
        J = p.hull.J_hull + forces.hull_armature(p) if self.J_source == "true" else ctx.inertia_prior
        acc = float(ref.accel(t)) + self.kp * e + self.kd * e_rate
        hull_torque = J * acc + p.spring.c * (s.phi - forces.true_neutral(p)) \
            - float(forces.hull_extra_torque(s.phi, s.w, s.water_rate, p)) - s.radiation_torque
        k_t = self.rig.k_t if self.k_t_source == "true" else ctx.k_t
        return np.array([np.clip(-hull_torque / k_t / p.motor.i_max, -1, 1)], dtype=np.float32), state


VARIANTS: list[dict[str, Any]] = [
    {"omega_c": 20.0}, {"omega_c": 10.0}, {"omega_c": 5.0},
    {"omega_c": 10.0, "feedback": "observed"},
    {"omega_c": 10.0, "feedback": "observed", "k_t": "known"},
    {"omega_c": 10.0, "feedback": "observed", "J": "prior"},
    {"omega_c": 10.0, "feedback": "observed", "J": "prior", "k_t": "known"},
    {"omega_c": 5.0, "feedback": "observed", "J": "prior", "k_t": "known"},
]


def run(n: int, cap: float = 0.005) -> dict[str, Any]:
    """Every variant, ``pd`` and ``pid`` (the benchmark's gains) on ``n`` scenarios from :data:`FIRST`."""
    from agents import make_controller  # noqa: PLC0415

    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415
    from addedinertia_env.learning import paired_batch  # noqa: PLC0415
    from addedinertia_env.learning.ars_residual import base_factory, base_params, capped_cost  # noqa: PLC0415

    suite = load_suite("hard-v0")
    seeds = list(range(FIRST, FIRST + n))
    oracle = paired_batch.run_batch(suite, seeds, None, oracle=[True] * n).rel_error
    rows = []

    def score(name: str, rel: np.ndarray, **knobs: Any) -> None:
        ce = np.abs(rel - oracle)
        rows.append({"entry": name, **knobs, "median_ce": float(np.nanmedian(ce)),
                     "mean_capped_cost": float(capped_cost(rel, oracle, cap).mean()),
                     "failures": int(np.sum(~np.isfinite(rel)))})

    for v in VARIANTS:
        knobs = {"omega_c": v["omega_c"], "feedback": v.get("feedback", "true"), "J": v.get("J", "true"),
                 "k_t": v.get("k_t", "true")}

        class Variant(DegradedOracle):
            def __init__(self, rig, omega_c=40.0, _k=knobs):
                super().__init__(rig, **_k)

        paired_batch.OracleController = Variant  # the oracle slots run the variant
        try:
            score("degraded oracle", paired_batch.run_batch(suite, seeds, None, oracle=[True] * n).rel_error, **knobs)
        finally:
            paired_batch.OracleController = OracleController
    score("pd", paired_batch.run_batch(suite, seeds, lambda: make_controller("pd")).rel_error)
    pid = base_params(suite, "pid")
    score("pid", paired_batch.run_batch(suite, seeds, base_factory("pid", pid)).rel_error)
    # the classical controllers pre-spin the flywheel in the hold; the oracle does not
    score("pid, no pre-spin", paired_batch.run_batch(suite, seeds, base_factory("pid", {**pid, "prespin": False})).rel_error)
    return {"suite": "hard-v0", "split": "train", "first_seed": FIRST, "scenarios": n, "cap": cap, "rows": rows}


def markdown(result: dict[str, Any]) -> str:
    """The result as a Markdown table."""
    lines = ["| entry | omega_c (rad/s) | feedback on | J | k_t | median control error | mean capped cost | failures |",
             "|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['entry']} | {r.get('omega_c', '-')} | {r.get('feedback', '-')} | {r.get('J', '-')} | "
                     f"{r.get('k_t', '-')} | {r['median_ce'] * 100:.3f} % | {r['mean_capped_cost'] * 100:.3f} % | "
                     f"{r['failures']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Command line (module doc); returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m addedinertia_env.reports.oracle_ablation",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", type=int, default=48)
    parser.add_argument("--out", type=Path, help="also write the result as JSON here")
    args = parser.parse_args(argv)
    result = run(args.scenarios)
    from addedinertia_env.foundation.machine import machine_line  # noqa: PLC0415

    result["command"] = "python -m addedinertia_env.reports.oracle_ablation " + " ".join(
        argv if argv is not None else sys.argv[1:])
    result["machine"] = machine_line()
    if args.out:
        atomic_write_text(args.out, json.dumps(result, indent=2) + "\n")
    print(markdown(result), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
