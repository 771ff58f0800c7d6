"""Helpers shared by the subcommands: JSON output, errors, argument types."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any


from addedinertia_env.experiment.protocol import ExperimentError
from addedinertia_env.identify.common import IdentificationError
from addedinertia_env.foundation.jsonable import plain
from addedinertia_env.records.record import RecordError
from addedinertia_env.sim.presets import ConfigError


class BadInput(ValueError):
    """Any user-facing input problem not covered by a more specific error."""


# OSError covers missing files and output folders that cannot be written (permissions, a file in the way).
BAD_INPUT = (RecordError, ConfigError, IdentificationError, BadInput, ExperimentError, OSError)
EXIT_BUG = 70  # an unexpected exception: a bug in this program (sysexits EX_SOFTWARE)


def bad_input_types() -> tuple[type[BaseException], ...]:
    """Every exception type that means "the input cannot be used" (exit 2), the optional ones included.

    Controllers, ONNX policies, discovery, the decay analysis and the bench link have
    their own error types; they are imported lazily (some pull in heavy packages), so
    only those already loaded are listed: an exception of a type never imported cannot
    have been raised.
    """
    types = list(BAD_INPUT)
    for module, name in (("agents.registry", "UnknownController"), ("agents.onnx_policy", "OnnxPolicyError"),
                         ("addedinertia_env.discover.prepare", "DiscoveryInputError"),
                         ("addedinertia_env.decay", "DecayInputError"),
                         ("addedinertia_env.bench.leaderboard", "RowsError"),
                         ("addedinertia_env.bench.resume", "RowsFileError"),
                         ("hw_adapter.link", "LinkError")):
        mod = sys.modules.get(module)
        if mod is not None and isinstance(getattr(mod, name, None), type):
            types.append(getattr(mod, name))
    return tuple(types)


def fail(error: BaseException) -> int:
    """One line on stderr for a bad input; exit status 2."""
    message = " ".join(str(error).split()) or type(error).__name__
    if isinstance(error, OSError) and error.filename is not None and str(error.filename) not in message:
        message = f"{error.filename}: {message}"
    print(f"addedinertia: error: {message}", file=sys.stderr)
    return 2


def report_bug(error: BaseException, argv: list[str] | None) -> int:
    """An unexpected exception: the traceback goes to a log file, one line on stderr points to it."""
    import datetime  # noqa: PLC0415
    import os  # noqa: PLC0415
    import tempfile  # noqa: PLC0415
    import traceback  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    from addedinertia_env import __version__  # noqa: PLC0415

    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    text = (f"addedinertia {__version__}, argv {argv if argv is not None else sys.argv[1:]}\n"
            + "".join(traceback.format_exception(type(error), error, error.__traceback__)))
    log = None
    for folder in (os.environ.get("ADDEDINERTIA_LOG_DIR"), Path.home() / ".cache" / "addedinertia", tempfile.gettempdir()):
        if not folder:
            continue
        try:
            Path(folder).mkdir(parents=True, exist_ok=True)
            log = Path(folder) / f"crash-{stamp}-{os.getpid()}.log"
            log.write_text(text)
            break
        except OSError:
            log = None
    where = f"the traceback is in {log}" if log else "the traceback could not be saved"
    first = " ".join(str(error).split())[:200]
    print(f"addedinertia: internal error (a bug, please report it): {type(error).__name__}: {first}; {where}",
          file=sys.stderr)
    return EXIT_BUG


def emit_json(obj: dict[str, Any]) -> None:
    """Exactly one JSON object on stdout."""
    print(json.dumps(plain(obj), allow_nan=False))


def info(*parts: Any) -> None:
    """Human-readable text: always on stderr, so stdout stays one JSON object."""
    print(*parts, file=sys.stderr)


def non_negative_float(text: str) -> float:
    """argparse type: ``text`` as a finite float >= 0 (in the option's unit); ArgumentTypeError otherwise."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number; expected a finite number >= 0") from None
    if not math.isfinite(v) or v < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a finite number >= 0")
    return v


def non_negative_int(text: str) -> int:
    """A seed: numpy's SeedSequence takes whole numbers >= 0 only."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; expected a whole number >= 0") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 0")
    return v


def positive_int(text: str) -> int:
    """argparse type: ``text`` as an integer > 0; ArgumentTypeError otherwise."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; expected a whole number > 0") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer > 0")
    return v
