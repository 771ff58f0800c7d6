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
  bandwidth ``1 / (2 pi tau)``; 0 is the ideal dead-beat loop of :mod:`.motor`);
* backlash: a gap of ``backlash`` rad (full width, at the flywheel) between the gearbox's
  output and the flywheel; the rotor (``rotor_inertia`` at the motor shaft, ``N^2`` times
  that at the flywheel) crosses it under the motor's torque alone and hits the far flank in
  a plastic impact (:func:`backlash_step`). The work the motor puts into the crossing shows
  in the supply (the rotor's relative rate adds to the back-EMF) but not in the current times
  the flywheel's angle, and is lost in the impact (hidden).

A YAML ``drive`` block states each value with its unit (:func:`drive_from_block`), so a
number without a unit is refused; so are unknown keys and impossible values.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numba import njit

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
    backlash: float = 0.0  # rad at the flywheel, the gearbox's gap (full width, flank to flank)
    rotor_inertia: float = 0.0  # kg m^2 at the motor shaft (rotor + gear input stage), for the gap crossing

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
        for name in ("gear_drag", "cogging_torque", "cogging_periods", "driver_time_constant", "backlash",
                     "rotor_inertia"):
            if getattr(self, name) < 0:
                raise ValueError(f"DriveParams.{name} = {getattr(self, name)!r}: expected >= 0")
        if self.cogging_torque > 0 and self.cogging_periods < 1:
            raise ValueError(f"DriveParams.cogging_periods = {self.cogging_periods!r}: expected >= 1 cycle per motor "
                             "turn when cogging_torque > 0")
        if self.backlash > 0 and not self.rotor_inertia > 0:
            raise ValueError(f"DriveParams.rotor_inertia = {self.rotor_inertia!r}: expected > 0 kg m^2 when "
                             "backlash > 0 (the rotor's inertia sets how it crosses the gap)")
        if self.backlash > math.pi / 18:
            raise ValueError(f"DriveParams.backlash = {self.backlash!r}: expected at most 10 deg (0.1745 rad); "
                             "gearheads have 0.1-2 deg")

    @property
    def ideal(self) -> bool:
        """Whether this is the ideal drive (direct, no losses, no cogging, dead-beat current loop)."""
        return self == DriveParams()

    @property
    def has_torque(self) -> bool:
        """Whether the drive puts a torque of its own on the flywheel (mesh friction, drag, cogging)."""
        return self.gear_efficiency < 1.0 or self.gear_drag > 0 or self.cogging_torque > 0

    @property
    def reflected_rotor_inertia(self) -> float:
        """The rotor's inertia seen at the flywheel, ``N^2 J_rotor``, kg m^2."""
        return self.gear_ratio**2 * self.rotor_inertia

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
    "backlash": ("backlash", {"rad": 1.0, "deg": _DEG, "arcmin": _DEG / 60.0}),
    "rotor_inertia": ("rotor_inertia", {"kg m^2": 1.0, "g cm^2": 1e-7}),
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


def backlash_step(gap, rate, torque, inertia, width, h):
    """The rotor in the gearbox's gap over one physics step with the motor's torque held.

    ``gap`` rad: the rotor's angle (at the flywheel) minus the flywheel's, in
    ``[-width/2, width/2]``; ``rate`` rad/s its rate; ``torque`` N m the motor's torque at the
    flywheel held over the step; ``inertia`` kg m^2 the rotor's at the flywheel
    (:attr:`DriveParams.reflected_rotor_inertia`); ``width`` rad the gap; ``h`` s the step.
    Scalars (plain Python, for the MuJoCo rig) or arrays broadcast per environment (the
    batched rig: the same function compiled, looped). An environment without backlash
    (``width`` 0) passes the torque unchanged. The rotor's inertia is small against the
    flywheel's, so in the gap it moves under the motor's torque alone (``inertia gap'' =
    torque``), in contact it moves with the flywheel, and a contact holds while the torque
    presses into it. Hitting a flank is a plastic impact: the flywheel receives the rotor's
    relative momentum ``inertia rate`` and the relative kinetic energy ``inertia rate^2 / 2``
    is lost.

    Returns ``(gap, rate, engaged, impulse, loss)``: the state after the step, the fraction of
    the step in contact (the torque transmitted), the impulse (N m s) and the energy lost in
    impacts (J) over the step. The flywheel feels ``torque engaged + impulse / h`` held over
    the step; the rotor's mean relative rate ``(gap_new - gap) / h`` adds to the back-EMF.
    Exact for a held torque (each flight a parabola, each impact found by its root).
    """
    if all(np.ndim(x) == 0 for x in (gap, rate, torque, inertia, width)):
        return backlash_scalar(float(gap), float(rate), float(torque), float(inertia), float(width), float(h))
    arrays = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (gap, rate, torque, inertia, width)))
    out = [np.empty(arrays[0].shape) for _ in range(5)]
    _backlash_loop(*(np.array(a, dtype=float).ravel() for a in arrays), float(h), *(o.ravel() for o in out))
    return tuple(out)


def backlash_scalar(g: float, v: float, torque: float, inertia: float, width: float, h: float):
    """:func:`backlash_step` for one environment, plain floats (compiled as it is for the batched rig)."""
    if width <= 0.0:
        return g, v, 1.0, 0.0, 0.0
    half = 0.5 * width
    a = torque / inertia
    left = h
    engaged = impulse = loss = 0.0
    for _ in range(6):  # contact, flight, impact, contact or flight again: a few phases at most
        if left <= 0.0:
            break
        if (g >= half and v >= 0.0 and a >= 0.0) or (g <= -half and v <= 0.0 and a <= 0.0):
            engaged += left  # pressed into a flank (or at rest on it): the torque goes through
            v = 0.0
            left = 0.0
            break
        t_hit, side = _time_to_flank(g, v, a, half)
        if t_hit <= left:
            v = v + a * t_hit
            g = side * half
            impulse += inertia * v
            loss += 0.5 * inertia * v * v
            v = 0.0
            left -= t_hit
        else:
            g = min(max(g + v * left + 0.5 * a * left * left, -half), half)
            v = v + a * left
            left = 0.0
    return g, v, engaged / h, impulse, loss


def _time_to_flank(g: float, v: float, a: float, half: float):
    """The first time > 0 at which ``g + v t + a t^2 / 2`` reaches a flank ``+-half``, and that
    flank's sign (inf, 0: never). A flank just left (t = 0) is not hit again."""
    best = math.inf
    side = 0.0
    for s in (1.0, -1.0):
        c = g - s * half  # a t^2 / 2 + v t + c = 0
        t1 = t2 = math.inf
        if abs(a) < 1e-12:
            if v != 0.0:
                t1 = -c / v
        else:
            disc = v * v - 2.0 * a * c
            if disc >= 0.0:
                r = math.sqrt(disc)
                t1 = (-v - r) / a
                t2 = (-v + r) / a
        if 1e-15 < t1 < best:
            best, side = t1, s
        if 1e-15 < t2 < best:
            best, side = t2, s
    return best, side


_time_to_flank = njit(cache=True)(_time_to_flank)  # called from plain Python and from the compiled loop
_backlash_scalar_jit = njit(cache=True)(backlash_scalar)


@njit(cache=True)
def _backlash_loop(g, v, torque, inertia, width, h, g1, v1, engaged, impulse, loss):  # pragma: no cover - compiled
    """:func:`backlash_scalar` for every environment ``k``, into the output arrays."""
    for k in range(g.shape[0]):
        g1[k], v1[k], engaged[k], impulse[k], loss[k] = _backlash_scalar_jit(g[k], v[k], torque[k], inertia[k],
                                                                             width[k], h)
