"""``addedinertia perf``: simulation throughput, MuJoCo single rig against the batched rig."""

from __future__ import annotations

import os
from pathlib import Path

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.cli.common import BadInput, emit_json, info, positive_int


def register(sub) -> None:
    """Add the ``perf`` subcommand and its options to the subparsers ``sub`` (``addedinertia perf --help``)."""
    p = sub.add_parser("perf", help="measure simulation throughput (single MuJoCo rig vs batched rig)")
    p.add_argument("--max-envs", type=positive_int, default=16384,
                   help="largest batch; the sweep is 1, 4, 16, ... up to it (default 16384)")
    p.add_argument("--seconds", type=float, default=0.3, help="wall time of one measurement, s (default 0.3)")
    p.add_argument("--repeats", type=positive_int, default=5, help="repeats per measurement; the best counts")
    p.add_argument("--vector-envs", type=positive_int, default=1024,
                   help="environments of the batched vector env for the whole-task figures (default 1024)")
    p.add_argument("--vector-steps", type=positive_int, default=200,
                   help="timed agent steps of the batched vector env (default 200)")
    p.add_argument("--vector-warmup", type=int, default=600,
                   help="agent steps before the timing starts, so that the first episodes spread out (default 600)")
    p.add_argument("--vector-seconds", type=float, default=20.0,
                   help="wall time of the single-env and gym.make_vec sync measurements, s (default 20)")
    p.add_argument("--vector-repeats", type=positive_int, default=1,
                   help="runs of the batched env's headline row, each from a fresh env; the median run counts (default 1)")
    p.add_argument("--vector-workers", type=positive_int, default=None,
                   help="processes of the batched env's headline row (default: the CPU cores, at most 2)")
    p.add_argument("--out", default=None, help="write the report to this Markdown file (e.g. docs/PERFORMANCE.md)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia perf`` with the parsed ``args``; measures steps per second of the single and the batched rig and prints the table (``--out``: writes it); returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.reports.perf import plot_time_vs_n, render_markdown, run_perf, with_kept_part  # noqa: PLC0415

    if not (0 < args.seconds <= 60):
        raise BadInput(f"--seconds {args.seconds!r}: expected a time in (0, 60] s")
    sizes = [1]
    while sizes[-1] * 4 <= args.max_envs:
        sizes.append(sizes[-1] * 4)
    if sizes[-1] != args.max_envs:
        sizes.append(args.max_envs)
    if not (0 < args.vector_seconds <= 600):
        raise BadInput(f"--vector-seconds {args.vector_seconds!r}: expected a time in (0, 600] s")
    result = run_perf(tuple(sizes), seconds=args.seconds, repeats=args.repeats, progress=info)
    from addedinertia_env.vector.measure import measure_vector_task  # noqa: PLC0415

    if args.vector_warmup < 0:
        raise BadInput(f"--vector-warmup {args.vector_warmup}: expected 0 or more agent steps")
    if args.vector_workers is not None and args.vector_workers > args.vector_envs:
        raise BadInput(f"--vector-workers {args.vector_workers}: expected at most --vector-envs ({args.vector_envs})")
    result.update(measure_vector_task(args.vector_envs, steps=args.vector_steps, warmup_steps=args.vector_warmup,
                                      seconds=args.vector_seconds, workers=args.vector_workers, progress=info,
                                      repeats=args.vector_repeats))
    result["machine"]["load_avg_at_end"] = [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None
    info(f"single MuJoCo env: {result['single_env_steps_per_s']:,.0f} steps/s; batched n={result['n_envs']}: "
         f"{result['batched_physics_steps_per_s']:,.0f} steps/s; ratio {result['ratio_batched_to_single']:,.0f}x")
    if args.out:
        out = Path(args.out)
        if not out.parent.is_dir():
            raise BadInput(f"--out {args.out!r}: folder {str(out.parent)!r} does not exist")
        fig_dir = out.parent / "figures"
        fig_dir.mkdir(exist_ok=True)
        fig = fig_dir / "perf_time_vs_n.png"
        plot_time_vs_n(result, str(fig))
        command = "addedinertia perf " + " ".join(
            [f"--max-envs {args.max_envs}", f"--vector-envs {args.vector_envs}", f"--vector-steps {args.vector_steps}",
             f"--vector-warmup {args.vector_warmup}",
             f"--vector-seconds {args.vector_seconds:g}"]
            + ([f"--vector-repeats {args.vector_repeats}"] if args.vector_repeats > 1 else [])
            + ([f"--vector-workers {args.vector_workers}"] if args.vector_workers is not None else [])
            + [f"--out {args.out}"])
        text = render_markdown(result, command, os.path.relpath(fig, out.parent))
        atomic_write_text(out, with_kept_part(text, out.read_text() if out.is_file() else None))
        info(f"wrote {out} and {fig}")
    if args.json:
        emit_json(result)
    return 0
