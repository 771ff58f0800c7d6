"""A learned residual controller trained on a suite's ranked score itself (drive-v0, issue 28).

Where :mod:`.ars_residual` (hard-v0) minimises the paired control error against the
oracle, this trainer minimises what the leaderboard ranks on suites whose oracle is a
reference, not a floor (``bench/score.py``, ``capped-mean-v1``)::

    s = min(|e|, CAP)   (CAP = 10 %; a failed run or identification scores CAP)

with ``e`` the lambda66 error of the energy method as written, each scenario run once per
candidate on the batched engine (:func:`.paired_batch.run_batch`: the suite's scenarios,
drive flaws and loop, the benchmark's sensor noise of cycle 0), all candidates of a
generation on the same scenarios (common random numbers). The trainer reads the truth to
score; the policy sees the task's observation only.

What is learned: a correction on a classical base, both acting once per drive set-point
(``action_repeat`` samples: 100 Hz, the two-rate bench's rate), gated by the phase so that
it can shift the hold's pre-spin and reshape the reverse stroke separately::

    x = clip((obs - mean) / std, -5, 5)                       # frozen statistics of the base's episodes
    z = [x * is_hold, x * is_reverse, is_hold, is_reverse]     # 2 n_obs + 2 features
    r = clip(theta . z, -1, 1)
    action = clip(base(obs) + scale * r, -limit, limit)        # agents/residual.py, as on the benchmark

``limit`` (``--action-limit``, a fraction of i_max; 1 by default) is the policy's own current
limit: below 1 the command never reaches the drive's limit, where the energy method rejects the
samples and a run can fail (a failure scores the cap). The bare base of the curves and of the
validation runs with the same limit.

``theta = 0`` at the start: the first policy *is* the base. Algorithm: Augmented Random
Search V1-t (Mania, Guy and Recht 2018) as in :mod:`.ars_residual`. Each generation also
scores the bare base and the current policy on its scenarios (the learning curve: their
paired difference against agent steps and CPU time). At the end both are scored on a
validation set of training-split scenarios that no generation drew (numbers from
:data:`VALIDATION_FIRST`), with a paired bootstrap interval of the mean difference.

Cost is CPU time of this process (``time.process_time``; one process, BLAS on one thread).
``python -m addedinertia_env.learning.score_ars --help``; docs/LEARNING.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.bench.score import CAP, bootstrap_mean
from addedinertia_env.bench.versions import row_fields as version_fields
from addedinertia_env.sim.forces import gear_ratio
from addedinertia_env.experiment.task import OBSERVATION_FIELDS
from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.learning.ars_residual import (add_run_arguments, add_search_arguments, ars_step, base_factory,
                                                    base_params, close_generation, export_and_report)
from addedinertia_env.learning.paired_batch import run_batch

CLIP_X = 5.0  # normalised observations are clipped to +-5
TRAIN_SEED_STRIDE = 1_000_003  # training scenario numbers of run ``seed``: disjoint streams per seed
VALIDATION_FIRST = 900_000_000  # validation scenario numbers (training split), never drawn in training
HOLD = list(OBSERVATION_FIELDS).index("is_hold")
REVERSE = list(OBSERVATION_FIELDS).index("is_reverse")


def episode_scores(rel_error: np.ndarray, cap: float = CAP) -> np.ndarray:
    """The ranked score per episode (bench/score.py): ``min(|e|, cap)``, ``cap`` for a failure (nan)."""
    e = np.abs(np.asarray(rel_error, dtype=float))
    return np.where(np.isfinite(e), np.minimum(e, cap), cap)


class GatedLinearPolicy:
    """``r = clip(theta . [x is_hold, x is_reverse, is_hold, is_reverse], -1, 1)`` (module doc)."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, theta: np.ndarray | None = None):
        self.mean = np.asarray(mean, dtype=np.float64)
        self.std = np.asarray(std, dtype=np.float64)
        self.dim = 2 * len(self.mean) + 2
        self.theta = np.zeros(self.dim) if theta is None else np.asarray(theta, dtype=np.float64).copy()
        if self.theta.shape != (self.dim,):
            raise ValueError(f"GatedLinearPolicy: theta of shape {self.theta.shape}; expected ({self.dim},)")

    def features(self, obs: np.ndarray) -> np.ndarray:
        """The gated features ``z`` (n, 2 n_obs + 2) of observations (n, n_obs)."""
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        x = np.clip((obs - self.mean) / self.std, -CLIP_X, CLIP_X)
        hold, rev = obs[:, HOLD:HOLD + 1], obs[:, REVERSE:REVERSE + 1]
        return np.concatenate([x * hold, x * rev, hold, rev], axis=1)

    def __call__(self, obs: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
        """Corrections (n,) float32 in [-1, 1] (``theta``: other parameters than the policy's own)."""
        th = self.theta if theta is None else theta
        return np.clip(self.features(obs) @ th, -1.0, 1.0).astype(np.float32)


def running_params(base: str) -> dict[str, Any]:
    """The parameters ``base`` runs with when built by name (configs/controllers/tuned.yaml or its defaults),
    pinned so that a later re-tune does not change the base under a trained correction."""
    from agents import make_controller  # noqa: PLC0415

    params = getattr(make_controller(base), "params", {}) or {}
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in params.items()}


def run_thetas(suite, seeds, make_base, policy: GatedLinearPolicy, theta_rows: np.ndarray, use_policy: np.ndarray,
               scale: float, action_repeat: int, action_limit: float = 1.0):
    """One batch: slot ``j`` runs the base plus the policy with ``theta_rows[j]`` (``use_policy[j]``) or the
    bare base; returns :func:`.paired_batch.run_batch`'s result."""

    def corrections(obs: np.ndarray, slots: np.ndarray) -> np.ndarray:
        z = policy.features(obs)
        r = np.clip(np.einsum("ij,ij->i", z, theta_rows[slots]), -1.0, 1.0)
        return np.where(use_policy[slots], r, 0.0).astype(np.float32)

    return run_batch(suite, seeds, make_base, policy=corrections, residual_scale=scale, action_repeat=action_repeat,
                     action_limit=action_limit)


def evaluate(suite, seeds: list[int], make_base, policy: GatedLinearPolicy, scale: float,
             action_repeat: int, action_limit: float = 1.0) -> dict[str, Any]:
    """Base and policy on ``seeds`` (training split), paired: their mean scores, the mean difference
    policy - base with its 95 % bootstrap interval, and the per-episode errors."""
    m = len(seeds)
    theta_rows = np.zeros((2 * m, policy.dim))
    theta_rows[m:] = policy.theta
    use = np.r_[np.zeros(m, bool), np.ones(m, bool)]
    res = run_thetas(suite, seeds + seeds, make_base, policy, theta_rows, use, scale, action_repeat, action_limit)
    s = episode_scores(res.rel_error)
    base, pol = s[:m], s[m:]
    lo, hi = bootstrap_mean(pol - base)
    return {"scenarios": m, "first": seeds[0], "base_score": float(base.mean()), "policy_score": float(pol.mean()),
            "mean_diff": float(np.mean(pol - base)), "ci95": [lo, hi],
            "base_failures": int(np.sum(~np.isfinite(res.rel_error[:m]))),
            "policy_failures": int(np.sum(~np.isfinite(res.rel_error[m:]))),
            "base_rel_error": res.rel_error[:m].tolist(), "policy_rel_error": res.rel_error[m:].tolist(),
            "agent_steps": res.agent_steps}


def train(out: Path, *, suite_name: str = "drive-v0", base: str = "feedforward-pd", seed: int = 0,
          scale: float = 0.3, generations: int = 100, scenarios: int = 16, directions: int = 8, top: int = 4,
          step: float = 0.02, noise: float = 0.05, cpu_minutes: float = 25.0, action_repeat: int = 10,
          validate: int = 64, action_limit: float = 1.0, log=print) -> dict[str, Any]:
    """Train (module doc); writes ``out/curve.jsonl``, ``out/policy.npz``, ``out/training_card.json``;
    returns the card. Stops after ``generations`` or ``cpu_minutes`` of CPU time (then validates).
    ``action_limit`` (0-1 of i_max): the policy's command, base plus correction, stays inside it
    (:func:`agents.residual.residual_action`), in training, validation and on the bench."""
    if not 0.0 < action_limit <= 1.0:
        raise ValueError(f"score_ars.train: action_limit = {action_limit}; expected a fraction of i_max in (0, 1]")
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    out.mkdir(parents=True, exist_ok=True)
    suite = load_suite(suite_name)
    pinned = base_params(suite, base) or running_params(base)  # the suite's tuned gains, else those it runs with
    make_base = base_factory(base, pinned)
    rng = np.random.default_rng(seed)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    next_scenario = seed * TRAIN_SEED_STRIDE
    cost = {"env_steps": 0, "episodes": 0}
    geared = gear_ratio(suite.scenario(next_scenario).rig) > 1.0  # the drive suites: the gear loss is booked
    version = version_fields(geared=geared, ranked=suite.ranked)["score_version"]  # what the suite's rows carry

    def draw(m: int) -> list[int]:
        nonlocal next_scenario
        seeds = list(range(next_scenario, next_scenario + m))
        next_scenario += m
        return seeds

    first = run_batch(suite, draw(scenarios), make_base, keep_observations=True, action_repeat=action_repeat,
                      policy=lambda obs, slots: np.zeros(len(obs), np.float32), action_limit=action_limit)
    cost["env_steps"] += first.agent_steps
    cost["episodes"] += scenarios
    policy = GatedLinearPolicy(first.observations.mean(axis=0), np.maximum(first.observations.std(axis=0), 1e-3))
    command = " ".join(["python -m addedinertia_env.learning.score_ars", *sys.argv[1:]])
    history: list[dict[str, Any]] = []
    validation: dict[str, Any] | None = None

    def write_card() -> dict[str, Any]:
        cpu_s = time.process_time() - cpu0
        card = {"algo": "ars-score", "objective": f"{version}: mean of min(|e|, {CAP:g}), failure at the cap",
                "suite": suite_name, "split": "train", "base": base, "base_params": pinned, "seed": seed,
                "scale": scale, "action_limit": action_limit, "action_repeat": action_repeat,
                "features": "gated-linear (x is_hold, x is_reverse, is_hold, is_reverse)", "generations_done": len(history),
                "hyperparams": {"generations": generations, "scenarios": scenarios, "directions": directions,
                                "top": top, "step": step, "noise": noise, "cpu_minutes": cpu_minutes,
                                "validate": validate},
                "cost": {**cost, "cpu_s": round(cpu_s, 1), "cpu_minutes": round(cpu_s / 60.0, 2),
                         "wall_s": round(time.perf_counter() - wall0, 1)},
                "validation": validation, "command": command}
        atomic_write_text(out / "training_card.json", json.dumps(card, indent=2) + "\n")
        return card

    (out / "curve.jsonl").write_text("")  # a fresh curve; close_generation appends a row a generation
    for gen in range(generations):
        seeds = draw(scenarios)
        deltas = rng.standard_normal((directions, policy.dim))
        thetas = [np.zeros(policy.dim), policy.theta] + [policy.theta + s * noise * d for d in deltas
                                                         for s in (1.0, -1.0)]
        m = len(seeds)
        theta_rows = np.repeat(np.array(thetas), m, axis=0)
        use = np.ones(len(theta_rows), bool)
        use[:m] = False  # the bare base
        res = run_thetas(suite, seeds * len(thetas), make_base, policy, theta_rows, use, scale, action_repeat,
                         action_limit)
        cost["env_steps"] += res.agent_steps
        cost["episodes"] += len(theta_rows)
        s = episode_scores(res.rel_error).reshape(len(thetas), m)
        base_s, center_s = s[0], s[1]
        reward = -s[2:].reshape(directions, 2, m).mean(axis=2)  # (+, -) per direction
        ars_step(policy, reward, deltas, top, step)
        row = {"generation": gen, "episodes": cost["episodes"], "agent_steps": cost["env_steps"],
               "cpu_s": round(time.process_time() - cpu0, 2), "wall_s": round(time.perf_counter() - wall0, 2),
               "scenarios": m, "base_score": float(base_s.mean()), "policy_score": float(center_s.mean()),
               "paired_mean_diff": float(np.mean(center_s - base_s)),
               "theta_norm": float(np.linalg.norm(policy.theta))}
        message = (f"gen {gen}: score base {100 * row['base_score']:.3f} % policy {100 * row['policy_score']:.3f} % "
                   f"(paired {100 * row['paired_mean_diff']:+.3f} %), |theta| {row['theta_norm']:.3f}, "
                   f"cpu {row['cpu_s']:.0f} s, steps {cost['env_steps']}")
        if close_generation(out, policy, history, row, message, log, write_card, cpu0, cpu_minutes):
            break
    if validate:
        vseeds = list(range(VALIDATION_FIRST, VALIDATION_FIRST + validate))
        validation = evaluate(suite, vseeds, make_base, policy, scale, action_repeat, action_limit)
        cost["env_steps"] += validation.pop("agent_steps")
        cost["episodes"] += 2 * validate
        log(f"validation ({validate} scenarios from {VALIDATION_FIRST}): base {100 * validation['base_score']:.3f} % "
            f"policy {100 * validation['policy_score']:.3f} % (paired {100 * validation['mean_diff']:+.3f} %, 95 % CI "
            f"{100 * validation['ci95'][0]:+.3f} .. {100 * validation['ci95'][1]:+.3f} %)")
    return write_card()


def finish(out: Path, validate: int = 64, log=print) -> dict[str, Any]:
    """Validate the policy of a run stopped before its end (``policy.npz`` and the card of its last
    generation) as :func:`train` does at its end, and add the validation and its cost to the card."""
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    card = json.loads((out / "training_card.json").read_text())
    if card.get("validation"):
        raise ValueError(f"{out}: the run is validated already (training_card.json has a validation)")
    cpu0 = time.process_time()
    suite = load_suite(card["suite"])
    make_base = base_factory(card["base"], card["base_params"])
    vseeds = list(range(VALIDATION_FIRST, VALIDATION_FIRST + validate))
    validation = evaluate(suite, vseeds, make_base, load_policy(out), card["scale"], card["action_repeat"],
                          card.get("action_limit", 1.0))
    cost = card["cost"]
    cost["env_steps"] += validation.pop("agent_steps")
    cost["episodes"] += 2 * validate
    cost["cpu_s"] = round(cost["cpu_s"] + time.process_time() - cpu0, 1)
    cost["cpu_minutes"] = round(cost["cpu_s"] / 60.0, 2)
    card["validation"] = validation
    card["stopped"] = "training stopped by hand after its last generation; validated by --finish"
    atomic_write_text(out / "training_card.json", json.dumps(card, indent=2) + "\n")
    log(f"validation ({validate} scenarios from {VALIDATION_FIRST}): base {100 * validation['base_score']:.3f} % "
        f"policy {100 * validation['policy_score']:.3f} % (paired {100 * validation['mean_diff']:+.3f} %)")
    return card


def load_policy(run: Path) -> GatedLinearPolicy:
    """The trained policy of run folder ``run`` (``policy.npz``)."""
    data = np.load(run / "policy.npz")
    return GatedLinearPolicy(data["mean"], data["std"], data["theta"])


def export_onnx(run: Path, onnx_path: Path, *, extra_card: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write run ``run``'s policy as ONNX with its metadata and card (:func:`.residual_export.export_residual`:
    a residual on the base acting at ``policy_rate_hz``, board mode ``zoh``); returns the card."""
    import torch  # noqa: PLC0415 - torch is heavy
    from torch import nn  # noqa: PLC0415

    from addedinertia_env.learning.residual_export import export_residual  # noqa: PLC0415

    policy = load_policy(run)
    train_card = json.loads((run / "training_card.json").read_text())
    n = len(policy.mean)

    class GatedLinear(nn.Module):
        def __init__(self):
            super().__init__()
            self.register_buffer("mean", torch.as_tensor(policy.mean, dtype=torch.float32))
            self.register_buffer("std", torch.as_tensor(policy.std, dtype=torch.float32))
            th = torch.as_tensor(policy.theta, dtype=torch.float32)
            self.register_buffer("w_hold", th[:n, None].clone())
            self.register_buffer("w_rev", th[n:2 * n, None].clone())
            self.register_buffer("b", th[2 * n:].clone())

        def forward(self, obs):
            x = torch.clamp((obs - self.mean) / self.std, -CLIP_X, CLIP_X)
            hold, rev = obs[:, HOLD:HOLD + 1], obs[:, REVERSE:REVERSE + 1]
            y = hold * (x @ self.w_hold) + rev * (x @ self.w_rev) + hold * self.b[0] + rev * self.b[1]
            return torch.clamp(y, -1.0, 1.0)

    # parity on observations in both phases (the gates are 0/1 fields)
    rng = np.random.default_rng(0)
    obs = rng.uniform(-10, 10, (1000, n)).astype(np.float32)
    obs[:, HOLD] = (np.arange(1000) % 3 == 0).astype(np.float32)
    obs[:, REVERSE] = (np.arange(1000) % 3 == 1).astype(np.float32)
    whole = {"gated_linear_policy": {"mean": policy.mean.tolist(), "std": policy.std.tolist(),
                                     "theta": policy.theta.tolist()}}
    return export_residual(GatedLinear(), policy, train_card, onnx_path, algo="ars-score", parity_obs=obs,
                           card_extra=whole, extra_card=extra_card)


def main(argv: list[str] | None = None) -> int:
    """Command line: train one seed (and optionally export it); returns the exit status."""
    p = argparse.ArgumentParser(prog="python -m addedinertia_env.learning.score_ars",
                                description="Train (and export) a gated linear residual controller on a suite's "
                                            "training split by random search on the ranked score (capped mean |e|).")
    add_search_arguments(p, suite="drive-v0", base="feedforward-pd", scale=0.3, generations=100, scenarios=16,
                         directions=8, top=4, noise=0.05)
    p.add_argument("--cpu-minutes", type=float, default=25.0, help="stop training after this much CPU time")
    p.add_argument("--validate", type=int, default=64, help="validation scenarios at the end (0: none)")
    p.add_argument("--action-repeat", type=int, default=10, help="rig samples per action (10: 100 Hz)")
    p.add_argument("--action-limit", type=float, default=1.0,
                   help="the policy's own current limit, a fraction of i_max in (0, 1]: base + correction is clipped "
                        "to it (below 1: a margin from the drive's limit, where the energy method rejects samples)")
    add_run_arguments(p)
    p.add_argument("--finish", action="store_true", help="do not train: validate the run in --out that was stopped "
                                                         "before its end (then export with --onnx)")
    args = p.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if args.finish:
        finish(args.out, validate=args.validate, log=lambda m: print(m, flush=True))
        export_and_report(export_onnx, args.out, args.onnx)
        return 0
    train(args.out, suite_name=args.suite, base=args.base, seed=args.seed, scale=args.scale,
          generations=args.generations, scenarios=args.scenarios, directions=args.directions, top=args.top,
          step=args.step, noise=args.noise, cpu_minutes=args.cpu_minutes, action_repeat=args.action_repeat,
          validate=args.validate, action_limit=args.action_limit, log=lambda m: print(m, flush=True))
    export_and_report(export_onnx, args.out, args.onnx)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
