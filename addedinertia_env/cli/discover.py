"""``addedinertia discover RUN.csv ... [--report DIR] [--json]``: what the nominal model gets wrong, and why."""

from __future__ import annotations

from addedinertia_env.records.record import read_record
from addedinertia_env.cli.common import BadInput, emit_json, info


def register(sub) -> None:
    """Add the ``discover`` subcommand and its options to the subparsers ``sub`` (``addedinertia discover --help``)."""
    p = sub.add_parser("discover", help="diagnose which effect the nominal model lacks (docs/DISCOVERY.md)",
                       description="Fit the nominal gray-box model to all strokes of the given free-decay and "
                                   "reverse-symmetric runs, grow it by the effects of the vocabulary that improve the "
                                   "prediction of held-out runs, name every cause and what each is worth; unusable "
                                   "records are skipped and listed.")
    p.add_argument("records", nargs="+", metavar="RUN.csv")
    p.add_argument("--report", metavar="DIR", default=None, help="write report.md, figures and discovery.json here")
    p.add_argument("--no-heldout", action="store_true", help="skip the held-out check (faster, weaker)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia discover`` with the parsed ``args``; prints what the nominal model misses and its likely causes (and writes ``--report``); returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.discover import DiscoveryInputError, discover  # noqa: PLC0415

    records = [read_record(path) for path in args.records]
    try:
        diag = discover(records, heldout=not args.no_heldout)
    except DiscoveryInputError as e:
        raise BadInput(str(e)) from None
    out = diag.to_json()
    if args.report:
        from addedinertia_env.discover.report import write_report  # noqa: PLC0415

        path = write_report(diag, args.report)
        out["report"] = str(path)
        info(f"report written to {path}")
    g = out["gain"]
    for s in out["skipped"]:
        info(f"{s['run']}: skipped: {s['reason']}")
    info(f"cause: {diag.cause}" + (f" (causes: {' + '.join(diag.causes)})" if len(diag.causes) > 1 else ""))
    info(f"hull residual RMS {g['residual_rms_nominal'] * 1e6:.2f} -> {g['residual_rms_extended'] * 1e6:.2f} urad; "
         f"lambda66 {g['lambda66_nominal']:.4f} -> {g['lambda66_extended']:.4f} kg m^2")
    if args.json:
        emit_json(out)
    else:
        print(f"cause: {diag.cause}" + (f" (causes: {' + '.join(diag.causes)})" if len(diag.causes) > 1 else ""))
        for rnd in out["rounds"]:
            for c in rnd:
                ho = "" if c["heldout_gain"] is None else f"held-out gain {c['heldout_gain']:6.1%}  "
                print(f"  round {c['round']}: {c['against']} + {c['cause']:18s} {ho}{c['reason']}")
        for row in out["effects_gain"]:
            print(f"  {row['model']:40s} lambda66 {row['lambda66']:.4f} kg m^2, hull residual "
                  f"{row['residual_rms'] * 1e6:.2f} urad")
    return 0
