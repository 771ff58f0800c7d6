"""Helpers shared by the subcommands: JSON output, errors, argument types."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np

from ..experiment.protocol import ExperimentError
from ..identify.common import IdentificationError
from ..record import RecordError
from ..rig.presets import ConfigError


class BadInput(ValueError):
    """Any user-facing input problem not covered by a more specific error."""


# OSError covers missing files and output folders that cannot be written (permissions, a file in the way).
BAD_INPUT = (RecordError, ConfigError, IdentificationError, BadInput, ExperimentError, OSError)


def fail(error: BaseException) -> int:
    message = str(error).replace("\n", " ")
    print(f"addedinertia: error: {message}", file=sys.stderr)
    return 2


def emit_json(obj: dict[str, Any]) -> None:
    """Exactly one JSON object on stdout."""
    print(json.dumps(_plain(obj), allow_nan=False))


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    return x


def info(*parts: Any) -> None:
    """Human-readable text: always on stderr, so stdout stays one JSON object."""
    print(*parts, file=sys.stderr)


def non_negative_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v) or v < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a finite number >= 0")
    return v


def non_negative_int(text: str) -> int:
    """A seed: numpy's SeedSequence takes whole numbers >= 0 only."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 0")
    return v


def positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer > 0")
    return v
