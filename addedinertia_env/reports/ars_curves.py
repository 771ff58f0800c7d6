"""Learning curves of the hard-v0 residual policies (:mod:`addedinertia_env.learning.ars_residual`),
the choice of the shipped seed on held-aside training scenarios, and its export.

``python -m addedinertia_env.reports.ars_curves --runs out/train/ars-hard-s0 out/train/ars-hard-s1
out/train/ars-hard-s2 --validate 24 --onnx agents/policies/hard_residual.onnx --figure
docs/figures/learning_hard_ars.png`` (``make hard-policy`` trains the runs first):

* the figure: per generation, the paired training cost of the current policy minus the
  bare base on that generation's fresh training scenarios (mean of ``min(|e - e_oracle|,
  cap)``), against agent steps and against CPU time; mean over the seeds and their range;
* validation: every run's final policy, the bare base and the oracle on the same
  ``--validate`` training-split scenarios (a range no run trained on; never the test
  split); the run with the lowest mean cost there is exported (ties: the lower seed);
* a JSON summary on stdout (and ``--summary FILE``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.atomic import atomic_write_text, save_figure
from addedinertia_env.foundation.machine import machine_line

VALIDATION_FIRST = 900_000_000  # training-split scenario numbers kept for validation (no run draws them)


def load_curve(run: Path) -> list[dict[str, Any]]:
    """The per-generation rows of a training run's ``curve.jsonl``."""
    return [json.loads(line) for line in (run / "curve.jsonl").read_text().splitlines() if line.strip()]


def validate(runs: list[Path], n: int, cap: float = 0.005) -> dict[str, Any]:
    """Each run's final policy, the base and the oracle on ``n`` validation scenarios of the training split."""
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415
    from addedinertia_env.learning.ars_residual import LinearPolicy, base_factory, capped_cost, run_candidates  # noqa: PLC0415

    cards = [json.loads((r / "training_card.json").read_text()) for r in runs]
    suite = load_suite(cards[0]["suite"])
    base, params, scale = cards[0]["base"], cards[0]["base_params"], cards[0]["scale"]
    policies = []
    for r in runs:
        d = np.load(r / "policy.npz")
        policies.append(LinearPolicy(d["mean"], d["std"], d["theta"]))
    seeds = list(range(VALIDATION_FIRST, VALIDATION_FIRST + n))
    # Oracle and base in one batch, then each run's policy (its own normalisation) on the same seeds.
    rel = {}
    first = run_candidates(suite, seeds * 2, base_factory(base, params), [True] * n + [False] * n,
                            policies[0], np.zeros((2 * n, len(policies[0].theta))), np.zeros(2 * n, dtype=bool),
                            scale, cards[0]["action_repeat"])
    rel["oracle"], rel["base"] = first.rel_error[:n], first.rel_error[n:]
    for r, p in zip(runs, policies):
        out = run_candidates(suite, seeds, base_factory(base, params), [False] * n, p,
                              np.tile(p.theta, (n, 1)), np.ones(n, dtype=bool), scale, cards[0]["action_repeat"])
        rel[r.name] = out.rel_error
    result: dict[str, Any] = {"scenarios": n, "first_seed": VALIDATION_FIRST, "cap": cap, "entries": {}}
    for name, e in rel.items():
        if name == "oracle":
            continue
        ce = np.abs(e - rel["oracle"])
        cost = capped_cost(e, rel["oracle"], cap)
        result["entries"][name] = {"mean_cost": float(cost.mean()), "median_ce": float(np.nanmedian(ce)),
                                   "failures": int(np.sum(~np.isfinite(e))),
                                   "paired_median_diff_vs_base": float(np.nanmedian(ce - np.abs(rel["base"] - rel["oracle"])))}
    best = min((r.name for r in runs), key=lambda k: (result["entries"][k]["mean_cost"], k))
    result["chosen"] = best
    return result


def figure(runs: list[Path], path: Path, title: str) -> None:
    """Write the learning-curve figure of ``runs`` (paired cost vs agent steps and CPU time; medians) to ``path``."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    curves = [load_curve(r) for r in runs]
    n = min(len(c) for c in curves)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    diff = np.array([[100 * row["paired_mean_diff"] for row in c[:n]] for c in curves])
    steps = np.array([[row["agent_steps"] for row in c[:n]] for c in curves]).mean(axis=0)
    cpu = np.array([[row["cpu_s"] / 60 for row in c[:n]] for c in curves]).mean(axis=0)
    for ax, x, label in ((axes[0], steps, "agent steps (100 Hz actions, all episodes)"),
                         (axes[1], cpu, "CPU minutes (mean over seeds)")):
        for r, d in zip(runs, diff):
            ax.plot(x, d, lw=0.8, alpha=0.5, label=r.name)
        ax.plot(x, diff.mean(axis=0), color="k", lw=2, label="mean of seeds")
        ax.fill_between(x, diff.min(axis=0), diff.max(axis=0), color="k", alpha=0.1, label="range")
        ax.axhline(0.0, color="r", lw=0.8)
        ax.set_xlabel(label)
        ax.set_ylabel("policy - base: mean capped |e - e_oracle|, %")
        ax.legend(fontsize=7)
    for r, c in zip(runs, curves):
        axes[2].plot([row["generation"] for row in c], [100 * row["policy_median_ce"] for row in c], lw=1,
                     label=f"{r.name} policy")
    base = np.array([[100 * row["base_median_ce"] for row in c[:n]] for c in curves]).mean(axis=0)
    axes[2].plot(np.arange(n), base, color="k", lw=1.5, ls="--", label="base (mean over seeds)")
    axes[2].set_xlabel("generation")
    axes[2].set_ylabel("median |e - e_oracle| on the generation's scenarios, %")
    axes[2].legend(fontsize=7)
    import textwrap  # noqa: PLC0415

    fig.suptitle("\n".join(textwrap.wrap(title, 180)), fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    """Command line (module doc); prints the JSON summary, returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m addedinertia_env.reports.ars_curves", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=Path, nargs="+", required=True)
    parser.add_argument("--validate", type=int, default=24, help="validation scenarios (training split)")
    parser.add_argument("--figure", type=Path, default=Path("docs/figures/learning_hard_ars.png"))
    parser.add_argument("--onnx", type=Path, help="export the chosen run's policy here (with its .json card)")
    parser.add_argument("--summary", type=Path, help="also write the JSON summary here")
    args = parser.parse_args(argv)
    import sys  # noqa: PLC0415

    command = " ".join(["python -m addedinertia_env.reports.ars_curves", *sys.argv[1:]])
    figure(args.runs, args.figure, f"hard-v0 residual (ARS on pid), {len(args.runs)} seeds. `{command}`. "
                                   f"{machine_line()}")
    summary: dict[str, Any] = {"command": command, "machine": machine_line(),
                               "runs": {r.name: json.loads((r / "training_card.json").read_text()) for r in args.runs}}
    if args.validate:
        summary["validation"] = validate(args.runs, args.validate)
    if args.onnx:
        from addedinertia_env.learning.ars_residual import export_onnx  # noqa: PLC0415

        chosen = summary.get("validation", {}).get("chosen", args.runs[0].name)
        run = next(r for r in args.runs if r.name == chosen)
        card = export_onnx(run, args.onnx, extra_card={"selection": {"chosen": chosen, "validation":
                                                                     summary.get("validation")}})
        summary["exported"] = {"path": str(args.onnx), "run": chosen, "size_bytes": card["size_bytes"],
                               "parity_max_abs_diff": card["parity_max_abs_diff"]}
    text = json.dumps(summary, indent=2)
    if args.summary:
        atomic_write_text(args.summary, text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
