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

from .common import bad_input_types, fail, report_bug


class OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr and exit status 2.

    argparse prints the whole usage block before the error; the command line's contract
    (docs/ARCHITECTURE.md) is one line. Subparsers inherit the class.
    """

    def error(self, message: str):
        print(f"{self.prog}: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineErrorParser(
        prog="addedinertia",
        description="Identify the added moment of inertia lambda66 of a hull on a reverse-symmetric yaw rig.")
    from .. import __version__  # noqa: PLC0415

    parser.add_argument("--version", action="version", version=f"addedinertia {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name == "common":
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # usage error (2, one line already printed), --help or --version (0)
        return e.code if isinstance(e.code, int) else 2
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
