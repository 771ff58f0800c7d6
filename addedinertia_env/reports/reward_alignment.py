"""How well the environment's shaping terms agree with a suite's ranked score (issue 28 item 5).

On a benchmark suite the environment's reward is the ranked score alone (its terminal term:
``-100 min(|e|, 10 %)``, a failure at the cap; ``experiment.task.SCORE_ONLY``). The shaping
terms that the default reward adds elsewhere (tracking, energy, limits; ``RewardWeights()``)
are measured here against that score on an evaluation set: ``--scenarios`` training-split
scenarios of the suite (numbers from :data:`FIRST`, never the tuning or test split), each run
by every controller of ``--controllers`` on the batched engine at the suite's sample rate with
the drive held ``--action-repeat`` samples (the learned policy's rate), with the benchmark's
sensor noise of cycle 0 (:func:`addedinertia_env.learning.paired_batch.run_batch`).

For each term (and their sum with the default weights) it reports the Spearman rank
correlation with ``-score`` (higher return, better score, so +1 is aligned):

* ``pooled``: over all episodes (scenario and controller both vary);
* ``within``: per scenario across the controllers, averaged over the scenarios: what a
  learner choosing between behaviours on one scenario sees.

``python -m addedinertia_env.reports.reward_alignment --suite drive-v0 --scenarios 32 --json out.json``
prints a markdown table (docs/ENVIRONMENT.md, "The reward on a benchmark suite").
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from addedinertia_env.bench.score import CAP
from addedinertia_env.experiment.task import TRACKING_UNIT, RewardWeights
from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.learning.paired_batch import run_batch

FIRST = 800_000_000  # training-split scenario numbers of the evaluation set (the trainers draw elsewhere)
CONTROLLERS = ("zero", "oracle", "pd", "pid", "lqr", "feedforward-pd", "drive-aware")
TERMS = ("tracking", "energy", "limits", "shaping")


def shaping_terms(tracking_sq: np.ndarray, energy_J: np.ndarray, limit_samples: np.ndarray, dt: float,
                  weights: RewardWeights = RewardWeights()) -> dict[str, np.ndarray]:
    """Per-episode sums of the shaping terms (experiment/task.py's formula) and their total."""
    t = -weights.tracking * tracking_sq / TRACKING_UNIT**2 * dt
    e = -weights.energy * energy_J
    lim = -weights.limits * limit_samples * dt
    return {"tracking": t, "energy": e, "limits": lim, "shaping": t + e + lim}


def _maker(name: str):
    from agents import make_controller  # noqa: PLC0415
    from agents.zero import ZeroCurrent  # noqa: PLC0415

    if name == "zero":
        return ZeroCurrent
    return lambda: make_controller(name)


def measure(suite_name: str, scenarios: int, controllers=CONTROLLERS, action_repeat: int = 10) -> dict:
    """Run the evaluation set (module doc); returns per-episode scores and terms and the correlations."""
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    suite = load_suite(suite_name)
    seeds = list(range(FIRST, FIRST + scenarios))
    cpu0 = time.process_time()
    per: dict[str, dict] = {}
    for name in controllers:
        if name == "oracle":
            res = run_batch(suite, seeds, _maker("pd"), oracle=[True] * len(seeds), action_repeat=action_repeat)
        else:
            res = run_batch(suite, seeds, _maker(name), action_repeat=action_repeat)
        e = np.abs(res.rel_error)
        score = np.where(np.isfinite(e), np.minimum(e, CAP), CAP)
        terms = shaping_terms(res.tracking_sq, res.energy_J, res.limit_samples, 1e-3)
        per[name] = {"score": score.tolist(), "rel_error": res.rel_error.tolist(),
                     **{k: v.tolist() for k, v in terms.items()}}
    score = np.array([per[c]["score"] for c in controllers])  # (controllers, scenarios)
    corr = {}
    for term in TERMS:
        x = np.array([per[c][term] for c in controllers])
        pooled = spearmanr(x.ravel(), -score.ravel()).statistic
        within = []
        for j in range(score.shape[1]):  # a scenario where a term or the score is constant has no rank correlation
            if np.ptp(x[:, j]) > 0 and np.ptp(score[:, j]) > 0:
                within.append(spearmanr(x[:, j], -score[:, j]).statistic)
        corr[term] = {"pooled": float(pooled), "within": float(np.mean(within)) if within else float("nan"),
                      "within_scenarios": len(within)}
    return {"suite": suite_name, "scenarios": scenarios, "first": FIRST, "controllers": list(controllers),
            "action_repeat": action_repeat, "cpu_s": round(time.process_time() - cpu0, 1),
            "mean_score": {c: float(np.mean(per[c]["score"])) for c in controllers},
            "mean_terms": {c: {t: float(np.mean(per[c][t])) for t in TERMS} for c in controllers},
            "spearman": corr, "episodes": per}


def table(result: dict) -> str:
    """The markdown tables of :func:`measure`'s result."""
    lines = ["| controller | mean score | tracking | energy | limits | shaping (sum) |", "|---|---|---|---|---|---|"]
    for c in result["controllers"]:
        t = result["mean_terms"][c]
        lines.append(f"| `{c}` | {100 * result['mean_score'][c]:.2f} % | {t['tracking']:.2f} | {t['energy']:.2f} | "
                     f"{t['limits']:.3f} | {t['shaping']:.2f} |")
    lines += ["", "| term (default weight) | Spearman with -score, pooled | within a scenario (mean) |", "|---|---|---|"]
    w = RewardWeights()
    names = {"tracking": f"tracking ({w.tracking:g})", "energy": f"energy ({w.energy:g})",
             "limits": f"limits ({w.limits:g})", "shaping": "all shaping (default weights)"}
    for term in TERMS:
        s = result["spearman"][term]
        lines.append(f"| {names[term]} | {s['pooled']:+.2f} | {s['within']:+.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Command line; returns the exit status."""
    p = argparse.ArgumentParser(prog="python -m addedinertia_env.reports.reward_alignment", description=__doc__.split("\n")[0])
    p.add_argument("--suite", default="drive-v0")
    p.add_argument("--scenarios", type=int, default=32)
    p.add_argument("--action-repeat", type=int, default=10)
    p.add_argument("--json", type=Path, help="write the whole result here")
    args = p.parse_args(argv)
    result = measure(args.suite, args.scenarios, action_repeat=args.action_repeat)
    if args.json:
        atomic_write_text(args.json, json.dumps(result) + "\n")
    print(f"{args.suite}: {args.scenarios} training-split scenarios from {FIRST}, {len(result['controllers'])} "
          f"controllers, action repeat {args.action_repeat}; {result['cpu_s']} CPU-s\n")
    print(table(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
