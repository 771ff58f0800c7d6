"""A suite's ``drive`` block: the drive's flaws drawn per scenario (sim/drive.py), with units.

Each key is one of :data:`~..rig.drive.UNITS` and its value a quantity with its unit
(``"90 %"``) or a range ``["80 %", "92 %"]`` drawn uniformly per scenario seed, from the
drive's own random stream (so adding a drive block never moves the other draws)::

    drive:
      gear_ratio: ["4 -", "8 -"]           # motor turns per flywheel turn (known: rig.gear_ratio)
      gear_efficiency: ["80 %", "92 %"]    # hidden
      gear_drag: ["5 mN m", "20 mN m"]     # hidden, at the flywheel
      supply: ["24 V", "36 V"]             # MotorParams.u_max (known: rig.u_max)

The scenario's drawn ``k_t`` is the torque per ampere at the flywheel: with a gearbox the
motor's own constant becomes ``k_t / gear_ratio``. A number without its unit, an unknown
key or an impossible value (a supply at or below ``R i_max``, an efficiency above 1) is
refused naming the suite file and the key.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.config_io import ConfigError
from addedinertia_env.sim.drive import UNITS, DriveParams, parse_quantity

STREAM = 103  # spawn key of the drive's random stream (scenario_draws uses 100..102)


def validate_drive(block: Any, path: Path) -> dict[str, tuple[float, float]]:
    """``{key: (low, high)}`` in SI units from a suite's ``drive`` block (module doc); ConfigError naming
    ``path`` and the key."""
    if block is None:
        return {}
    where = f"{path}: drive"
    if not isinstance(block, dict):
        raise ConfigError(f"{where} = {block!r}: expected a mapping of drive keys {sorted(UNITS)}")
    out: dict[str, tuple[float, float]] = {}
    for key, value in block.items():
        if key not in UNITS:
            raise ConfigError(f"{where}: unknown key {key!r}; allowed keys are {sorted(UNITS)}")
        if key == "driver_bandwidth":
            raise ConfigError(f"{where}.driver_bandwidth: give driver_time_constant in a suite (drawn uniformly)")
        ends = value if isinstance(value, list) else [value, value]
        if len(ends) != 2:
            raise ConfigError(f"{where}.{key} = {value!r}: expected a quantity or [low, high] quantities with units")
        lo, hi = (parse_quantity(v, key, where) for v in ends)
        if lo > hi:
            raise ConfigError(f"{where}.{key} = {value!r}: expected low <= high")
        out[key] = (lo, hi)
    fields = {k: v[0] for k, v in out.items() if k != "supply"}
    try:  # the ends must be a possible drive
        DriveParams(**{UNITS[k][0]: v for k, v in fields.items()})
        DriveParams(**{UNITS[k][0]: out[k][1] for k in fields})
    except ValueError as e:
        raise ConfigError(f"{where}: {e}") from None
    return out


def apply_drive(scenario, spec: dict[str, tuple[float, float]]):
    """``scenario`` with its drive drawn for its seed (module doc); ValueError for a drawn supply at
    or below ``R i_max``."""
    if not spec:
        return scenario
    rng = np.random.default_rng(np.random.SeedSequence(entropy=scenario.seed, spawn_key=(STREAM,)))
    drawn = {k: float(rng.uniform(lo, hi)) if hi > lo else lo for k, (lo, hi) in sorted(spec.items())}
    rig = scenario.rig
    motor = rig.motor
    supply = drawn.pop("supply", None)
    drive = dataclasses.replace(rig.drive, **{UNITS[k][0]: v for k, v in drawn.items()})
    if drive.gear_ratio != rig.drive.gear_ratio:  # the drawn k_t stays the flywheel's
        motor = dataclasses.replace(motor, k_t=motor.k_t * rig.drive.gear_ratio / drive.gear_ratio)
    if supply is not None:
        if not supply > motor.R * motor.i_max:
            raise ValueError(f"drive.supply {supply:g} V: expected more than R i_max = {motor.R * motor.i_max:g} V")
        motor = dataclasses.replace(motor, u_max=supply)
    return dataclasses.replace(scenario, rig=rig.replace(drive=drive, motor=motor))


def check_supply_floor(spec: dict[str, tuple[float, float]], motor_block: dict[str, Any], presets, path: Path) -> None:
    """Refuse, when the suite is loaded, a ``drive.supply`` range whose low end cannot drive the current
    limit through the winding at rest (``R i_max`` of each preset, with the suite's ``motor`` overrides at
    their largest), rather than on the first seed that draws it; ConfigError naming ``path`` and the key."""
    if "supply" not in spec:
        return
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping  # noqa: PLC0415

    low = spec["supply"][0]

    def largest(key: str, default: float) -> float:
        v = motor_block.get(key, default)
        return float(max(v)) if isinstance(v, list) else float(v)

    for preset in presets:
        motor = rig_from_mapping(load_preset(preset)).motor
        floor = largest("R", motor.R) * largest("i_max", motor.i_max)
        if not low > floor:
            raise ConfigError(f"{path}: drive.supply = {low:g} V at its low end: expected more than R i_max = "
                              f"{floor:g} V on preset {preset!r} (the voltage that drives the current limit "
                              "through the winding with the flywheel at rest)")
