"""``addedinertia bench-server``: the bench emulator, the simulated rig behind the bench protocol.

Listens on 127.0.0.1 only. Prints one JSON line ``{"url": "socket://127.0.0.1:PORT", ...}``
on stdout once it is listening (``--port 0`` picks a free port), then serves until
interrupted (or until the first host disconnects, with ``--once``).
"""

from __future__ import annotations

import json
import signal
import sys

from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.cli.common import BadInput, info


def register(sub) -> None:
    """Add the ``bench-server`` subcommand and its options to the subparsers ``sub`` (``addedinertia bench-server --help``)."""
    p = sub.add_parser("bench-server", help="run the bench emulator (simulated rig behind the bench protocol)",
                       description="Serve the simulated rig behind the bench wire protocol (docs/PROTOCOL.md) on "
                                   "127.0.0.1, for `addedinertia deploy --bench socket://127.0.0.1:PORT`.")
    p.add_argument("--port", type=int, default=5555, help="TCP port on 127.0.0.1 (0: any free port; default 5555)")
    p.add_argument("--rig", default="wigley-2m", help="rig preset name or YAML path")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated sensor noise")
    p.add_argument("--faults", default="", help="faults to inject, e.g. 'drop=0.5@1.0,latency=5' (docs/BENCH.md)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--realtime", dest="realtime", action="store_true", default=True,
                      help="free-running board paced by the wall clock (default)")
    mode.add_argument("--fast", dest="realtime", action="store_false",
                      help="lock-step: one step and one SAMPLE per COMMAND, as fast as the host")
    p.add_argument("--board-watchdog-ms", type=int, default=50, help="board watchdog while driving, ms")
    p.add_argument("--events", default=None, help="write fault onsets and safe-state times here (JSON lines)")
    p.add_argument("--once", action="store_true", help="exit after the first host disconnects")
    p.add_argument("--idle-timeout", type=float, default=30.0,
                   help="drop a host that sends no valid frame for this long, s (default 30; the board goes safe)")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia bench-server`` with the parsed ``args``; serves until interrupted (or, with ``--once``, until the first host leaves); returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from hw_adapter.board import Board, BoardLimits  # noqa: PLC0415 - keep `addedinertia --help` light
    from hw_adapter.emulator import EmulatorServer  # noqa: PLC0415
    from hw_adapter.faults import FaultSpecError, parse_faults  # noqa: PLC0415

    if not 0 <= args.port <= 65535:
        raise BadInput(f"--port {args.port}: expected 0..65535")
    if not 0.1 <= args.idle_timeout <= 86400:
        raise BadInput(f"--idle-timeout {args.idle_timeout}: expected 0.1 to 86400 s")
    if args.board_watchdog_ms <= 0:
        raise BadInput(f"--board-watchdog-ms {args.board_watchdog_ms}: expected > 0")
    try:
        faults = parse_faults(args.faults)
    except FaultSpecError as e:
        raise BadInput(str(e)) from None
    params = rig_from_mapping(load_preset(args.rig))
    board = Board(params, seed=args.seed, faults=faults, lockstep=not args.realtime,
                  limits=BoardLimits(watchdog_ms=args.board_watchdog_ms), board_id=f"emu-{params.hull.name}"[:16])
    try:
        server = EmulatorServer(board, port=args.port, events_path=args.events, idle_timeout_s=args.idle_timeout)
    except OSError as e:
        raise BadInput(f"--port {args.port}: cannot listen on 127.0.0.1 ({e})") from None
    print(json.dumps({"url": server.url, "port": server.port, "rig": args.rig,
                      "mode": "realtime" if args.realtime else "fast", "faults": faults.to_dict()}), flush=True)
    info(f"bench emulator on {server.url} ({'realtime' if args.realtime else 'fast'}); Ctrl-C to stop")
    signal.signal(signal.SIGTERM, lambda *_: server.request_stop())
    try:
        server.serve_forever(once=args.once)
    except KeyboardInterrupt:
        pass
    finally:
        server.listener.close()
        server.write_events()
    sys.stdout.flush()
    return 0
