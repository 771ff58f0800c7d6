"""``addedinertia discover RUN.csv ... [--report DIR] [--json]``: what the nominal model gets wrong, and why."""

from __future__ import annotations

from ..record import read_record
from .common import BadInput, emit_json, info


def register(sub) -> None:
    """Add the ``discover`` subcommand and its options to the subparsers ``sub`` (``addedinertia discover --help``)."""
    p = sub.add_parser("discover", help="diagnose which effect the nominal model lacks (docs/DISCOVERY.md)",
                       description="Fit the nominal gray-box model to all strokes of the given free-decay and "
                                   "reverse-symmetric runs, try each candidate effect of the vocabulary (and pairs), "
                                   "name the cause and the gain; unusable records are skipped and listed.")
    p.add_argument("records", nargs="+", metavar="RUN.csv")
    p.add_argument("--report", metavar="DIR", default=None, help="write report.md, figures and discovery.json here")
    p.add_argument("--no-heldout", action="store_true", help="skip the held-out check (faster, weaker)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia discover`` with the parsed ``args``; prints what the nominal model misses and its likely causes (and writes ``--report``); returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from ..discover import DiscoveryInputError, discover  # noqa: PLC0415

    records = [read_record(path) for path in args.records]
    try:
        diag = discover(records, heldout=not args.no_heldout)
    except DiscoveryInputError as e:
        raise BadInput(str(e)) from None
    out = diag.to_json()
    if args.report:
        from ..discover.report import write_report  # noqa: PLC0415

        path = write_report(diag, args.report)
        out["report"] = str(path)
        info(f"report written to {path}")
    g = out["gain"]
    for s in out["skipped"]:
        info(f"{s['run']}: skipped: {s['reason']}")
    info(f"cause: {diag.cause}" + (f" (both: {' + '.join(diag.causes)})" if len(diag.causes) > 1 else ""))
    info(f"hull residual RMS {g['residual_rms_nominal'] * 1e6:.2f} -> {g['residual_rms_extended'] * 1e6:.2f} urad; "
         f"lambda66 {g['lambda66_nominal']:.4f} -> {g['lambda66_extended']:.4f} kg m^2")
    if args.json:
        emit_json(out)
    else:
        print(f"cause: {diag.cause}" + (f" (both: {' + '.join(diag.causes)})" if len(diag.causes) > 1 else ""))
        for c in out["candidates"]:
            print(f"  {c['cause']:18s} delta BIC {c['delta_bic']:9.1f}  {c['reason']}")
    return 0
