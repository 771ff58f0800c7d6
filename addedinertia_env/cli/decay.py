"""``addedinertia decay AMPLITUDES.csv|--textbook [--processing FILE] [--plot PNG] [--json]``: damping law of a free decay."""

from __future__ import annotations

from addedinertia_env.cli.common import BadInput, emit_json, info

# The textbook's measured decay, shipped as package data (its README cites the source).
TEXTBOOK_IN_REPO = "addedinertia_env/data/textbook/textbook_roll_decay.csv"


def textbook_path() -> str:
    """Path of the shipped textbook amplitude file (its processing table lies beside it)."""
    from importlib.resources import files  # noqa: PLC0415

    return str(files("addedinertia_env") / "data" / "textbook" / "textbook_roll_decay.csv")


def register(sub) -> None:
    """Add the ``decay`` subcommand and its options to the subparsers ``sub`` (``addedinertia decay --help``)."""
    p = sub.add_parser("decay", help="damping laws from successive free-decay amplitudes (docs/TEXTBOOK_DECAY.md)",
                       description="Fit candidate damping laws to a series of successive half-swing amplitudes "
                                   "(columns 'swing', 'theta_deg') and reproduce the textbook's nu (6.17, 6.18).")
    p.add_argument("amplitudes", metavar="AMPLITUDES.csv", nargs="?", default=None,
                   help="successive amplitudes (columns 'swing', 'theta_deg'); or --textbook")
    p.add_argument("--textbook", action="store_true",
                   help="the measured record shipped with the project (" + TEXTBOOK_IN_REPO + ")")
    p.add_argument("--processing", metavar="FILE", default=None,
                   help="the textbook's processing table (default: STEM_processing.csv beside the input, if any)")
    p.add_argument("--plot", metavar="PNG", default=None, help="write a figure of the fits")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia decay`` with the parsed ``args``; prints the damping laws ranked by BIC (with ``--json``, one object on stdout); returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.decay import DecayInputError, analyse, plot  # noqa: PLC0415

    if args.textbook == (args.amplitudes is not None):
        raise BadInput("decay: give either an AMPLITUDES.csv file or --textbook (the shipped measured record), "
                       "not both and not neither")
    amplitudes = textbook_path() if args.textbook else args.amplitudes
    try:
        result = analyse(amplitudes, args.processing)
    except DecayInputError as e:
        raise BadInput(str(e)) from None
    if args.plot:
        result["plot"] = str(plot(result, args.plot))
        info(f"figure written to {result['plot']}")
    pr = result["textbook"].get("printed")
    lines = [f"law: {result['law']} (lowest BIC of {len(result['models'])} laws fitted to "
             f"{result['n_amplitudes']} amplitudes)"]
    for m in result["models"]:
        ps = ", ".join(f"{k} = {v:.4g} +- {m['stderr'][k]:.2g}" for k, v in m["params"].items())
        lines.append(f"  {m['law']:17s} chi2/dof {m['chi2'] / max(m['dof'], 1):6.2f}  BIC {m['bic']:7.2f}  {ps}")
    if pr:
        lines.append(f"textbook nu (6.17) reproduced to {pr['check_nu_6_17']['max_abs_diff']:.2g}, "
                     f"(6.18) to {pr['check_nu_6_18']['max_abs_diff']:.2g}")
    if args.json:
        for line in lines:
            info(line)
        emit_json(result)
    else:
        print("\n".join(lines))
    return 0
