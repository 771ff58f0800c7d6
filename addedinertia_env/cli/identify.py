"""``addedinertia identify RUN.csv ... [--method M] [--json]``: lambda66 with a 95 % interval."""

from __future__ import annotations

from addedinertia_env.identify import METHODS, identify
from addedinertia_env.records.record import read_record, sampling
from addedinertia_env.cli.common import emit_json, info


def register(sub) -> None:
    """Add the ``identify`` subcommand and its options to the subparsers ``sub`` (``addedinertia identify --help``)."""
    p = sub.add_parser("identify", help="estimate lambda66 from run records",
                       description="Estimate lambda66 (kg m^2) with a 95 %% interval from one or more run records.")
    p.add_argument("records", nargs="+", metavar="RUN.csv")
    p.add_argument("--method", choices=sorted(METHODS), default="energy")
    p.add_argument("--work", choices=("reaction", "current", "electric"), default=None,
                   help="energy method: how motor work is measured (default: reaction)")
    p.add_argument("--effect", default=None, metavar="CAUSE",
                   help="whole-record: extend the model by this effect (a cause named by discover, "
                        "or two joined by '+'); default the nominal model")
    p.add_argument("--memory", choices=("auto", "off"), default="auto",
                   help="energy method: identify the water's radiation memory from the records (free decays "
                        "given beside reverse runs help) and correct for it, so that lambda66 is A66(0) "
                        "(default auto; docs/RADIATION_MEMORY.md); off: the energy balance alone")
    p.add_argument("--prior", choices=("none", "bem"), default="none",
                   help="with --memory auto: 'none' (default) identifies the memory model from the records alone; "
                        "'bem' lends it the hull's BEM cache's kernel shape where the records accept it (stated "
                        "in the JSON as prior)")
    p.add_argument("--bem-cache", default=None, metavar="PATH.bem.json",
                   help="--prior bem: the BEM cache (default configs/rigs/PRESET.bem.json of the preset the "
                        "records name)")
    p.add_argument("--verbose", action="store_true", help="include every interval in the JSON")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia identify`` with the parsed ``args``; prints lambda66 (kg m^2) with its 95 % interval (``--json``: one object); returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    records = [read_record(path) for path in args.records]
    for rec in records:
        for t_before, gap in rec.gaps:
            info(f"{rec.name}: warning: gap of {gap:.4f} s in 't' after t = {t_before:.4f} s")
    options = {}
    if args.work is not None:
        if args.method != "energy":
            info("--work applies to the energy method only; ignored")
        else:
            options["work"] = args.work
    options["memory"] = args.memory
    if args.method in ("energy", "whole-record"):
        options["prior"] = args.prior
        if args.bem_cache is not None:
            options["bem_cache"] = args.bem_cache
    elif args.prior != "none" or args.bem_cache is not None:
        info("--prior and --bem-cache apply to the energy and whole-record methods only; ignored")
    if args.effect is not None:
        if args.method != "whole-record":
            info("--effect applies to the whole-record method only; ignored")
        else:
            options["effect"] = args.effect
    result = identify(records, args.method, **options)
    for warning in result.details.get("warnings", []):
        info(f"warning: {warning}")
    if args.json:
        out = result.to_json(verbose=args.verbose)
        # how each record was sampled (jitter, dropped samples, gaps): never assumed uniform
        out.setdefault("sampling", [{"run": rec.name, **sampling(rec).to_json()} for rec in records])
        emit_json(out)
    else:
        lo, hi = result.ci95
        print(f"lambda66 = {result.lambda66:.4f} kg m^2  (95 % interval {lo:.4f} .. {hi:.4f}; "
              f"method {result.method}, {result.n_intervals} intervals)")
    return 0
