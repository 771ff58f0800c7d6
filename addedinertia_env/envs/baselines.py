"""Reference returns of the environment: what a learned controller should beat.

``python -m addedinertia_env.envs.baselines [--episodes 5] [--seed 0]`` runs the same
randomised episodes (env seeds ``seed .. seed + episodes - 1``, default options) under:
``zero`` (no current), ``random`` (uniform actions), ``feedforward-pd`` at 1 kHz
(``action_repeat`` 1) and at 100 Hz (``action_repeat`` 10, the controller's own
``dt`` set to 10 ms through ``controller_context``), and prints one JSON object with,
per policy, the mean return, the mean of each reward term, the mean and the largest
``abs(rel_error)`` (a fraction, 0.01 = 1 %), the failed estimates and the mean energy.
:func:`table_block` is the reference-returns table of docs/ENVIRONMENT.md (errors in
percent), written there by ``python -m addedinertia_env.reports.environment_returns``.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any, Callable

import numpy as np

from agents import make_controller

from addedinertia_env.envs.reverse_stroke import ReverseStrokeEnv

Policy = Callable[[ReverseStrokeEnv, np.ndarray], np.ndarray]


def _zero(env: ReverseStrokeEnv, obs: np.ndarray) -> np.ndarray:
    return np.zeros(1, np.float32)


def _random(env: ReverseStrokeEnv, obs: np.ndarray) -> np.ndarray:
    return env.action_space.sample()


def _controller(name: str) -> Policy:
    state: dict[str, Any] = {}

    def policy(env: ReverseStrokeEnv, obs: np.ndarray) -> np.ndarray:
        if state.get("episode") is not env.experiment:  # a new episode: a fresh controller
            state["episode"] = env.experiment
            state["controller"] = make_controller(name)
            state["controller"].reset(env.controller_context())
        return state["controller"].predict(obs, deterministic=True)[0]

    return policy


POLICIES: dict[str, tuple[Callable[[], Policy], int]] = {
    "zero": (lambda: _zero, 10),
    "random": (lambda: _random, 10),
    "feedforward-pd@1kHz": (lambda: _controller("feedforward-pd"), 1),
    "feedforward-pd@100Hz": (lambda: _controller("feedforward-pd"), 10),
}


def evaluate(policy: Policy, action_repeat: int, seeds: list[int]) -> dict[str, Any]:
    """Run ``policy`` for one episode per seed with ``action_repeat``; returns the mean return,
    its reward terms, the median |rel_error| of lambda66, the failures and the motor energy (J).
    """
    env = ReverseStrokeEnv(action_repeat=action_repeat)
    returns, errors, failed, energy = [], [], 0, []
    terms: dict[str, list[float]] = {}
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        total, sums = 0.0, {}
        while True:
            obs, reward, terminated, truncated, info = env.step(policy(env, obs))
            total += reward
            for k, v in info["reward_terms"].items():
                sums[k] = sums.get(k, 0.0) + v
            if terminated or truncated:
                break
        returns.append(total)
        for k, v in sums.items():
            terms.setdefault(k, []).append(v)
        failed += bool(info["failed"])
        if math.isfinite(info["rel_error"]):
            errors.append(abs(info["rel_error"]))
        energy.append(info["energy_J"])
    return {"action_repeat": action_repeat, "mean_return": float(np.mean(returns)),
            "mean_terms": {k: float(np.mean(v)) for k, v in terms.items()},
            "mean_abs_rel_error": float(np.mean(errors)) if errors else math.nan,
            "max_abs_rel_error": float(np.max(errors)) if errors else math.nan,
            "failed": failed, "mean_energy_J": float(np.mean(energy))}


BEGIN, END = "<!-- baselines:begin -->", "<!-- baselines:end -->"
TERMS = ("tracking", "energy", "limits", "accuracy")


def _pct(x: float) -> str:
    return f"{100 * x:.3f} %" if math.isfinite(x) else "-"


def table_block(out: dict[str, Any], command: str, machine: str) -> str:
    """The doc's reference-returns block (between :data:`BEGIN` and :data:`END`) for ``out``."""
    seeds = out["seeds"]
    lines = [BEGIN,
             f"Measured with `{command}` (randomised scenarios, env seeds {seeds[0]}-{seeds[-1]}, default options and "
             f"weights) on {machine}. `|rel_error|` = |lambda66 estimate / truth - 1| in percent, over the "
             "episodes with an estimate; `failed`: episodes without one.",
             "",
             "| policy | action_repeat | mean return | " + " | ".join(TERMS)
             + " | mean \\|rel_error\\| | max \\|rel_error\\| | failed | mean energy |",
             "|---|---|---|" + "---|" * len(TERMS) + "---|---|---|---|"]
    for name in POLICIES:
        if name not in out:
            continue
        r = out[name]
        terms = " | ".join(f"{r['mean_terms'].get(k, 0.0):.3f}" if k == "limits" else f"{r['mean_terms'].get(k, 0.0):.2f}"
                           for k in TERMS)
        lines.append(f"| {name} | {r['action_repeat']} | {r['mean_return']:.2f} | {terms} | "
                     f"{_pct(r['mean_abs_rel_error'])} | {_pct(r['max_abs_rel_error'])} | "
                     f"{r['failed']}/{out['episodes']} | {r['mean_energy_J']:.1f} J |")
    return "\n".join(lines + [END]) + "\n"


def run(episodes: int, seed: int = 0, policies: list[str] | None = None) -> dict[str, Any]:
    """The reference returns of ``policies`` (default: all of :data:`POLICIES`) on env seeds
    ``seed .. seed + episodes - 1``, as the JSON object :func:`main` prints."""
    seeds = list(range(seed, seed + episodes))
    out: dict[str, Any] = {"episodes": episodes, "seeds": seeds}
    for name in policies or list(POLICIES):
        make, repeat = POLICIES[name]
        out[name] = evaluate(make(), repeat, seeds)
    return out


def main(argv: list[str] | None = None) -> int:
    """Print the reference returns of :data:`POLICIES` as JSON; ``argv`` as on the command line; returns 0."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--policies", nargs="+", default=list(POLICIES), choices=list(POLICIES))
    args = ap.parse_args(argv)
    print(json.dumps(run(args.episodes, args.seed, args.policies), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
