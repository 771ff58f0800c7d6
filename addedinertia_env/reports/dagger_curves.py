"""Learning curves of the hard-v0 DAgger students (:mod:`addedinertia_env.learning.dagger`), the
choice of the shipped seed on held-aside training scenarios, and its export.

``python -m addedinertia_env.reports.dagger_curves --group "pid, hold gate=out/train/dagger-s0,..."
[--group ...] --validate 48 --onnx agents/policies/hard_dagger.onnx --figure
docs/figures/learning_hard_dagger.png --summary docs/figures/learning_hard_dagger.json``
(``make hard-policy-dagger`` trains the runs first):

* the figure: per DAgger iteration, the imitation loss on the states the student visits
  (before the refit) and the median control error ``|e - e_oracle|`` on the held-aside
  training scenarios of the runs (:data:`~addedinertia_env.learning.dagger.VALIDATION_FIRST`),
  against agent steps and against CPU time; each group (a configuration, several seeds):
  mean over its seeds and their range; the bare base of the group as a dotted line;
* validation: the chosen student of every run of the *first* group, its base, ``pd`` and
  the oracle on ``--validate`` other training-split scenarios (from
  :data:`SELECTION_FIRST`, which no run trains or selects on; never the test split); the
  run with the lowest median control error there is exported (ties: the lower seed);
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

SELECTION_FIRST = 900_000_000  # training-split scenario numbers kept for the choice of seed


def load_curve(run: Path) -> list[dict[str, Any]]:
    """The per-iteration rows of a DAgger run's ``curve.jsonl`` (the first: the bare base)."""
    return [json.loads(line) for line in (run / "curve.jsonl").read_text().splitlines() if line.strip()]


def parse_group(text: str) -> tuple[str, list[Path]]:
    """``"label=run1,run2"`` -> (label, [run paths]); a clear error otherwise."""
    label, sep, runs = text.partition("=")
    if not sep or not runs.strip():
        raise SystemExit(f"--group {text!r}: expected 'label=run_folder[,run_folder...]'")
    return label.strip(), [Path(r.strip()) for r in runs.split(",") if r.strip()]


def paired_median_diff(a: np.ndarray, b: np.ndarray, n_boot: int = 2000, seed: int = 0) -> dict[str, float]:
    """Median over scenarios of ``a - b`` (control errors; a failure is an infinite error, both
    failed: 0) with its 95 % bootstrap interval over the scenarios (``n_boot`` resamples)."""
    a = np.where(np.isfinite(a), a, np.inf)
    b = np.where(np.isfinite(b), b, np.inf)
    with np.errstate(invalid="ignore"):
        d = np.where(np.isinf(a) & np.isinf(b), 0.0, a - b)
    rng = np.random.default_rng(seed)
    boots = np.median(d[rng.integers(0, len(d), (n_boot, len(d)))], axis=1)
    return {"median": float(np.median(d)), "ci_low": float(np.quantile(boots, 0.025)),
            "ci_high": float(np.quantile(boots, 0.975)), "n": int(len(d))}


def validate(runs: list[Path], n: int, cap: float = 0.005) -> dict[str, Any]:
    """The chosen student of every run, its base, ``pd`` and the oracle on ``n`` scenarios of the
    training split from :data:`SELECTION_FIRST`; the run with the lowest median control error is chosen."""
    from agents import make_controller  # noqa: PLC0415

    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415
    from addedinertia_env.learning.ars_residual import base_factory, capped_cost  # noqa: PLC0415
    from addedinertia_env.learning.dagger import load_student  # noqa: PLC0415
    from addedinertia_env.learning.paired_batch import run_batch  # noqa: PLC0415

    cards = [json.loads((r / "training_card.json").read_text()) for r in runs]
    suite = load_suite(cards[0]["suite"])
    make_base = base_factory(cards[0]["base"], cards[0]["base_params"])
    repeat, scale = cards[0]["action_repeat"], cards[0]["scale"]
    seeds = list(range(SELECTION_FIRST, SELECTION_FIRST + n))
    first = run_batch(suite, seeds * 2, make_base, oracle=[True] * n + [False] * n, action_repeat=repeat)
    rel = {"oracle": first.rel_error[:n], f"base ({cards[0]['base']})": first.rel_error[n:]}
    rel["pd"] = run_batch(suite, seeds, lambda: make_controller("pd"), action_repeat=repeat).rel_error
    for r, card in zip(runs, cards):
        student = load_student(r / "policy.npz")
        rel[r.name] = run_batch(suite, seeds, base_factory(card["base"], card["base_params"]), policy=student,
                                residual_scale=card["scale"], action_repeat=repeat).rel_error
    ce = {k: np.abs(v - rel["oracle"]) for k, v in rel.items() if k != "oracle"}
    result: dict[str, Any] = {"scenarios": n, "first_seed": SELECTION_FIRST, "cap": cap, "entries": {}}
    for name, c in ce.items():
        result["entries"][name] = {"median_ce": float(np.nanmedian(c)),
                                   "mean_capped_cost": float(capped_cost(rel[name], rel["oracle"], cap).mean()),
                                   "failures": int(np.sum(~np.isfinite(rel[name]))),
                                   "paired_vs_pd": paired_median_diff(c, ce["pd"]) if name != "pd" else None}
    result["chosen"] = min((r.name for r in runs), key=lambda k: (result["entries"][k]["median_ce"], k))
    return result


def figure(groups: list[tuple[str, list[Path]]], path: Path, title: str) -> None:
    """Write the learning-curve figure of the run groups (imitation loss and held-aside median
    control error, against agent steps and CPU time; mean and range over seeds) to ``path``."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for g, (label, runs) in enumerate(groups):
        colour = colours[g % len(colours)]
        curves = [load_curve(r) for r in runs]
        m = min(len(c) for c in curves)
        for row, key, scale in ((0, "onpolicy_loss", 1.0), (1, "val_median_ce", 100.0)):
            for col, xkey, xscale in ((0, "agent_steps", 1e-6), (1, "cpu_s", 1 / 60.0)):
                ax = axes[row, col]
                # row 0 of a curve is the bare base (no student yet): a dotted line below
                x = np.array([[c[i][xkey] * xscale for i in range(1, m)] for c in curves])
                y = np.array([[(c[i][key] if c[i][key] is not None else np.nan) * scale for i in range(1, m)]
                              for c in curves])
                for xi, yi in zip(x, y):
                    ax.plot(xi, yi, color=colour, lw=0.6, alpha=0.5)
                ax.plot(x.mean(axis=0), y.mean(axis=0), color=colour, lw=2, label=f"{label} ({len(runs)} seeds)")
                ax.fill_between(x.mean(axis=0), y.min(axis=0), y.max(axis=0), color=colour, alpha=0.15)
                if key == "val_median_ce":
                    base = np.mean([c[0][key] for c in curves]) * scale
                    ax.axhline(base, color=colour, ls=":", lw=1.2, label=f"bare base of {label}")
    axes[0, 0].set_ylabel("imitation loss on visited states\n(MSE of the correction, before refit)")
    axes[1, 0].set_ylabel("median |e - e_oracle| on 48 held-aside\ntraining scenarios, %")
    for col, xl in ((0, "agent steps (millions, 100 Hz; rollouts + validation)"), (1, "CPU minutes (one process)")):
        axes[1, col].set_xlabel(xl)
        axes[0, col].set_xlabel(xl)
    axes[0, 0].set_yscale("log")
    axes[0, 1].set_yscale("log")
    axes[1, 1].legend(fontsize=7)
    fig.suptitle(title + "\n" + machine_line(), fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Command line (module doc); returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m addedinertia_env.reports.dagger_curves", description=__doc__.split("\n")[0])
    parser.add_argument("--group", action="append", required=True, help="'label=run1,run2,...'; the first group is validated and exported")
    parser.add_argument("--validate", type=int, default=48, help="selection scenarios (training split)")
    parser.add_argument("--onnx", type=Path, help="export the chosen run's student here (with its .json card)")
    parser.add_argument("--figure", type=Path)
    parser.add_argument("--summary", type=Path)
    parser.add_argument("--title", default="DAgger: the oracle distilled into a residual controller, hard-v0 training split")
    args = parser.parse_args(argv)
    groups = [parse_group(g) for g in args.group]
    for _, runs in groups:
        for r in runs:
            if not (r / "curve.jsonl").is_file():
                raise SystemExit(f"{r}: no curve.jsonl; expected a run folder of addedinertia_env.learning.dagger")
    summary: dict[str, Any] = {"groups": {label: [str(r) for r in runs] for label, runs in groups},
                               "command": "python -m addedinertia_env.reports.dagger_curves " + " ".join(
                                   f"'{a}'" if " " in a else a for a in (argv if argv is not None else __import__("sys").argv[1:]))}
    if args.figure:
        figure(groups, args.figure, args.title)
    if args.validate > 0:
        summary["validation"] = validate(groups[0][1], args.validate)
        if args.onnx:
            from addedinertia_env.learning.dagger import export_onnx  # noqa: PLC0415

            chosen = next(r for r in groups[0][1] if r.name == summary["validation"]["chosen"])
            card = export_onnx(chosen, args.onnx, extra_card={"selection": summary["validation"]})
            summary["exported"] = {"run": str(chosen), "onnx": str(args.onnx), "size_bytes": card["size_bytes"],
                                   "parity_max_abs_diff": card["parity_max_abs_diff"]}
    text = json.dumps(summary, indent=2) + "\n"
    if args.summary:
        atomic_write_text(args.summary, text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
