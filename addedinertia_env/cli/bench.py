"""``addedinertia bench run|leaderboard|tune``: the controller benchmark.

* ``bench run --suite NAME --controller NAME [--split test] [--seeds N] [--out FILE.jsonl]``
  one JSON line per episode (fields: addedinertia_env/bench/runner.py);
* ``bench leaderboard FILES... [--format md|html|json|scores] [--out FILE]`` ranks controllers
  (``scores``: the runs x scenarios score matrix rliable reads, an ``.npz`` at ``--out`` and a JSON sidecar);
* ``bench tune --suite NAME --controller NAME`` tunes on the suite's tuning split only
  and stores the gains in configs/controllers/tuned.yaml (addedinertia_env/bench/tuning.py).
"""

from __future__ import annotations

import os
import re
import shlex
import sys
from pathlib import Path

from addedinertia_env.cli.common import BadInput, emit_json, info, positive_int


def register(sub) -> None:
    """Add ``bench`` with its actions ``run``, ``leaderboard`` and ``tune`` to the subparsers ``sub``."""
    p = sub.add_parser("bench", help="benchmark controllers on a suite of scenarios; rank them")
    bsub = p.add_subparsers(dest="bench_command", required=True, metavar="ACTION")

    r = bsub.add_parser("run", help="run a controller on a suite; one JSON line per episode")
    r.add_argument("--suite", required=True, help="suite name in configs/suites/ or a .yaml path")
    r.add_argument("--controller", required=True,
                   help="pd, feedforward-pd, pid, lqr, ilc, mpc, onnx:PATH or module:factory; or a reference row: "
                        "oracle (truth-based tracking, the floor) or zero (0 A, no control)")
    r.add_argument("--entry-kind", choices=("classical", "learned"), default=None,
                   help="what a submission is (default: from its card file, else classical; docs/SUBMITTING.md)")
    r.add_argument("--train-cost", default=None, metavar="ENV_STEPS,CPU_MINUTES",
                   help="a learned submission's training cost, e.g. 40960,6.5 (default: from its card file)")
    r.add_argument("--split", default="test", choices=("test", "tuning", "all"), help="scenario split (default: test)")
    r.add_argument("--seeds", type=positive_int, default=None, help="only the first N scenarios of the split")
    r.add_argument("--out", default=None, help="JSON-lines file (default: out/bench/SUITE-CONTROLLER.jsonl)")
    r.add_argument("--jobs", type=positive_int, default=min(2, os.cpu_count() or 1), help="worker processes")
    r.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    r.add_argument("--allow-failures", action="store_true",
                   help="exit 0 when some (not all) episodes failed: a leaderboard counts them as infinite errors "
                        "(by default any failed episode gives exit status 1)")
    r.add_argument("--force", action="store_true",
                   help="start --out over even if it holds rows (by default a run resumes the rows of the same "
                        "controller, suite and split, and refuses a file holding others)")
    r.add_argument("--json", action="store_true",
                   help="print a one-object summary on stdout (median_abs_error: median |estimate / truth - 1|, "
                        "a fraction, 0.01 = 1 %%; failed episodes count as infinite)")
    r.set_defaults(func=run_bench)

    lb = bsub.add_parser("leaderboard", help="rank controllers from bench rows")
    lb.add_argument("files", nargs="+", metavar="FILE.jsonl")
    lb.add_argument("--format", choices=("md", "html", "json", "scores"), default="md",
                    help="md, html, json: the leaderboard; scores: the runs x scenarios matrix of each controller's "
                         "per-episode score (.npz, rliable's score_dict by dict(numpy.load(FILE))) and FILE.json "
                         "(scenarios, what the score is); needs --out")
    lb.add_argument("--out", default=None, help="output file (figures go to FILE's folder, in figures/); default stdout")
    lb.add_argument("--title", default="Controller leaderboard")
    lb.set_defaults(func=run_leaderboard)

    t = bsub.add_parser("tune", help="tune a classical controller on the suite's tuning split")
    t.add_argument("--suite", default="standard-v0")
    t.add_argument("--controller", required=True)
    t.add_argument("--candidates", type=positive_int, default=8, help="random-search candidates (incl. defaults)")
    t.add_argument("--scenarios", type=positive_int, default=8, help="tuning-split scenarios per candidate")
    t.add_argument("--seed", type=int, default=0, help="random-search seed")
    t.add_argument("--jobs", type=positive_int, default=min(2, os.cpu_count() or 1))
    t.add_argument("--dry-run", action="store_true", help="do not write configs/controllers/tuned.yaml")
    t.add_argument("--no-progress", action="store_true")
    t.add_argument("--json", action="store_true")
    t.set_defaults(func=run_tune)


def _check_controller(name: str) -> None:
    """Refuse an unknown controller before any episode runs (exit status 2)."""
    from agents.registry import CLASSICAL, UnknownController, load_factory  # noqa: PLC0415

    from addedinertia_env.bench.runner import REFERENCES  # noqa: PLC0415

    if name in REFERENCES or name in CLASSICAL:
        return
    if name.startswith("onnx:"):
        from agents.registry import make_controller  # noqa: PLC0415

        make_controller(name)  # loads and validates the policy (OnnxPolicyError names the file: exit 2)
        return
    if ":" not in name:
        raise BadInput(f"--controller {name!r}: expected one of {', '.join(sorted(CLASSICAL))}, "
                       "onnx:PATH or module:factory")
    try:
        load_factory(name)
    except UnknownController as e:
        raise BadInput(str(e)) from None


def run_bench(args) -> int:
    """Run ``addedinertia bench run`` with the parsed ``args``; one JSON line per episode is appended to ``--out`` (a run resumes the rows already there and retries the failed ones); returns 0, or 1 when episodes failed (how many and the first reason on stderr; with ``--allow-failures`` only when all failed); bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.bench.resume import RowAppender, drop_failed, failure_reason, is_failed, prepare_output  # noqa: PLC0415
    from addedinertia_env.bench.runner import run_tasks  # noqa: PLC0415
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    suite = load_suite(args.suite)
    _check_controller(args.controller)
    from addedinertia_env.bench.submission import SubmissionError, declared_entry  # noqa: PLC0415

    try:
        entry = declared_entry(args.controller, args.entry_kind, args.train_cost)
    except SubmissionError as e:
        raise BadInput(str(e)) from None
    scenarios = suite.scenarios(args.split)
    if args.seeds is not None:
        scenarios = scenarios[:args.seeds]
    tasks = [suite.task(sc, args.controller, entry=entry) for sc in scenarios]
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", args.controller)
    out = Path(args.out or f"out/bench/{suite.name}-{safe}.jsonl")
    key = {"controller": args.controller, "suite": suite.name, "split": args.split}
    from addedinertia_env.foundation.atomic import remove_stale_temps  # noqa: PLC0415

    for stale in remove_stale_temps(out.parent):
        info(f"bench: removed {stale}, a temporary file of a killed earlier run")
    from addedinertia_env.bench.versions import row_fields as version_fields  # noqa: PLC0415
    from addedinertia_env.sim.forces import gear_ratio  # noqa: PLC0415

    geared = any(gear_ratio(sc.rig) > 1.0 for sc in scenarios)
    version = version_fields(geared=geared, ranked=suite.ranked)["score_version"]
    kept, notes = prepare_output(out, key, force=args.force, version=version)
    for note in notes:
        info(f"bench: {note}")
    kept, retry = drop_failed(out, kept)
    if retry:
        info(f"bench: {len(retry)} episode(s) of {out} failed in an earlier run; running them again "
             f"(first: {failure_reason(retry[0])})")
    done = {r["scenario"]: r for r in kept}
    todo = [t for t in tasks if t.scenario.name not in done]
    if done:
        info(f"bench: resuming {out}: {len(tasks) - len(todo)} of {len(tasks)} episode(s) already there, "
             f"running the other {len(todo)} (--force starts over)")
    info(f"bench: {len(todo)} scenario(s) of {suite.name}/{args.split} with {args.controller}, {args.jobs} job(s)")
    try:
        with RowAppender(out) as appender:
            command = invoked_command(args)

            def land(row: dict) -> None:
                row["command"] = command  # the leaderboard header says how its rows were made
                appender.append(row)

            new = run_tasks(todo, jobs=args.jobs, progress=not args.no_progress, desc=args.controller,
                            on_row=land)
    except KeyboardInterrupt:
        info(f"bench: interrupted; the finished episodes are in {out}: run the same command to resume")
        raise
    by_name = {**done, **{r["scenario"]: r for r in new}}
    rows = [by_name[t.scenario.name] for t in tasks if t.scenario.name in by_name]
    failed = [r for r in rows if is_failed(r)]
    failures = len(failed)
    info(f"wrote {len(new)} row(s) to {out}; {len(rows)} of this run's {len(tasks)} there ({failures} failure(s))")
    if args.json:
        import numpy as np  # noqa: PLC0415

        errs = [abs(r["rel_error"]) if r["rel_error"] is not None else float("inf") for r in rows]
        emit_json({"suite": suite.name, "split": args.split, "controller": args.controller, "rows": len(rows),
                   "out": str(out), "failures": failures, "median_abs_error": float(np.median(errs))})
    if failed:
        info(f"bench: {failures} of {len(rows)} episode(s) failed; first: {failure_reason(failed[0])}")
        if not (args.allow_failures and failures < len(rows)):
            info("bench: exit status 1 (a failed episode counts as an infinite error on the leaderboard; "
                 "fix the cause and run the same command again: the failed episodes are retried"
                 + ("" if args.allow_failures else "; --allow-failures accepts some failed episodes") + ")")
            return 1
    return 0


def invoked_command(args) -> str:
    """The command line actually run, as ``addedinertia ...``."""
    return "addedinertia " + " ".join(shlex.quote(a) for a in getattr(args, "argv", sys.argv[1:]))


def run_leaderboard(args) -> int:
    """Run ``addedinertia bench leaderboard`` with the parsed ``args``; writes (or prints) the ranking as Markdown, HTML or JSON; returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.bench.leaderboard import RowsError, load_rows, public  # noqa: PLC0415
    from addedinertia_env.bench.report import build  # noqa: PLC0415
    from addedinertia_env.foundation.jsonable import plain  # noqa: PLC0415

    from addedinertia_env.bench.score import ScoreVersionError, check_versions  # noqa: PLC0415

    try:
        rows = load_rows(args.files)
        check_versions(rows, where=", ".join(map(str, args.files)))  # one score version per board
    except (RowsError, ScoreVersionError) as e:
        raise BadInput(str(e)) from None
    out = Path(args.out) if args.out else None
    if args.format == "scores":
        from addedinertia_env.bench.leaderboard import scores  # noqa: PLC0415
        from addedinertia_env.bench.statistics import score_matrix, write_scores  # noqa: PLC0415

        if out is None:
            raise BadInput("bench leaderboard --format scores: expected --out FILE.npz (a binary matrix file)")
        what, per_controller = scores(rows)
        scenarios, matrices = score_matrix(per_controller)
        if not scenarios:
            raise BadInput(f"{', '.join(args.files)}: no scenario that every controller ran; expected rows of the "
                           "same suite and split for each controller")
        path, side = write_scores(out, scenarios, matrices, what)
        info(f"wrote {path} ({len(matrices)} controllers x {len(scenarios)} scenarios) and {side}")
        return 0
    if args.format == "json":
        from addedinertia_env.bench.leaderboard import summarise  # noqa: PLC0415
        from addedinertia_env.bench.verdict import discrimination, verdict  # noqa: PLC0415

        entries = summarise(rows)
        disc = discrimination(entries)
        from addedinertia_env.bench.versions import check_versions  # noqa: PLC0415

        obj = plain({"title": args.title, "entries": public(entries), "files": args.files,
                              "score_version": check_versions({"rows": rows}),
                              "verdict": verdict(entries),
                              "discrimination": {k: v for k, v in disc.items()} if disc else None,
                              "command": invoked_command(args)})
        if out is not None:
            import json  # noqa: PLC0415

            from addedinertia_env.foundation.atomic import atomic_write_text  # noqa: PLC0415

            atomic_write_text(out, json.dumps(obj, indent=1, allow_nan=False, default=str) + "\n")
        emit_json(obj)
        return 0
    text, _ = build(rows, invoked_command(args), args.format, out, args.title)
    if out is None:
        sys.stdout.write(text)
    else:
        from addedinertia_env.foundation.atomic import atomic_write_text  # noqa: PLC0415

        atomic_write_text(out, text)
        info(f"wrote {out}" + (f" and its figures in {out.parent / 'figures'}" if args.format == "md" else ""))
    return 0


def run_tune(args) -> int:
    """Run ``addedinertia bench tune`` with the parsed ``args``; tunes the controller on the suite's tuning split and writes its tuned file (not with ``--dry-run``); returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.bench.tuning import tune, write_tuned  # noqa: PLC0415

    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    suite = load_suite(args.suite)
    try:
        result = tune(args.controller, suite=args.suite, candidates=args.candidates, scenarios=args.scenarios,
                      seed=args.seed, jobs=args.jobs, progress=not args.no_progress)
    except ValueError as e:
        raise BadInput(str(e)) from None
    command = (f"addedinertia bench tune --suite {args.suite} --controller {args.controller} "
               f"--candidates {args.candidates} --scenarios {args.scenarios} --seed {args.seed}")
    for t in result["trials"]:
        info(f"  score {100 * t['score']:.3f} %  energy {t['median_energy_J']:.2f} J  {t['params']}")
    info(f"best: {result['params']} (ranked score {100 * result['score']:.3f} % on the tuning split)")
    if not args.dry_run:
        info(f"wrote {write_tuned(args.controller, result, command, path=suite.tuned_path)}")
    if args.json:
        emit_json({"controller": args.controller, "suite": args.suite, **result, "command": command})
    return 0
