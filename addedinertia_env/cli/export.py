"""``addedinertia export MODEL --onnx FILE``: a trained model as ONNX, with its card, parity and latency."""

from __future__ import annotations

from pathlib import Path

from addedinertia_env.cli.common import emit_json, info, positive_int


def register(sub) -> None:
    """Add the ``export`` subcommand and its options to the subparsers ``sub`` (``addedinertia export --help``)."""
    p = sub.add_parser("export", help="export a trained model to ONNX (docs/LEARNING.md)",
                       description="Write the deterministic actor with observation normalisation and action "
                                   "clipping as ONNX, a policy card (<stem>.json) beside it, and check parity "
                                   "with model.predict(deterministic=True).")
    p.add_argument("model", metavar="MODEL", help="model.zip from `addedinertia train`, or its folder")
    p.add_argument("--onnx", required=True, metavar="FILE", help="ONNX file to write")
    p.add_argument("--parity-samples", type=positive_int, default=1000, help="observations in the parity check")
    p.add_argument("--tolerance", type=float, default=1e-5, help="largest allowed parity difference")
    p.add_argument("--json", action="store_true", help="print the policy card as one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia export`` with the parsed ``args``; writes the ONNX file with its card and prints parity and latency; returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.learning.export import export_onnx  # noqa: PLC0415 - torch is heavy
    from addedinertia_env.cli.common import BadInput  # noqa: PLC0415

    card = export_onnx(args.model, args.onnx, n_parity=args.parity_samples)
    lat = card["latency_us"]
    info(f"wrote {args.onnx} ({card['size_bytes']} bytes) and {Path(args.onnx).with_suffix('.json')}; "
         f"parity max |diff| {card['parity_max_abs_diff']:.2e}; latency p50 {lat['p50']} us, p99 {lat['p99']} us")
    if args.json:
        emit_json(card)
    if not card["parity_max_abs_diff"] <= args.tolerance:
        raise BadInput(f"{args.onnx}: parity max |diff| {card['parity_max_abs_diff']:.3g} > --tolerance "
                       f"{args.tolerance}; the export does not reproduce model.predict")
    return 0
