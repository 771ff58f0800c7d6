"""A free-decay amplitude series (``swing``, ``theta_deg``), read and checked; the reading resolution."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

READING_RESOLUTION_DEG = 0.1025  # deg, one 0.5 mm step of trace at 0.205 deg/mm (data README)
READING_SIGMA_DEG = READING_RESOLUTION_DEG / math.sqrt(12.0)
MIN_AMPLITUDES = 5


class DecayInputError(ValueError):
    """An amplitude file that cannot be analysed; the message names file, line, column and value."""


@dataclass
class Amplitudes:
    """A free-decay amplitude series read from ``path``: half-swing numbers and amplitudes in deg."""

    path: str
    swing: np.ndarray  # half-swing numbers
    theta: np.ndarray  # deg


def read_amplitudes(path: str | Path) -> Amplitudes:
    """Read and check an amplitude series; raises :class:`DecayInputError` on anything doubtful."""
    path = Path(path)
    rows = list(csv.reader(read_text(path, "an amplitude CSV with columns 'swing' and 'theta_deg'").splitlines()))
    if not rows:
        raise DecayInputError(f"{path}: empty file; expected a header with columns 'swing' and 'theta_deg'")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in ("swing", "theta_deg") if c not in header]
    if missing:
        raise DecayInputError(f"{path}: line 1: missing column(s) {missing}; header is {header}, expected "
                              "'swing' (half-swing number) and 'theta_deg' (amplitude, degrees)")
    ks, kt = header.index("swing"), header.index("theta_deg")
    swing, theta = [], []
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise DecayInputError(f"{path}: line {n}: {len(row)} fields, expected {len(header)} as in the header")
        for col, k, out in (("swing", ks, swing), ("theta_deg", kt, theta)):
            text = row[k].strip()
            try:
                v = float(text)
            except ValueError:
                raise DecayInputError(f"{path}: line {n}, column '{col}': {text!r} is not a number; expected a finite number") from None
            if not math.isfinite(v):
                raise DecayInputError(f"{path}: line {n}, column '{col}': {text!r}; expected a finite number")
            out.append(v)
        if swing[-1] != round(swing[-1]):
            raise DecayInputError(f"{path}: line {n}, column 'swing': {row[ks].strip()!r}; expected a whole number")
        if theta[-1] <= 0:
            raise DecayInputError(f"{path}: line {n}, column 'theta_deg': {row[kt].strip()!r}; expected an "
                                  "amplitude > 0 degrees (amplitudes are magnitudes)")
        if len(swing) > 1 and swing[-1] != swing[-2] + 1:
            raise DecayInputError(f"{path}: line {n}, column 'swing': {swing[-1]:g} after {swing[-2]:g}; expected "
                                  "successive half swings numbered 1, 2, 3, ... with none missing")
    if len(theta) < MIN_AMPLITUDES:
        raise DecayInputError(f"{path}: {len(theta)} amplitude(s); expected at least {MIN_AMPLITUDES}")
    th = np.array(theta)
    if th[-1] >= th[0]:
        raise DecayInputError(f"{path}: the last amplitude {th[-1]:g} deg is not below the first {th[0]:g} deg; "
                              "expected a decaying record")
    return Amplitudes(path=str(path), swing=np.array(swing), theta=th)


def read_text(path: Path, what: str) -> str:
    """The text of ``path``; DecayInputError naming the file and ``what`` was expected otherwise."""
    if not path.exists():
        raise DecayInputError(f"{path}: no such file; expected {what}")
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise DecayInputError(f"{path}: not UTF-8 text; expected {what}") from None
    except OSError as e:
        raise DecayInputError(f"{path}: cannot read ({e.strerror}); expected {what}") from None
