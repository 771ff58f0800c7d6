"""The ``addedinertia`` command line.

Each subcommand lives in its own module of this package and exposes
``register(subparsers)``, which adds its parser and sets ``func(args) -> int``. Modules
are found by name, so adding a command means adding a file. Errors in the input (bad
records, bad configs, bad options, a policy or link that cannot be used) print one line
on stderr and exit with status 2; any other exception is a bug: one line on stderr
points to a log file with the traceback, exit status 70 (docs/RELIABILITY.md).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from addedinertia_env.cli.common import bad_input_types, fail, report_bug


class OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr and exit status 2.

    argparse prints the whole usage block before the error; the command line's contract
    (docs/ARCHITECTURE.md) is one line. Subparsers inherit the class.
    """

    def error(self, message: str):
        """Print the usage error as one line naming the fix (``--help``) on stderr and exit 2."""
        print(f"{self.prog}: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    """The ``addedinertia`` argument parser, with every subcommand module's ``register`` applied."""
    parser = OneLineErrorParser(
        prog="addedinertia",
        description="Identify the added moment of inertia lambda66 of a hull on a reverse-symmetric yaw rig.")
    from addedinertia_env import __version__  # noqa: PLC0415

    parser.add_argument("--version", action="version", version=f"addedinertia {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name == "common":
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def _sigterm_as_interrupt():
    """SIGTERM ends a command like Ctrl-C: files are closed, workers stopped, exit 130, no traceback.
    Returns the handler it replaced (None off the main thread)."""
    import signal  # noqa: PLC0415
    import threading  # noqa: PLC0415

    if threading.current_thread() is not threading.main_thread():
        return None

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, interrupt)


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default: ``sys.argv[1:]``); returns the exit status.

    0 done; 2 bad input (one line on stderr naming file, field, value and what was
    expected) or a usage error; 130 interrupted (Ctrl-C or SIGTERM); 70 a bug (it
    logs the traceback to a file named on stderr); a subcommand's own codes otherwise (``deploy``,
    ``bench-faults``).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # usage error (2, one line already printed), --help or --version (0)
        return e.code if isinstance(e.code, int) else 2
    previous = _sigterm_as_interrupt()
    args.argv = list(sys.argv[1:] if argv is None else argv)  # the command actually run (leaderboard headers)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("addedinertia: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # stdout closed by the reader (| head): nothing more to say
        return 0
    except Exception as e:  # noqa: BLE001 - the one place every failure ends up
        if isinstance(e, bad_input_types()):
            return fail(e)
        return report_bug(e, argv)
    finally:
        if previous is not None:
            import signal  # noqa: PLC0415

            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
