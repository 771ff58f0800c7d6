"""Faults the bench emulator can inject: the ``--faults SPEC`` option of ``bench-server``.

``SPEC`` is a comma-separated list of ``name[=value][@start]``; ``start`` is in seconds
of board time after the last RESET (default 0: from the start). Names and values:

==============  =====================================================================
``latency=MS``  every frame the board sends is delayed by MS milliseconds
``jitter=MS``   plus a uniform random delay in [0, MS] ms (frame order is kept)
``drop=P``      each frame the board sends is lost with probability P (0..1)
``corrupt=P``   each frame the board sends has one bit flipped with probability P
``disconnect``  the board closes the connection once (a pulled cable)
``glitch=RAD``  one SAMPLE reports the hull angle off by RAD rad (default 0.2)
``stuck_brake`` the brake stops following requests; it stays as it is
``seed=N``      seed of the random draws (default 0)
==============  =====================================================================

Example: ``drop=0.5@1.0,latency=5,jitter=2`` adds 5..7 ms to every frame and, from one
second after RESET, loses half of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

NAMES = ("latency", "jitter", "drop", "corrupt", "disconnect", "glitch", "stuck_brake", "seed")
_DEFAULTS = {"disconnect": 1.0, "glitch": 0.2, "stuck_brake": 1.0}


class FaultSpecError(ValueError):
    """A ``--faults`` string that cannot be parsed; the message names the item."""


@dataclass(frozen=True)
class Fault:
    """One injected fault: its name (:data:`NAMES`), value (unit per fault) and start time."""

    name: str
    value: float
    start_s: float = 0.0  # s of board time after RESET


@dataclass(frozen=True)
class FaultPlan:
    """The faults of one emulator run (parsed ``--faults``) and the seed of their random draws."""

    faults: tuple[Fault, ...] = ()
    seed: int = 0
    spec: str = ""

    def get(self, name: str) -> Fault | None:
        """The fault called ``name`` in this plan, or ``None``; a name no fault has is an error
        (a misspelt name in the emulator must not read as "not active")."""
        if name not in NAMES:
            raise KeyError(f"no fault is called {name!r}; the faults are {', '.join(NAMES)}")
        for f in self.faults:
            if f.name == name:
                return f
        return None

    def active(self, name: str, board_t: float) -> float:
        """The fault's value if it is active at ``board_t`` (s after RESET), else 0."""
        f = self.get(name)
        return f.value if f is not None and board_t >= f.start_s else 0.0

    @property
    def empty(self) -> bool:
        """Whether no fault is injected."""
        return not self.faults

    def to_dict(self) -> dict[str, dict[str, float]]:
        """The plan as ``{fault: {value, start_s}}`` (value in the fault's unit, start in s after RESET)."""
        return {f.name: {"value": f.value, "start_s": f.start_s} for f in self.faults}


def parse_faults(spec: str | None) -> FaultPlan:
    """Parse a ``--faults`` string; see the module docstring for the grammar."""
    if not spec or not spec.strip() or spec.strip() == "none":
        return FaultPlan()
    faults: list[Fault] = []
    seed = 0
    seen: set[str] = set()
    for raw in spec.split(","):
        item = raw.strip()
        if not item:
            continue
        body, _, start_text = item.partition("@")
        name, eq, value_text = body.partition("=")
        name = name.strip()
        if name not in NAMES:
            raise FaultSpecError(f"--faults item {item!r}: unknown fault {name!r}; expected one of {', '.join(NAMES)}")
        if name in seen:
            raise FaultSpecError(f"--faults item {item!r}: {name!r} given twice")
        seen.add(name)
        if eq:
            value = _number(value_text, item)
        elif name in _DEFAULTS:
            value = _DEFAULTS[name]
        else:
            raise FaultSpecError(f"--faults item {item!r}: {name} needs a value, e.g. {name}=0.1")
        start = _number(start_text, item) if start_text else 0.0
        if start < 0:
            raise FaultSpecError(f"--faults item {item!r}: start time {start} s must be >= 0")
        if name in ("drop", "corrupt") and not 0.0 <= value <= 1.0:
            raise FaultSpecError(f"--faults item {item!r}: probability {value} must be in 0..1")
        if name in ("latency", "jitter") and not 0.0 <= value <= 10_000.0:
            raise FaultSpecError(f"--faults item {item!r}: {value} ms must be in 0..10000")
        if name == "seed":
            seed = int(value)
            continue
        faults.append(Fault(name, value, start))
    return FaultPlan(tuple(faults), seed, spec)


def _number(text: str, item: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise FaultSpecError(f"--faults item {item!r}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise FaultSpecError(f"--faults item {item!r}: {text!r} must be finite")
    return v


@dataclass
class FaultLog:
    """When the emulator's faults took effect and when its board reached the safe state."""

    events: list[dict] = field(default_factory=list)

    def add(self, name: str, wall: float, board_t: float, **extra) -> None:
        """Log event ``name`` at wall-clock time ``wall`` (s, monotonic) and board time ``board_t`` (s after RESET), with ``extra`` fields."""
        self.events.append({"event": name, "wall": wall, "board_t": board_t, **extra})

    def first(self, name: str) -> dict | None:
        """The first logged event called ``name``, or None."""
        return next((e for e in self.events if e["event"] == name), None)
