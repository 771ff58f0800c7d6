"""``addedinertia simulate``: run simulated experiments and write run records."""

from __future__ import annotations

from agents.registry import DEFAULT_CONTROLLER

from pathlib import Path

from addedinertia_env.sim.effects import effect_names
from addedinertia_env.sim.presets import SENSOR_QUALITY, load_preset, rig_from_mapping, sensors_for_quality
from addedinertia_env.experiment.protocol import plan_from_preset
from addedinertia_env.experiment.runner import needs_stated_link
from addedinertia_env.experiment.two_rate import MAX_STATED_ROUND_TRIP_S
from addedinertia_env.loop.control_loop import ControlLoop
from addedinertia_env.apps.simulate import OTHER_KINDS, OutputInUse, effects_from_name, simulate_to_dir
from addedinertia_env.cli.common import BadInput, emit_json, info, non_negative_float, non_negative_int, positive_int


MAX_CYCLES = 1000  # records per call


def register(sub) -> None:
    """Add the ``simulate`` subcommand and its options to the subparsers ``sub`` (``addedinertia simulate --help``)."""
    p = sub.add_parser("simulate", help="simulate experiments and write run records")
    p.add_argument("--rig", default="wigley-2m", help="rig preset name or YAML path")
    p.add_argument("--controller", default=DEFAULT_CONTROLLER, help="controller name (see docs/CONTROLLERS.md)")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--hold", type=non_negative_float, default=None, help="brake hold at the reversal, s")
    p.add_argument("--alpha", type=float, default=None, help="twist before release, rad")
    p.add_argument("--cycles", type=positive_int, default=1, help="repeated experiments (one record each)")
    p.add_argument("--kind", default="reverse-symmetric", choices=["reverse-symmetric", *OTHER_KINDS])
    p.add_argument("--sensors", choices=SENSOR_QUALITY, default=None, help="sensor set (default: the preset's)")
    p.add_argument("--effect", default="none", choices=["none", *effect_names()],
                   help="hide one effect in the simulated truth (seeded size)")
    p.add_argument("--out", default="out/sim", help="folder for the records")
    p.add_argument("--force", action="store_true",
                   help="overwrite records in --out (by default records of this same simulation are kept and "
                        "others are refused)")
    p.add_argument("--hydrodynamics", choices=["constant", "cummins"], default=None,
                   help="the water's model (default: the preset's): constant added inertia, or cummins radiation "
                        "memory from the hull's BEM cache (docs/RADIATION_MEMORY.md)")
    p.add_argument("--frequencies", type=float, nargs="+", default=None, metavar="HZ",
                   help="--kind forced-oscillation: drive frequencies, Hz (at least two; default: ratios 0.75, 0.85, "
                        "1.2, 1.35 of the natural frequency found by the first half swing)")
    p.add_argument("--periods", type=positive_int, default=None,
                   help="--kind forced-oscillation: measured drive periods per frequency (default 2)")
    p.add_argument("--settle", type=non_negative_float, default=None,
                   help="--kind forced-oscillation: s driven at each frequency before its measured periods "
                        "(default 0; docs/RADIATION_MEMORY.md says how long water that remembers needs)")
    p.add_argument("--link-round-trip-ms", type=non_negative_float, default=None, metavar="MS",
                   help="--kind reverse-symmetric: a link with this round trip, ms: simulated as the readings' delay "
                        "(whole samples) and stated to the controllers (ControllerContext.link_round_trip_s; needed by "
                        "smith-pd); recorded as experiment.link_round_trip_s and truth.control_loop (default: an ideal "
                        "loop, nothing stated)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia simulate`` with the parsed ``args``; writes one run record (CSV + JSON) per run under ``--out``; returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    if args.cycles > MAX_CYCLES:
        raise BadInput(f"--cycles {args.cycles}: expected at most {MAX_CYCLES} records per call (docs/RELIABILITY.md)")
    data = load_preset(args.rig)
    sensors = sensors_for_quality(args.sensors) if args.sensors else None
    rig = rig_from_mapping(data, effects=effects_from_name(args.effect, args.seed), sensors=sensors,
                           hydrodynamics=args.hydrodynamics)
    plan = plan_from_preset(data, hold_s=args.hold, alpha=args.alpha)
    forced = {"frequencies_hz": tuple(args.frequencies) if args.frequencies else None, "periods": args.periods,
              "settle_s": args.settle}
    if args.kind != "forced-oscillation" and any(v is not None for v in forced.values()):
        raise BadInput("--frequencies, --periods and --settle apply to --kind forced-oscillation only; "
                       f"got --kind {args.kind}")
    if args.kind == "forced-oscillation":
        from addedinertia_env.experiment.forced import ForcedPlan  # noqa: PLC0415

        try:
            plan = ForcedPlan(alpha=plan.alpha, **{k: v for k, v in forced.items() if v is not None})
        except ValueError as e:
            raise BadInput(f"--frequencies/--periods/--settle: {e}") from None
    loop = None
    if args.link_round_trip_ms is not None:
        if args.kind != "reverse-symmetric":
            raise BadInput(f"--link-round-trip-ms applies to --kind reverse-symmetric only (a controlled experiment); "
                           f"got --kind {args.kind}")
        if args.link_round_trip_ms > 1e3 * MAX_STATED_ROUND_TRIP_S:
            raise BadInput(f"--link-round-trip-ms {args.link_round_trip_ms:g}: expected at most "
                           f"{1e3 * MAX_STATED_ROUND_TRIP_S:g} ms (the longest link a controller may be told of)")
        rtt = 1e-3 * args.link_round_trip_ms
        loop = ControlLoop(obs_delay_s=rtt, stated_round_trip_s=rtt)
    if args.kind == "reverse-symmetric":
        from agents.registry import CLASSICAL, controller_class, make_controller  # noqa: PLC0415

        if ":" not in args.controller and args.controller not in CLASSICAL:
            raise BadInput(f"--controller {args.controller!r}: expected one of {', '.join(sorted(CLASSICAL))}, "
                           "onnx:PATH or module:factory")
        needs = args.controller in CLASSICAL and getattr(controller_class(args.controller), "needs_stated_link", False)
        if ":" in args.controller:
            needs = needs_stated_link(make_controller(args.controller))  # loaded and checked before anything runs
        if needs and loop is None:
            raise BadInput(f"--controller {args.controller!r} needs the link's round trip stated to it "
                           "(ControllerContext.link_round_trip_s); without --link-round-trip-ms simulate runs an "
                           "ideal loop and states none: give --link-round-trip-ms MS (simulated and stated), or run "
                           "it on a suite that states one, e.g. `addedinertia bench run --suite drive-v3`")
    from addedinertia_env.foundation.atomic import remove_stale_temps  # noqa: PLC0415

    for stale in remove_stale_temps(args.out):
        info(f"removed {stale}, a temporary file of a killed earlier run")
    signature = {"rig": args.rig, "controller": args.controller, "seed": args.seed, "hold": args.hold,
                 "alpha": args.alpha, "kind": args.kind, "sensors": args.sensors, "effect": args.effect}
    for key, value in forced.items():  # (absent when not given: earlier records' signatures stay valid)
        if value is not None:
            signature[key] = list(value) if isinstance(value, tuple) else value
    if args.hydrodynamics is not None:  # (absent otherwise: earlier records' signatures stay valid)
        signature["hydrodynamics"] = args.hydrodynamics
    if args.link_round_trip_ms is not None:  # (likewise)
        signature["link_round_trip_ms"] = args.link_round_trip_ms
    kept: list[Path] = []
    try:
        paths = simulate_to_dir(rig, Path(args.out), controller=args.controller, plan=plan, seed=args.seed,
                                cycles=args.cycles, kind=args.kind, signature=signature, force=args.force, kept=kept,
                                loop=loop)
    except OutputInUse as e:
        raise BadInput(str(e)) from None
    if kept:
        info(f"resumed: kept {len(kept)} record(s) of this simulation already in {args.out} (--force redoes them)")
    for p in paths:
        if p not in kept:
            info(f"wrote {p} (+ .json)")
    if args.json:
        emit_json({"records": [str(p) for p in paths], "rig": args.rig, "kind": args.kind,
                   "controller": args.controller, "seed": args.seed})
    return 0
