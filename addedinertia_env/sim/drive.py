"""The drive's flaws: a gearbox, cogging, a current driver with its own bandwidth (issue 28).

:class:`DriveParams` is the simulated truth of the drive between the supply and the
flywheel beyond the ideal motor of :mod:`.motor` (the supply voltage itself is
``MotorParams.u_max``: the drive's voltage is clipped to it, so the back-EMF eats into it
as the flywheel speeds up). Every field's neutral value leaves the rig exactly as without
a drive block. The laws live in :mod:`.forces` (:func:`~.forces.drive_torque`,
:func:`~.forces.true_torque_constant`) and :mod:`.motor` (the driver's lag), so every
engine runs the same ones.

* gearbox: ``gear_ratio`` motor turns per flywheel turn (the motor's torque and back-EMF
  constant seen at the flywheel are ``gear_ratio k_t``; known to the experimenter, the run
  record's ``rig.gear_ratio``); mesh friction ``(1 - gear_efficiency) |torque|`` plus the
  no-load ``gear_drag``, both against the flywheel's relative motion (hidden);
* cogging: ``cogging_torque sin(cogging_periods theta + cogging_phase)`` on the rotor
  (``theta = gear_ratio psi``), the magnet's pull on the stator teeth: absent from the
  current, conservative over a period (hidden);
* driver: a current loop with time constant ``driver_time_constant`` (first order, so
  bandwidth ``1 / (2 pi tau)``; 0 is the ideal dead-beat loop of :mod:`.motor`).

A YAML ``drive`` block states each value with its unit (:func:`drive_from_block`), so a
number without a unit is refused; so are unknown keys and impossible values.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields
from typing import Any

from addedinertia_env.foundation.config_io import ConfigError, check_keys


@dataclass(frozen=True)
class DriveParams:
    """The drive between supply and flywheel, SI units; the defaults are the ideal drive."""

    gear_ratio: float = 1.0  # -, motor turns per flywheel turn (1: direct drive)
    gear_efficiency: float = 1.0  # -, mesh efficiency (torque out / torque in) under load
    gear_drag: float = 0.0  # N m at the flywheel, the gearbox's no-load running torque
    cogging_torque: float = 0.0  # N m at the motor shaft, peak
    cogging_periods: float = 0.0  # -, cogging cycles per motor turn (lcm of slots and poles)
    cogging_phase: float = 0.0  # rad, cogging phase at psi = 0
    driver_time_constant: float = 0.0  # s, the current loop's first-order time constant (0: dead-beat)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"DriveParams.{f.name} = {v!r}: expected a finite number")
        if self.gear_ratio < 1.0:
            raise ValueError(f"DriveParams.gear_ratio = {self.gear_ratio!r}: expected >= 1 (motor turns per flywheel "
                             "turn; a gearbox reduces)")
        if not 0.3 <= self.gear_efficiency <= 1.0:
            raise ValueError(f"DriveParams.gear_efficiency = {self.gear_efficiency!r}: expected 0.3 to 1 (a mesh "
                             "below 0.3 is self-locking, a worm drive, not a backdrivable gearbox)")
        for name in ("gear_drag", "cogging_torque", "cogging_periods", "driver_time_constant"):
            if getattr(self, name) < 0:
                raise ValueError(f"DriveParams.{name} = {getattr(self, name)!r}: expected >= 0")
        if self.cogging_torque > 0 and self.cogging_periods < 1:
            raise ValueError(f"DriveParams.cogging_periods = {self.cogging_periods!r}: expected >= 1 cycle per motor "
                             "turn when cogging_torque > 0")

    @property
    def ideal(self) -> bool:
        """Whether this is the ideal drive (direct, no losses, no cogging, dead-beat current loop)."""
        return self == DriveParams()

    @property
    def has_torque(self) -> bool:
        """Whether the drive puts a torque of its own on the flywheel (mesh friction, drag, cogging)."""
        return self.gear_efficiency < 1.0 or self.gear_drag > 0 or self.cogging_torque > 0

    def to_dict(self) -> dict[str, float]:
        """The non-neutral fields (SI units), for a run record's ``truth.drive``."""
        neutral = DriveParams()
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) != getattr(neutral, f.name)}


# The YAML drive block: key -> (field, {unit: factor to SI}).
_DEG = math.pi / 180.0
UNITS: dict[str, tuple[str, dict[str, float]]] = {
    "gear_ratio": ("gear_ratio", {"-": 1.0}),
    "gear_efficiency": ("gear_efficiency", {"-": 1.0, "%": 0.01}),
    "gear_drag": ("gear_drag", {"N m": 1.0, "mN m": 1e-3}),
    "cogging_torque": ("cogging_torque", {"N m": 1.0, "mN m": 1e-3}),
    "cogging_periods": ("cogging_periods", {"/turn": 1.0}),
    "cogging_phase": ("cogging_phase", {"rad": 1.0, "deg": _DEG}),
    "driver_time_constant": ("driver_time_constant", {"s": 1.0, "ms": 1e-3}),
    "driver_bandwidth": ("driver_time_constant", {"Hz": 1.0, "kHz": 1e3}),  # -> tau = 1 / (2 pi f)
    "supply": ("u_max", {"V": 1.0}),  # MotorParams.u_max
}
_VALUE = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


def parse_quantity(text: Any, key: str, where: str) -> float:
    """``"<number> <unit>"`` of drive key ``key`` in SI units; ConfigError naming ``where.key``
    for a bare number (no unit), an unknown unit or text that is not a quantity."""
    _, units = UNITS[key]
    if isinstance(text, bool) or isinstance(text, (int, float)):
        raise ConfigError(f"{where}.{key} = {text!r}: missing unit; expected '<number> <unit>' with unit one of "
                          f"{sorted(units)}")
    m = _VALUE.match(str(text))
    if not m or m.group(2) not in units:
        raise ConfigError(f"{where}.{key} = {text!r}: expected '<number> <unit>' with unit one of {sorted(units)}")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise ConfigError(f"{where}.{key} = {text!r}: expected a finite number")
    return value * units[m.group(2)]


def drive_from_block(block: Any, where: str, *, R: float, i_max: float) -> tuple[DriveParams, float | None]:
    """``(DriveParams, supply V or None)`` from a YAML ``drive`` block; ConfigError naming ``where``
    and the key for an unknown key, a value without its unit, or an impossible value (a negative
    drag, an efficiency over 1, a supply below ``R i_max``, the voltage that drives the current
    limit through the winding with the flywheel at rest). ``R`` ohm, ``i_max`` A: the motor's."""
    check_keys(block, set(UNITS), where)
    values: dict[str, float] = {}
    supply = None
    for key, text in block.items():
        if key == "_path":
            continue
        v = parse_quantity(text, key, where)
        if key == "supply":
            if not v > R * i_max:
                raise ConfigError(f"{where}.supply = {text!r}: expected more than R i_max = {R * i_max:g} V (the "
                                  "voltage that drives the current limit through the winding with the flywheel at rest)")
            supply = v
        elif key == "driver_bandwidth":
            if not v > 0:
                raise ConfigError(f"{where}.driver_bandwidth = {text!r}: expected a bandwidth > 0 Hz")
            values["driver_time_constant"] = 1.0 / (2.0 * math.pi * v)
        else:
            values[UNITS[key][0]] = v
    if "driver_bandwidth" in block and "driver_time_constant" in block:
        raise ConfigError(f"{where}: both driver_bandwidth and driver_time_constant given; expected one of them")
    try:
        return DriveParams(**values), supply
    except ValueError as e:
        raise ConfigError(f"{where}: {e}") from None
