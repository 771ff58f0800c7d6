"""Learning curves on the batched engine: the benchmark metric against agent steps and time.

One command per algorithm trains it for several seeds (or reuses runs already finished
in ``--runs``) and writes its section of ``docs/LEARNING.md`` (between the markers
``<!-- curves:ALGO:begin -->`` and ``<!-- curves:ALGO:end -->``) and its figure
``docs/figures/learning_ALGO.png``::

    nice -n 10 python -m addedinertia_env.reports.learning_curves --algo ppo --seeds 0 1 2 --timesteps 150000

Every run is ``addedinertia train`` with the shipped config (``configs/algos/ALGO.yaml``,
batched engine) and two evaluation settings made explicit here: ``--eval-every`` agent
steps, ``--eval-episodes`` episodes on the fixed evaluation seed 10000 (the same
scenarios at every evaluation and for every seed). The metric is the median
``|rel_error|`` of lambda66 over those episodes (the benchmark's score); the spread shown
is the minimum and maximum over seeds around their mean.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.atomic import save_figure
from addedinertia_env.reports.sections import replace_section

MARK = "<!-- curves:{algo}:{end} -->"
DOC = Path("docs/LEARNING.md")


def run_seed(algo: str, seed: int, timesteps: int, eval_every: int, eval_episodes: int, out: Path) -> dict[str, Any]:
    """Train one seed (unless its card is there already); returns its card."""
    card_path = out / "training_card.json"
    if card_path.exists():
        card = json.loads(card_path.read_text())
        if card["cost"]["env_steps"] >= timesteps:
            return card
    from addedinertia_env.learning.config import load_config  # noqa: PLC0415 - torch is heavy
    from addedinertia_env.learning.train import train  # noqa: PLC0415

    cfg = load_config(algo)
    cfg.n_timesteps = timesteps
    cfg.eval.update(freq=eval_every, n_episodes=eval_episodes)
    cfg.checkpoint_freq = timesteps  # one checkpoint, at the end
    if (out / "eval" / "curve.jsonl").exists():
        (out / "eval" / "curve.jsonl").unlink()  # a fresh run writes a fresh curve
    command = f"addedinertia train --algo {algo} --timesteps {timesteps} --seed {seed} (eval every {eval_every}, " \
              f"{eval_episodes} episodes)"
    return train(cfg, seed=seed, out=out, command=command)


def classical_reference(controller: str, eval_seed: int, n_episodes: int, action_repeat: int = 10) -> dict[str, Any]:
    """A classical controller on the evaluation episodes (single env ``reset(seed=eval_seed + k)``,
    the scenarios the batched evaluation runs): median ``|rel_error|`` and mean energy."""
    import gymnasium as gym  # noqa: PLC0415

    import addedinertia_env  # noqa: F401, PLC0415
    from agents import make_controller  # noqa: PLC0415 - agents depends on this package

    from addedinertia_env.experiment.runner import drive  # noqa: PLC0415

    rel, energy = [], []
    for k in range(n_episodes):
        env = gym.make("AddedInertia/ReverseStroke-v0", action_repeat=action_repeat).unwrapped
        env.reset(seed=eval_seed + k)
        drive(env.experiment, make_controller(controller))
        summary = env._score()
        rel.append(abs(summary["rel_error"]))
        energy.append(summary["energy_J"])
    rel_arr = np.array(rel)
    return {"controller": controller, "n": n_episodes, "median_abs_rel_error": float(np.nanmedian(rel_arr)),
            "failed": int(np.sum(~np.isfinite(rel_arr))), "mean_energy_J": float(np.mean(energy))}


def read_curve(out: Path) -> list[dict[str, Any]]:
    """The evaluation curve of a training run folder ``out`` (``eval/curve.jsonl``), one dict per evaluation."""
    path = out / "eval" / "curve.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def aggregate(curves: list[list[dict[str, Any]]], key: str) -> dict[str, np.ndarray]:
    """Per evaluation point (common to all seeds): agent steps, mean/min/max of ``key``, mean wall/CPU s."""
    n = min(len(c) for c in curves)
    steps = np.array([c["timesteps"] for c in curves[0][:n]])
    values = np.array([[c[k].get(key, np.nan) for k in range(n)] for c in curves])
    wall = np.array([[c[k].get("wall_s", np.nan) for k in range(n)] for c in curves])
    cpu = np.array([[c[k].get("cpu_s", np.nan) for k in range(n)] for c in curves])
    return {"steps": steps, "mean": np.nanmean(values, axis=0), "min": np.nanmin(values, axis=0),
            "max": np.nanmax(values, axis=0), "wall": np.nanmean(wall, axis=0), "cpu": np.nanmean(cpu, axis=0)}


def plot(algo: str, metric: dict[str, np.ndarray], reward: dict[str, np.ndarray], path: Path, title: str) -> None:
    """Plot the metric (median |rel_error|, %) against agent steps, wall and CPU minutes; writes the PNG ``path`` atomically."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, x, label in ((axes[0], metric["steps"], "agent steps"), (axes[1], metric["wall"] / 60, "wall time, min"),
                         (axes[2], metric["cpu"] / 60, "CPU time, min")):
        ax.plot(x, 100 * metric["mean"], "o-", label="median |rel_error|, mean of seeds")
        ax.fill_between(x, 100 * metric["min"], 100 * metric["max"], alpha=0.25, label="min..max over seeds")
        ax.set_xlabel(label)
        ax.set_ylabel("lambda66 error, %")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)


def section(algo: str, args, cards: list[dict[str, Any]], metric, reward, figure: str, command: str,
            reference: dict[str, Any] | None = None) -> str:
    """The marked Markdown section of one algorithm: the command, the machine, the figure, the curve table and the cost per seed (CPU minutes)."""
    from addedinertia_env.foundation.machine import machine_info  # noqa: PLC0415

    m = {**machine_info(), "load_avg_1_5_15": [round(x, 1) for x in os.getloadavg()]}
    cpu_min = [c["cost"]["cpu_s"] / 60 for c in cards]
    wall_min = [c["cost"]["wall_s"] / 60 for c in cards]
    final = [c["final_eval"].get("median_abs_rel_error", math.nan) for c in cards]
    lines = [MARK.format(algo=algo, end="begin"), "", f"### {algo}", "",
             f"`{command}` (seeds {', '.join(map(str, args.seeds))}; {args.timesteps:,} agent steps each; evaluation every "
             f"{args.eval_every:,} steps on {args.eval_episodes} fixed episodes, seed 10000). Machine: {m.get('cpu', '?')}, "
             f"nproc {m.get('nproc', '?')}, shared with other jobs (load average {m.get('load_avg_1_5_15', '?')} when "
             "written), so wall time is mostly waiting; CPU time is the cost.", "",
             f"![{algo} learning curves]({figure})", "",
             "| agent steps | median abs rel_error, mean of seeds | min .. max over seeds | mean eval reward | CPU min (mean) |",
             "|---:|---:|---:|---:|---:|"]
    for k in range(len(metric["steps"])):
        lines.append(f"| {int(metric['steps'][k]):,} | {100 * metric['mean'][k]:.3f} % | {100 * metric['min'][k]:.3f} .. "
                     f"{100 * metric['max'][k]:.3f} % | {reward['mean'][k]:.2f} | {metric['cpu'][k] / 60:.1f} |")
    lines += ["", f"Final evaluation (median |rel_error| per seed): "
              f"{', '.join(f'{100 * v:.3f} %' for v in final)}. Cost per seed: "
              f"{', '.join(f'{c:.1f}' for c in cpu_min)} CPU-minutes, {', '.join(f'{w:.0f}' for w in wall_min)} wall minutes."]
    if reference:
        lines += ["", f"For scale: `{reference['controller']}` on the same {reference['n']} evaluation episodes (the single "
                  f"env, `reset(seed=10000 + k)`): median |rel_error| {100 * reference['median_abs_rel_error']:.3f} %, "
                  f"mean energy {reference['mean_energy_J']:.2f} J, {reference['failed']} failed estimates."]
    lines += ["", MARK.format(algo=algo, end="end")]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Regenerate ``one algorithm's section of docs/LEARNING.md and its figure`` (the command is in the module docstring; training runs in ``--runs`` are reused when finished; returns 2 for out-of-range options); ``argv`` as on the command line; returns 0."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--algo", required=True, choices=["ppo", "sac", "td3", "recurrent-ppo"])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--timesteps", type=int, default=150_000)
    p.add_argument("--eval-every", type=int, default=None, help="agent steps between evaluations (default: timesteps / 6)")
    p.add_argument("--eval-episodes", type=int, default=16)
    p.add_argument("--runs", default="out/curves", help="folder of the training runs (reused when finished)")
    p.add_argument("--doc", default=str(DOC))
    p.add_argument("--reference", default="lqr", help="classical controller run on the same evaluation episodes "
                                                       "for scale ('none': skip)")
    args = p.parse_args(argv)
    if args.timesteps < 1000 or args.eval_episodes < 1 or not args.seeds:
        print(f"learning_curves: --timesteps {args.timesteps} (>= 1000), --eval-episodes {args.eval_episodes} (>= 1), "
              f"--seeds {args.seeds} (at least one): out of range", file=sys.stderr)
        return 2
    args.eval_every = args.eval_every or max(args.timesteps // 6, 1)
    cards, curves = [], []
    for seed in args.seeds:
        out = Path(args.runs) / args.algo / f"seed{seed}"
        print(f"{args.algo} seed {seed} -> {out}", file=sys.stderr)
        cards.append(run_seed(args.algo, seed, args.timesteps, args.eval_every, args.eval_episodes, out))
        curves.append(read_curve(out))
    metric = aggregate(curves, "median_abs_rel_error")
    reward = aggregate(curves, "mean_reward")
    doc = Path(args.doc)
    fig_dir = doc.parent / "figures"
    fig_dir.mkdir(exist_ok=True)
    fig = fig_dir / f"learning_{args.algo.replace('-', '_')}.png"
    command = "python -m addedinertia_env.reports.learning_curves " + shlex.join(sys.argv[1:] if argv is None else argv)
    plot(args.algo, metric, reward, fig, f"{args.algo}, batched engine, {len(args.seeds)} seeds")
    reference = None if args.reference == "none" else classical_reference(args.reference, 10000, args.eval_episodes)
    text = section(args.algo, args, cards, metric, reward, os.path.relpath(fig, doc.parent), command, reference)
    replace_section(doc, text, MARK.format(algo=args.algo, end="begin"), MARK.format(algo=args.algo, end="end"),
                    heading="## Learning curves on the batched engine")
    print(f"wrote {doc} ({args.algo}) and {fig}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
