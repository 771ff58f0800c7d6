"""``addedinertia deploy``: one experiment on a bench (real or emulated) through ``hw_adapter``.

Exit status: 0 complete (or a clean dry run), 1 complete but lambda66 not identified,
2 bad input (also: a policy whose rate or board mode the bench does not match, refused
before arming), 3 aborted in the safe state (fault, trip, failed arming check; the partial
record is kept, ``experiment.status`` says why), 4 the bench did not answer.
"""

from __future__ import annotations

import math
from pathlib import Path

from addedinertia_env.cli.common import BadInput, emit_json, info, non_negative_float
from addedinertia_env.experiment.two_rate import MAX_STATED_ROUND_TRIP_S


def register(sub) -> None:
    """Add the ``deploy`` subcommand and its options to the subparsers ``sub`` (``addedinertia deploy --help``)."""
    p = sub.add_parser("deploy", help="run one experiment on a bench (real or emulated)",
                       description="One reverse-symmetric experiment on a bench through the safety envelope, "
                                   "record written as it goes, lambda66 identified at the end (docs/BENCH.md).")
    p.add_argument("--bench", required=True, help="pyserial URL: /dev/ttyUSB0, socket://127.0.0.1:5555, loop://")
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--controller", help="classical controller name (pd, feedforward-pd, pid, lqr, ilc, mpc) "
                                          "or module:factory")
    who.add_argument("--policy", help="exported ONNX policy file")
    p.add_argument("--lab", default="wigley-2m",
                   help="lab file (.yaml, see hw_adapter/labs/example.yaml) or, for the emulator, a rig preset name")
    p.add_argument("--out", default="out/deploy", help="folder for the run record")
    p.add_argument("--run-id", default="deploy", help="stem of the record's file names")
    p.add_argument("--hold", type=non_negative_float, default=None, help="brake hold at the reversal, s")
    p.add_argument("--alpha", type=float, default=None, help="twist before release, rad")
    p.add_argument("--warmup", type=non_negative_float, default=0.2, help="passive braked warm-up, s")
    p.add_argument("--watchdog-ms", type=float, default=None,
                   help="link silence that stops the run, ms (default 20; 1000 against a lock-step emulator)")
    p.add_argument("--reset-timeout", type=non_negative_float, default=120.0,
                   help="how long to wait for the hull to be placed at the twist angle, s")
    p.add_argument("--host-rate-hz", type=float, default=None,
                   help="two-rate mode (protocol version 2): the board runs the inner loop every sample, the host "
                        "acts and sends time-stamped segments at this rate, Hz (an exported policy: its card's rate)")
    p.add_argument("--board-mode", choices=("zoh", "pd"), default=None,
                   help="two-rate: what the board does between host actions (default: the policy's card, else zoh)")
    p.add_argument("--link-round-trip-ms", default=None, metavar="MS|ping",
                   help="the link's round trip stated to the controllers (ControllerContext.link_round_trip_s), ms, "
                        "as the lab measured it (a loopback ping); 'ping': the median of this deploy's arming echoes. "
                        "Needed by controllers that compensate the link (smith-pd and policies on it); "
                        "recorded as experiment.link_round_trip_s (docs/BENCH.md)")
    p.add_argument("--dry-run", action="store_true", help="connect, arming checks, warm-up at zero current; no motion")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def _check_url(url: str) -> None:
    """A --bench URL pyserial cannot even parse is bad input (exit 2); one that does not answer is exit 4."""
    import serial  # noqa: PLC0415

    try:
        serial.serial_for_url(url, do_not_open=True)
    except (ValueError, serial.SerialException) as e:
        raise BadInput(f"--bench {url!r}: {e}; expected a pyserial URL such as /dev/ttyUSB0, "
                       "socket://127.0.0.1:5555 or loop://") from None




def link_round_trip_s(text: str | None) -> float | str | None:
    """``--link-round-trip-ms`` as :attr:`hw_adapter.deploy.DeployOptions.link_round_trip_s`: None, ``"ping"`` or s;
    BadInput naming the option, the value and what was expected otherwise."""
    if text is None or text.strip() == "ping":
        return None if text is None else "ping"
    try:
        ms = float(text)
    except ValueError:
        ms = math.nan
    if not (math.isfinite(ms) and 0.0 <= ms <= 1e3 * MAX_STATED_ROUND_TRIP_S):
        raise BadInput(f"--link-round-trip-ms {text!r}: expected 'ping' or a finite number of ms in "
                       f"[0, {1e3 * MAX_STATED_ROUND_TRIP_S:g}] (the link's round trip as the lab measured it)")
    return 1e-3 * ms


def run(args) -> int:
    """Run ``addedinertia deploy`` with the parsed ``args``; returns the exit status of :func:`hw_adapter.deploy.deploy` (0 ok, 1 not identified, 2 refused before arming, 3 aborted in the safe state, 4 no bench); bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from agents.registry import UnknownController, make_controller  # noqa: PLC0415
    from hw_adapter.deploy import DeployOptions, deploy  # noqa: PLC0415
    from hw_adapter.lab import load_lab  # noqa: PLC0415

    if args.policy is not None:
        policy = Path(args.policy)
        if not policy.is_file():
            raise BadInput(f"--policy {args.policy}: no such file (expected an exported .onnx policy)")
        name = f"onnx:{policy}"
    else:
        name = args.controller
    if args.watchdog_ms is not None and not 0 < args.watchdog_ms <= 1000:
        raise BadInput(f"--watchdog-ms {args.watchdog_ms}: expected 0 < ms <= 1000")
    _check_url(args.bench)
    if args.host_rate_hz is not None and not (math.isfinite(args.host_rate_hz) and 0 < args.host_rate_hz <= 20_000):
        raise BadInput(f"--host-rate-hz {args.host_rate_hz}: expected 0 < Hz <= 20000 (at most the board's sample rate)")
    if args.board_mode is not None and args.host_rate_hz is None:
        raise BadInput(f"--board-mode {args.board_mode}: only with --host-rate-hz (the two-rate mode)")
    rtt = link_round_trip_s(args.link_round_trip_ms)
    lab = load_lab(args.lab)
    try:
        lab.plan(hold_s=args.hold, alpha=args.alpha)
    except ValueError as e:
        raise BadInput(str(e)) from None
    try:
        controller = make_controller(name)
    except UnknownController as e:
        raise BadInput(f"--controller/--policy: {e}") from None
    from addedinertia_env.experiment.runner import needs_stated_link  # noqa: PLC0415

    if rtt is None and needs_stated_link(controller):
        raise BadInput(f"--controller/--policy {name}: needs the link's round trip stated to it "
                       "(ControllerContext.link_round_trip_s): give --link-round-trip-ms MS (a loopback ping's "
                       "median) or --link-round-trip-ms ping (this deploy measures it)")
    opts = DeployOptions(bench=args.bench, controller=name, lab=lab, out=Path(args.out), run_id=args.run_id,
                         dry_run=args.dry_run, warmup_s=args.warmup,
                         watchdog_s=None if args.watchdog_ms is None else args.watchdog_ms * 1e-3,
                         hold_s=args.hold, alpha=args.alpha, reset_timeout_s=args.reset_timeout,
                         host_rate_hz=args.host_rate_hz, board_mode=args.board_mode, link_round_trip_s=rtt)
    summary, status = deploy(opts, controller)
    if args.json:
        emit_json(summary)
    else:
        print(f"status {deploy_outcome(summary, status)} (exit {status}); safe stop {'confirmed' if summary['safe_stop'] else 'NOT confirmed'}")
        if summary.get("lambda66") is not None:
            lo, hi = summary["ci95"]
            print(f"lambda66 {summary['lambda66']:.4f} kg m^2 (95 % interval {lo:.4f} .. {hi:.4f})")
        if summary.get("loop_jitter_p99_ms") is not None:
            print(f"loop jitter p50 {summary['loop_jitter_p50_ms']:.3f} ms, p99 {summary['loop_jitter_p99_ms']:.3f} ms, "
                  f"{summary['overruns']} overruns")
    if summary.get("record"):
        info(f"record {summary['record']} (+ .json)")
    if summary.get("refused"):
        info(f"addedinertia deploy: refused before arming: {summary['refused']}")
        return status
    if status != 0:
        info(f"addedinertia deploy: {deploy_outcome(summary, status)}")
    return status


def deploy_outcome(summary: dict, status: int) -> str:
    """One line saying how a deploy ended: ``complete, not identified: REASON`` when the
    experiment ran to its end but gave no lambda66 (exit status 1), else the run's status."""
    if status == 1 and summary.get("status") == "complete":
        reason = summary.get("identify_error") or "no lambda66 in the result"
        return f"complete, not identified: {reason}"
    return str(summary.get("status"))
