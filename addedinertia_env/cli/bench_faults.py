"""``addedinertia bench-faults --bench URL [--clear] [--json]``: read, and on request clear, a board's latched faults.

A fault stays latched on the board (docs/PROTOCOL.md section 5) and ARM is refused until
a RESET, so after a crash or a trip every ``deploy`` stops at its arming checks. This is
the operator's path: it connects, asks the board for its present state (QUERY) and shows
the latched faults; with ``--clear`` it shows them first, then sends a RESET that keeps
the hull where it is (``phi0`` = the present encoder angle, brake on) and confirms with a
second QUERY that nothing is latched any more. Faults are never cleared without
``--clear``. Exit status: 0 no fault left, 3 faults still latched, 4 the bench did not
answer (or is busy with another host), 2 bad input.
"""

from __future__ import annotations

import math
import time

from addedinertia_env.cli.common import emit_json, info

EXIT_FAULTS = 3
EXIT_NO_BENCH = 4


def register(sub) -> None:
    """Add the ``bench-faults`` subcommand and its options to the subparsers ``sub`` (``addedinertia bench-faults --help``)."""
    p = sub.add_parser("bench-faults", help="show (and with --clear, clear) a bench board's latched faults",
                       description="Connect to a bench board, show its present state and latched faults; "
                                   "--clear resets them, keeping the hull where it is (docs/BENCH.md).")
    p.add_argument("--bench", required=True, help="pyserial URL: /dev/ttyUSB0, socket://127.0.0.1:5555, loop://")
    p.add_argument("--clear", action="store_true", help="after showing them, clear the latched faults with a RESET")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def _await(link, kind, timeout_s: float = 1.0, tries: int = 3, request=None):
    """The next message of type ``kind`` (resending ``request`` up to ``tries`` times), or None."""
    from hw_adapter import messages as m  # noqa: PLC0415
    from hw_adapter.link import LinkError  # noqa: PLC0415

    for _ in range(tries):
        if request is not None:
            link.send(request)
        deadline = time.perf_counter() + timeout_s
        while (left := deadline - time.perf_counter()) > 0:
            got = link.recv(left)
            if got is None:
                break
            msg = got[1]
            if msg.type == m.HEARTBEAT and getattr(msg, "reason", None) == m.BUSY_REASON:
                raise LinkError(f"bench {link.url!r} is busy: another host is connected")
            if msg.type == kind:
                return msg
    return None


def _state(sample, caps) -> dict:
    from hw_adapter import messages as m  # noqa: PLC0415

    return {"faults": m.fault_names(sample.faults), "fault_bits": sample.faults,
            "armed": bool(sample.status & m.ST_ARMED), "brake": bool(sample.brake),
            "current_A": float(sample.current), "voltage_V": float(sample.voltage),
            "phi_rad": sample.phi_count * 2 * math.pi / caps.phi_counts}


def run(args) -> int:
    """Run ``addedinertia bench-faults`` with the parsed ``args``; returns 0 (no latched fault left), :data:`EXIT_FAULTS` (3, faults remain) or :data:`EXIT_NO_BENCH` (4, the bench did not answer); bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from hw_adapter import messages as m  # noqa: PLC0415
    from hw_adapter.link import Link, LinkError  # noqa: PLC0415

    from addedinertia_env.cli.deploy import _check_url  # noqa: PLC0415

    _check_url(args.bench)
    out: dict = {"bench": args.bench, "cleared": False}
    try:
        link = Link(args.bench)
    except LinkError as e:
        info(f"addedinertia bench-faults: {e}")
        return EXIT_NO_BENCH
    try:
        caps = _await(link, m.CAPS, 0.5, 3, m.Hello())
        if caps is None:
            info(f"addedinertia bench-faults: bench {args.bench!r} did not answer HELLO")
            return EXIT_NO_BENCH
        before = _await(link, m.SAMPLE, request=m.Empty(m.QUERY, 0))
        if before is None:
            info(f"addedinertia bench-faults: bench {args.bench!r} did not answer QUERY")
            return EXIT_NO_BENCH
        out["board_id"] = caps.board_id
        out["before"] = _state(before, caps)
        names = ", ".join(out["before"]["faults"]) or "none"
        info(f"{caps.board_id or args.bench}: latched faults: {names}; armed {out['before']['armed']}, "
             f"brake {'on' if before.brake else 'OFF'}, current {before.current:+.3f} A")
        after = before
        if args.clear and before.faults:
            info(f"clearing {names} with a RESET at the present angle {out['before']['phi_rad']:+.5f} rad, brake on")
            psi = before.psi_count * 2 * math.pi / caps.psi_counts
            link.send(m.Reset(phi0=out["before"]["phi_rad"], psi0=psi, brake=True))
            after = None
            deadline = time.perf_counter() + 5.0
            while after is None and time.perf_counter() < deadline:  # streamed samples may come first
                got = _await(link, m.SAMPLE, 1.0, 1)
                if got is not None and got.status & m.ST_RESET_DONE:
                    after = got
            if after is None:
                info(f"addedinertia bench-faults: bench {args.bench!r} did not answer the RESET")
                return EXIT_NO_BENCH
            out["cleared"] = after.faults == 0
        out["after"] = _state(after, caps)
        left = ", ".join(out["after"]["faults"])
        if args.clear:
            info(f"latched faults now: {left or 'none'}")
        elif after.faults:
            info(f"run `addedinertia bench-faults --bench {args.bench} --clear` to clear them once the bench is checked")
    except LinkError as e:
        info(f"addedinertia bench-faults: {e}")
        return EXIT_NO_BENCH
    finally:
        link.close()
    if args.json:
        emit_json(out)
    return EXIT_FAULTS if out["after"]["faults"] else 0
