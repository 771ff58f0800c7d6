"""``addedinertia dataset export [RUNS...] --minari NAME [--simulate N --controller NAME]``.

Episodes as a Minari dataset for offline RL (docs/DATASETS.md): run records (bench,
emulator or simulated ``addedinertia-run/1`` records, one episode each), or ``N``
episodes simulated now in ``AddedInertia/ReverseStroke-v0`` under a controller, with the
scoring (which score, the suite and its version, reference scores) in the dataset's
metadata. Needs the optional ``[data]`` extra (Minari, h5py).
"""

from __future__ import annotations

from addedinertia_env.cli.common import BadInput, emit_json, info, non_negative_int, positive_int


def register(sub) -> None:
    """Add the ``dataset`` subcommand and its options to the subparsers ``sub`` (``addedinertia dataset --help``)."""
    p = sub.add_parser("dataset", help="episodes as an offline-RL dataset (Minari; docs/DATASETS.md)",
                       description="Package episodes for offline RL.")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    e = actions.add_parser("export", help="write run records or simulated episodes as a Minari dataset",
                           description="Write a Minari dataset (loadable with minari.load_dataset(NAME)) from run "
                                       "records (RUNS: their .csv or .json files) or from --simulate N episodes of "
                                       "the environment; never both, never over an existing dataset.")
    e.add_argument("runs", metavar="RUNS", nargs="*", help="run records (.csv or .json of addedinertia-run/1), one episode each")
    e.add_argument("--minari", required=True, metavar="NAME",
                   help="dataset id, [namespace/]name-vN (stored under MINARI_DATASETS_PATH or ~/.minari/datasets)")
    e.add_argument("--simulate", type=positive_int, default=None, metavar="N",
                   help="simulate N episodes in AddedInertia/ReverseStroke-v0 instead of reading RUNS")
    e.add_argument("--controller", default="feedforward-pd", help="controller of the simulated episodes (default feedforward-pd)")
    e.add_argument("--suite", default=None, help="draw the simulated scenarios from a benchmark suite's train split (e.g. standard-v0)")
    e.add_argument("--seed", type=non_negative_int, default=0, help="first env seed of the simulated episodes (default 0)")
    e.add_argument("--action-repeat", type=positive_int, default=10, help="rig samples per action (default 10: 100 Hz)")
    e.add_argument("--no-references", action="store_true",
                   help="skip the reference controllers (zero, feedforward-pd) on the same seeds: no ref_min/max_score")
    e.add_argument("--json", action="store_true", help="print a summary as one JSON object")
    e.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia dataset export``; writes the dataset and prints where; returns 0; bad input raises."""
    from addedinertia_env.learning import minari_export as mx  # noqa: PLC0415

    try:
        mx._minari()
        mx.check_dataset_id(args.minari)
        if mx.dataset_path(args.minari).exists():  # before any work: refuse early
            raise mx.DatasetError(f"--minari {args.minari}: a dataset already exists at {mx.dataset_path(args.minari)}; "
                                  "expected a new name or version (Minari datasets are never overwritten)")
        if args.runs and args.simulate:
            raise BadInput("RUNS and --simulate: expected one source (run records or simulated episodes), not both")
        if not args.runs and not args.simulate:
            raise BadInput("no episodes: expected RUNS (run record files) or --simulate N")
        env = None
        if args.simulate:
            if args.suite is not None:
                from addedinertia_env.bench.suites import available_suites  # noqa: PLC0415

                if args.suite not in available_suites():
                    raise BadInput(f"--suite {args.suite!r}: expected one of {', '.join(available_suites())}")
            env, episodes, scoring = mx.simulate_episodes(args.simulate, args.controller, seed=args.seed,
                                                          suite=args.suite, action_repeat=args.action_repeat,
                                                          references=not args.no_references, progress=info)
        else:
            episodes, scoring = mx.record_episodes(args.runs)
        path = mx.write_dataset(args.minari, episodes, scoring, env=env)
    except mx.DatasetError as e:
        raise BadInput(str(e)) from None
    info(f"dataset {args.minari} written to {path} ({len(episodes)} episodes, "
         f"{sum(int(e.meta['steps']) for e in episodes)} steps)")
    if args.json:
        emit_json({"dataset_id": args.minari, "path": str(path), "episodes": len(episodes),
                   "returns": [e.meta["return"] for e in episodes], "scoring": scoring})
    return 0
