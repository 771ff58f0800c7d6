"""A learned residual controller for a benchmark suite (hard-v0), trained on the benchmark's own paired score.

What is learned: a linear correction on top of a classical base controller, both acting at
the suite's drive rate (100 Hz on hard-v0, ``action_repeat`` = 10 samples)::

    x = clip((obs - mean) / std, -5, 5)          # frozen statistics of the base's own episodes
    r = clip(W x + b, -1, 1)                      # the policy (22 weights + 1 bias)
    action = clip(base(obs) + scale * r, -1, 1)   # agents/residual.py, as on the benchmark

``W = 0, b = 0`` at the start: the first policy *is* the base controller.

Objective (training split only, never the test split): the benchmark's ranked score, the
control error ``|e - e_oracle|`` paired by scenario (``e``: lambda66 error of the energy
method as written), measured on the batched engine (:mod:`.paired_batch`): each
generation draws ``scenarios`` fresh training scenarios, runs the oracle on them once
and every candidate on the same scenarios and sensor noise (common random numbers), and
scores a candidate by ``mean(min(|e - e_oracle|, cap))`` (a failed identification costs
``cap``). The trainer reads simulator truth to score; the policy only sees the task's
observation.

Algorithm: Augmented Random Search (Mania, Guy and Recht 2018, "Simple random search
provides a competitive approach to reinforcement learning", V1-t): ``directions``
Gaussian directions, each evaluated at ``theta +- noise * delta``; the best ``top``
directions (by the better of their two scores) step ``theta`` by
``step / (top * sigma_R) * sum (R+ - R-) delta``. Every generation also scores the
current policy and the bare base on the same scenarios: the learning curve is their
paired difference, against agent steps and CPU time.

Cost is CPU time of this process (``time.process_time``; one process, BLAS on one thread).
``python -m addedinertia_env.learning.ars_residual --help``; docs/LEARNING.md.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np


from addedinertia_env.foundation.atomic import atomic_target, atomic_write_text
from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.task import OBSERVATION_FIELDS
from addedinertia_env.learning.paired_batch import run_batch

CLIP_X = 5.0  # normalised observations are clipped to +-5
TRAIN_SEED_STRIDE = 1_000_003  # training scenario numbers of run ``seed``: disjoint streams per seed


class LinearPolicy:
    """``r = clip(W clip((obs - mean) / std, -5, 5) + b, -1, 1)`` on batches of observations."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, theta: np.ndarray | None = None):
        self.mean = np.asarray(mean, dtype=np.float64)
        self.std = np.asarray(std, dtype=np.float64)
        n = len(self.mean)
        self.theta = np.zeros(n + 1) if theta is None else np.asarray(theta, dtype=np.float64).copy()

    def features(self, obs: np.ndarray) -> np.ndarray:
        """Observations (n, n_obs) normalised with the frozen statistics and clipped to +-5."""
        return np.clip((np.asarray(obs, dtype=np.float64) - self.mean) / self.std, -CLIP_X, CLIP_X)

    def __call__(self, obs: np.ndarray, theta: np.ndarray | None = None) -> np.ndarray:
        """Corrections (n,) float32 in [-1, 1] for observations (n, n_obs) (``theta``: other parameters)."""
        th = self.theta if theta is None else theta
        x = self.features(np.atleast_2d(obs))
        return np.clip(x @ th[:-1] + th[-1], -1.0, 1.0).astype(np.float32)


def base_params(suite, base: str) -> dict[str, Any]:
    """The parameters ``base`` runs with on ``suite``'s benchmark (its gains tuned on the suite's
    tuning split, as ``Suite.task`` loads them), pinned for training and the policy's metadata."""
    from agents import make_controller  # noqa: PLC0415
    from agents.tuned import load_tuned  # noqa: PLC0415

    tuned = load_tuned(base, suite.tuned_path) if suite.tuned_path is not None else {}
    c = make_controller(base, tuned=False, **tuned) if tuned else make_controller(base)
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in getattr(c, "params", {}).items()} if tuned else {}


def base_factory(base: str, params: dict[str, Any]) -> Callable[[], Controller]:
    """A maker of fresh ``base`` controllers with the pinned gains ``params`` (:func:`base_params`;
    empty: the controller's defaults), as the batched trainers (ARS, DAgger) build their base."""
    from agents import make_controller  # noqa: PLC0415

    return (lambda: make_controller(base, tuned=False, **params)) if params else (lambda: make_controller(base))


def capped_cost(rel: np.ndarray, rel_oracle: np.ndarray, cap: float) -> np.ndarray:
    """Per-episode training cost: min(|e - e_oracle|, cap), cap for a failure (of either)."""
    c = np.abs(rel - rel_oracle)
    return np.where(np.isfinite(c), np.minimum(c, cap), cap)


def train(out: Path, *, suite_name: str = "hard-v0", base: str = "pid", seed: int = 0, scale: float = 0.1,
          generations: int = 30, scenarios: int = 12, directions: int = 4, top: int = 2, step: float = 0.02,
          noise: float = 0.03, cap: float = 0.005, cpu_minutes: float = 30.0, action_repeat: int = 10,
          log=print) -> dict[str, Any]:
    """Train (module doc); writes ``out/curve.jsonl`` (one line per generation) and ``out/policy.npz``;
    returns the training card. Stops after ``generations`` or ``cpu_minutes`` of CPU time."""
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    out.mkdir(parents=True, exist_ok=True)
    suite = load_suite(suite_name)
    pinned = base_params(suite, base)
    make_base = base_factory(base, pinned)
    rng = np.random.default_rng(seed)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    next_scenario = seed * TRAIN_SEED_STRIDE
    env_steps = 0
    episodes = 0

    def draw(m: int) -> list[int]:
        nonlocal next_scenario
        seeds = list(range(next_scenario, next_scenario + m))
        next_scenario += m
        return seeds

    # Observation statistics from the base's own episodes (frozen from then on).
    seeds0 = draw(scenarios)
    first = run_batch(suite, seeds0, make_base, keep_observations=True, action_repeat=action_repeat)
    env_steps += first.agent_steps
    episodes += len(seeds0)
    mean = first.observations.mean(axis=0)
    std = np.maximum(first.observations.std(axis=0), 1e-3)
    policy = LinearPolicy(mean, std)
    dim = len(policy.theta)
    command = " ".join(["python -m addedinertia_env.learning.ars_residual", *sys.argv[1:]])

    def write_card() -> dict[str, Any]:
        """The training card so far (rewritten every generation: a stopped run keeps its cost)."""
        cpu_s = time.process_time() - cpu0
        card = {"algo": "ars", "suite": suite_name, "split": "train", "base": base, "base_params": pinned,
                "seed": seed, "scale": scale, "action_repeat": action_repeat, "generations_done": len(history),
                "hyperparams": {"generations": generations, "scenarios": scenarios, "directions": directions,
                                "top": top, "step": step, "noise": noise, "cap": cap, "cpu_minutes": cpu_minutes},
                "cost": {"env_steps": env_steps, "episodes": episodes, "cpu_s": round(cpu_s, 1),
                         "cpu_minutes": round(cpu_s / 60.0, 2), "wall_s": round(time.perf_counter() - wall0, 1)},
                "command": command}
        atomic_write_text(out / "training_card.json", json.dumps(card, indent=2) + "\n")
        return card

    (out / "curve.jsonl").write_text("")  # a fresh curve; close_generation appends a row a generation
    history: list[dict[str, Any]] = []
    for gen in range(generations):
        seeds = draw(scenarios)
        deltas = rng.standard_normal((directions, dim))
        thetas = [policy.theta] + [policy.theta + s * noise * d for d in deltas for s in (1.0, -1.0)]
        n_cand = len(thetas)
        # one batch: oracle, bare base, current policy, then the +- candidates; every group on the same seeds
        groups = [("oracle", None)] + [("base", None)] + [("policy", th) for th in thetas]
        batch_seeds, oracle_mask, which = [], [], []
        for g, (kind, _) in enumerate(groups):
            batch_seeds += seeds
            oracle_mask += [kind == "oracle"] * len(seeds)
            which += [g] * len(seeds)
        which = np.asarray(which)
        theta_rows = np.zeros((len(which), dim))
        use_policy = np.zeros(len(which), dtype=bool)
        for g, (kind, th) in enumerate(groups):
            if kind == "policy":
                theta_rows[which == g] = th
                use_policy[which == g] = True
        result = run_candidates(suite, batch_seeds, make_base, oracle_mask, policy, theta_rows, use_policy,
                                 scale, action_repeat)
        env_steps += result.agent_steps
        episodes += len(batch_seeds)
        m = len(seeds)
        rel = result.rel_error.reshape(len(groups), m)
        cost = np.stack([capped_cost(rel[g], rel[0], cap) for g in range(1, len(groups))])  # base, policy, candidates
        base_cost, center_cost = cost[0], cost[1]
        cand = cost[2:].reshape(directions, 2, m).mean(axis=2)  # (+, -) mean cost per direction
        reward = -cand
        ars_step(policy, reward, deltas, top, step)
        ce_base = np.abs(rel[1] - rel[0])
        ce_pol = np.abs(rel[2] - rel[0])
        row = {"generation": gen, "episodes": episodes, "agent_steps": env_steps,
               "cpu_s": round(time.process_time() - cpu0, 2), "wall_s": round(time.perf_counter() - wall0, 2),
               "scenarios": m, "candidates": n_cand,
               "base_mean_cost": float(base_cost.mean()), "policy_mean_cost": float(center_cost.mean()),
               "paired_mean_diff": float(np.mean(center_cost - base_cost)),
               "base_median_ce": float(np.nanmedian(ce_base)), "policy_median_ce": float(np.nanmedian(ce_pol)),
               "paired_median_diff": float(np.nanmedian(ce_pol - ce_base)),
               "theta_norm": float(np.linalg.norm(policy.theta))}
        message = (f"gen {gen}: cost base {row['base_mean_cost'] * 100:.4f} % policy {row['policy_mean_cost'] * 100:.4f} % "
                   f"(paired {row['paired_mean_diff'] * 100:+.4f} %), median ce base {row['base_median_ce'] * 100:.4f} % "
                   f"policy {row['policy_median_ce'] * 100:.4f} %, |theta| {row['theta_norm']:.3f}, "
                   f"cpu {row['cpu_s']:.0f} s, steps {env_steps}")
        if close_generation(out, policy, history, row, message, log, write_card, cpu0, cpu_minutes):
            break
    return write_card()


def run_candidates(suite, seeds, make_base, oracle_mask, policy: LinearPolicy, theta_rows, use_policy, scale,
                   action_repeat):
    """One batch of episodes (``seeds`` of ``suite``) where slot ``j`` runs the oracle (``oracle_mask[j]``),
    the bare base (correction 0) or the base plus the policy with parameters ``theta_rows[j]``
    (``use_policy[j]``); the correction is clipped to [-1, 1], scaled by ``scale`` (normalised action units),
    added to the base's action and held ``action_repeat`` samples. Returns :func:`.paired_batch.run_batch`'s BatchResult."""

    def corrections(obs: np.ndarray, slots: np.ndarray) -> np.ndarray:
        x = policy.features(obs)
        th = theta_rows[slots]
        r = np.clip(np.einsum("ij,ij->i", x, th[:, :-1]) + th[:, -1], -1.0, 1.0)
        return np.where(use_policy[slots], r, 0.0).astype(np.float32)

    return run_batch(suite, seeds, make_base, oracle=oracle_mask, policy=corrections, residual_scale=scale,
                     action_repeat=action_repeat)


# --- export ------------------------------------------------------------------------------------
def export_onnx(run: Path, onnx_path: Path, *, extra_card: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write the trained policy of ``run`` (``policy.npz``, ``training_card.json``) as ONNX with its
    metadata (``agents/onnx_policy.py``: a residual on ``base`` acting at ``policy_rate_hz``, board
    mode ``zoh``) and the card ``<stem>.json`` (:func:`.residual_export.export_residual`); returns the card."""
    import torch  # noqa: PLC0415 - torch is heavy
    from torch import nn  # noqa: PLC0415

    from addedinertia_env.learning.residual_export import export_residual  # noqa: PLC0415

    data = np.load(run / "policy.npz")
    train_card = json.loads((run / "training_card.json").read_text())
    policy = LinearPolicy(data["mean"], data["std"], data["theta"])

    class Linear(nn.Module):
        def __init__(self):
            super().__init__()
            self.register_buffer("mean", torch.as_tensor(policy.mean, dtype=torch.float32))
            self.register_buffer("std", torch.as_tensor(policy.std, dtype=torch.float32))
            self.register_buffer("w", torch.as_tensor(policy.theta[:-1, None], dtype=torch.float32))
            self.register_buffer("b", torch.as_tensor(policy.theta[-1:], dtype=torch.float32))

        def forward(self, obs):
            x = torch.clamp((obs - self.mean) / self.std, -CLIP_X, CLIP_X)
            return torch.clamp(x @ self.w + self.b, -1.0, 1.0)

    # the whole policy, to check the graph against (LinearPolicy(mean, std, theta))
    whole = {"linear_policy": {"mean": policy.mean.tolist(), "std": policy.std.tolist(),
                               "theta": policy.theta.tolist()}}
    return export_residual(Linear(), policy, train_card, onnx_path, algo="ars", card_extra=whole,
                           extra_card=extra_card)


def ars_step(policy, reward: np.ndarray, deltas: np.ndarray, top: int, step: float) -> None:
    """One update of basic random search (Mania et al. 2018, ARS V1-t) on ``policy.theta``: the ``top``
    directions by their better side's ``reward`` (directions x (+, -)), each weighted by its reward
    difference, the step divided by those rewards' standard deviation."""
    best = np.argsort(np.max(reward, axis=1))[::-1][:top]
    sigma = float(np.std(reward[best])) or 1.0
    policy.theta = policy.theta + step / (top * sigma) * np.sum(
        (reward[best, 0] - reward[best, 1])[:, None] * deltas[best], axis=0)


def append_curve_row(curve_path: Path, row: dict) -> None:
    """One generation's row appended to the run's ``curve.jsonl`` (a resumable log, one JSON object a line)."""
    with curve_path.open("a") as f:
        f.write(json.dumps(row) + "\n")


def close_generation(out: Path, policy, history: list, row: dict, message: str, log, write_card, cpu0: float,
                     cpu_minutes: float) -> bool:
    """A generation's books: its row kept and appended to ``out/curve.jsonl``, ``message`` logged, the
    policy and the card saved; True when the run's CPU budget (``cpu_minutes`` from ``cpu0``) is spent."""
    history.append(row)
    append_curve_row(out / "curve.jsonl", row)
    log(message)
    save_policy(out, policy)
    write_card()
    return time.process_time() - cpu0 > 60.0 * cpu_minutes


def save_policy(out: Path, policy) -> None:
    """The policy's normalisation and weights written atomically to ``out/policy.npz``."""
    with atomic_target(out / "policy.npz", suffix=".npz") as tmp:
        np.savez(tmp, mean=policy.mean, std=policy.std, theta=policy.theta)


def add_search_arguments(parser: argparse.ArgumentParser, *, suite: str, base: str, scale: float, generations: int,
                         scenarios: int, directions: int, top: int, noise: float, step: float = 0.02) -> None:
    """The random search's flags, shared by the ARS trainers (this one and score_ars), with each one's defaults."""
    parser.add_argument("--suite", default=suite)
    parser.add_argument("--base", default=base, help=f"classical base controller (default {base})")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scale", type=float, default=scale, help="largest correction, fraction of i_max")
    parser.add_argument("--generations", type=int, default=generations)
    parser.add_argument("--scenarios", type=int, default=scenarios, help="training scenarios per generation")
    parser.add_argument("--directions", type=int, default=directions)
    parser.add_argument("--top", type=int, default=top)
    parser.add_argument("--step", type=float, default=step)
    parser.add_argument("--noise", type=float, default=noise)


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The run folder and the optional export, shared by the ARS trainers (this one and score_ars)."""
    parser.add_argument("--out", type=Path, required=True, help="run folder (curve.jsonl, policy.npz, card)")
    parser.add_argument("--onnx", type=Path, help="also export the final policy here (with its .json card)")


def export_and_report(export, run: Path, onnx: Path | None) -> None:
    """Where ``onnx`` is given, export ``run``'s policy there with the trainer's ``export(run, onnx) -> card``
    and say what was written."""
    if onnx:
        card = export(run, onnx)
        print(f"wrote {onnx} ({card['size_bytes']} bytes, parity {card['parity_max_abs_diff']:.2e})")


def main(argv: list[str] | None = None) -> int:
    """Command line: train one seed (and optionally export it); returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m addedinertia_env.learning.ars_residual",
                                     description="Train (and export) a linear residual controller on a suite's "
                                                 "training split by random search on the paired benchmark score.")
    add_search_arguments(parser, suite="hard-v0", base="pid", scale=0.1, generations=30, scenarios=12, directions=4,
                         top=2, noise=0.03)
    parser.add_argument("--cap", type=float, default=0.005, help="per-episode cost cap (relative, 0.005 = 0.5 %%)")
    parser.add_argument("--cpu-minutes", type=float, default=30.0, help="stop after this much CPU time")
    add_run_arguments(parser)
    args = parser.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    train(args.out, suite_name=args.suite, base=args.base, seed=args.seed, scale=args.scale,
          generations=args.generations, scenarios=args.scenarios, directions=args.directions, top=args.top,
          step=args.step, noise=args.noise, cap=args.cap, cpu_minutes=args.cpu_minutes,
          log=lambda m: print(m, flush=True))
    export_and_report(export_onnx, args.out, args.onnx)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
