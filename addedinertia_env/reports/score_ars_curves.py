"""Learning curves of :mod:`addedinertia_env.learning.score_ars` runs (docs/LEARNING.md, drive suite).

Per run (a ``--out`` folder of the trainer): each generation's paired score difference,
policy minus its bare base on that generation's fresh training scenarios (negative: the
policy is better), against agent steps and against CPU minutes, with a running mean over
``--window`` generations; and the validation at the end (policy and base on scenarios no
generation drew, paired 95 % interval), read from the run's ``training_card.json``.

``python -m addedinertia_env.reports.score_ars_curves --runs out/train/score-ars-drive-v0-s0 ... --figure F.png --summary F.json``
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from addedinertia_env.foundation.atomic import atomic_write_text


def load_run(run: Path) -> dict:
    """A run's curve rows and training card."""
    rows = [json.loads(line) for line in (run / "curve.jsonl").read_text().splitlines() if line.strip()]
    card = json.loads((run / "training_card.json").read_text())
    return {"run": str(run), "rows": rows, "card": card}


def running_mean(x: np.ndarray, window: int) -> np.ndarray:
    """Mean of the last ``window`` values at each point (fewer at the start)."""
    c = np.cumsum(np.r_[0.0, x])
    i = np.arange(1, len(x) + 1)
    lo = np.maximum(0, i - window)
    return (c[i] - c[lo]) / (i - lo)


def summary(runs: list[dict], window: int) -> list[dict]:
    """One line per run: generations, cost, mean paired difference (all and the last ``window``), validation."""
    out = []
    for r in runs:
        d = np.array([row["paired_mean_diff"] for row in r["rows"]])
        c = r["card"]
        out.append({"run": r["run"], "suite": c["suite"], "base": c["base"], "seed": c["seed"], "generations": len(d),
                    "cpu_minutes": c["cost"]["cpu_minutes"], "env_steps": c["cost"]["env_steps"],
                    "episodes": c["cost"]["episodes"], "mean_paired_diff": float(d.mean()) if len(d) else None,
                    "last_window_paired_diff": float(d[-window:].mean()) if len(d) else None,
                    "validation": c.get("validation")})
    return out


def plot(runs: list[dict], path: Path, window: int) -> None:
    """The figure: paired difference against agent steps and CPU minutes."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for r in runs:
        d = 100 * np.array([row["paired_mean_diff"] for row in r["rows"]])
        steps = np.array([row["agent_steps"] for row in r["rows"]]) / 1e6
        cpu = np.array([row["cpu_s"] for row in r["rows"]]) / 60.0
        label = f"{r['card']['suite']} seed {r['card']['seed']} (base {r['card']['base']})"
        for ax, x in zip(axes, (steps, cpu)):
            line, = ax.plot(x, running_mean(d, window), lw=2, label=label)
            ax.plot(x, d, lw=0.6, alpha=0.5, color=line.get_color())
    for ax, xl in zip(axes, ("agent steps (millions, 100 Hz)", "CPU minutes")):
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel(xl)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("score: policy - base, paired (%)\n(thin: per generation; thick: running mean)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"ARS on the ranked score (mean min(|e|, 10 %)): running mean over {window} generations")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Command line; returns the exit status."""
    p = argparse.ArgumentParser(prog="python -m addedinertia_env.reports.score_ars_curves", description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=Path, nargs="+", required=True)
    p.add_argument("--window", type=int, default=5)
    p.add_argument("--figure", type=Path)
    p.add_argument("--summary", type=Path)
    args = p.parse_args(argv)
    runs = [load_run(r) for r in args.runs]
    s = summary(runs, args.window)
    if args.figure:
        plot(runs, args.figure, args.window)
    if args.summary:
        atomic_write_text(args.summary, json.dumps(s, indent=2) + "\n")
    for line in s:
        v = line["validation"]
        val = (f"validation {v['scenarios']}: base {100 * v['base_score']:.2f} % policy {100 * v['policy_score']:.2f} % "
               f"(paired {100 * v['mean_diff']:+.2f} %, CI {100 * v['ci95'][0]:+.2f} .. {100 * v['ci95'][1]:+.2f} %)"
               if v else "no validation")
        print(f"{line['run']}: {line['generations']} generations, {line['cpu_minutes']} CPU-min, mean paired "
              f"{100 * line['mean_paired_diff']:+.3f} % (last {args.window}: {100 * line['last_window_paired_diff']:+.3f} %); {val}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
