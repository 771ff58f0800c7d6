"""What the lab knows about its bench: the half of the run record's ``rig`` block that the
board cannot tell (inertias, stiffness, motor constants from calibration), plus the
safety limits and the experiment plan for this bench.

The board's half (encoder counts, sample rate, current and voltage limits) comes from
its CAPS message at connection time; :func:`known_rig` joins the two into the typed
:class:`~addedinertia_env.rig.known.KnownRig` (the run record's ``rig`` block).

A lab file is YAML (example: ``hw_adapter/labs/example.yaml``)::

    name: tank-1
    J_hull: 5.8            # kg m^2, hull + rod + frame + stator, test in air
    J_flywheel: 0.1        # kg m^2
    c_torsion: 43.4        # N m/rad, static calibration
    phi_neutral: 0.0       # rad, encoder frame
    k_t: 0.25              # N m/A
    R: 0.5                 # ohm
    L: 0.0005              # H
    motor_friction: {viscous: 0.0001, coulomb: 0.002}
    gear_ratio: 1.0        # optional: motor turns per flywheel turn (k_t is then the motor's own)
    limits: {phi_max: 0.35, rate_max: 1.0}     # optional, SafetyLimits fields
    experiment: {alpha: 0.1, hold_s: 2.0}      # optional, ExperimentPlan fields

For the emulator, a rig preset name (``wigley-2m``) may stand in for a lab file: its
experimenter-known constants (``RigParams.known()``, a ``KnownRig``; never the truth) are used.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from addedinertia_env.config_io import check_keys, read_yaml

from addedinertia_env.rig.known import KnownRig
from addedinertia_env.rig.presets import ConfigError, load_preset, rig_from_mapping
from addedinertia_env.experiment.protocol import plan_from_preset

from .messages import CAP_EMULATOR, Caps
from .safety import SafetyLimits

MECHANICAL_KEYS = ("J_hull", "J_flywheel", "c_torsion", "phi_neutral", "k_t", "R", "L")
POSITIVE_KEYS = ("J_hull", "J_flywheel", "c_torsion", "k_t", "R", "L")
LAB_KEYS = {"name", *MECHANICAL_KEYS, "motor_friction", "limits", "experiment", "gear_ratio"}


@dataclass(frozen=True)
class LabConfig:
    """A lab file, checked: the bench's constants, safety limits and experiment plan."""

    name: str
    constants: dict[str, Any]  # MECHANICAL_KEYS + motor_friction, SI
    limits: dict[str, float] = field(default_factory=dict)  # SafetyLimits overrides
    experiment: dict[str, Any] = field(default_factory=dict)  # ExperimentPlan overrides
    source: str = ""

    def safety_limits(self, caps: Caps | None = None, **overrides: float) -> SafetyLimits:
        """The lab's limits, never looser than the board's own current and voltage limits."""
        values = {**self.limits, **{k: v for k, v in overrides.items() if v is not None}}
        if caps is not None:
            values["i_max"] = min(values.get("i_max", caps.i_max), caps.i_max)
            values["u_max"] = min(values.get("u_max", caps.u_max), caps.u_max)
        try:
            return SafetyLimits(**values)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{self.source or self.name}: limits: {e}") from None

    def plan(self, **overrides: Any):
        """The experiment plan of this lab (``ExperimentPlan``), with ``overrides`` applied."""
        return plan_from_preset({"experiment": self.experiment, "_path": self.source or self.name}, **overrides)


def load_lab(name_or_path: str) -> LabConfig:
    """A lab file (``.yaml``) or, for the emulator, a rig preset's known constants."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") and path.exists():
        data = read_yaml(path, "lab")
        return lab_from_mapping(data, str(path))
    preset = load_preset(name_or_path)  # raises ConfigError naming the known presets
    known = rig_from_mapping(preset).known()
    constants: dict[str, Any] = {k: getattr(known, k) for k in MECHANICAL_KEYS}
    if known.gear_ratio != 1.0:  # a geared preset: the motor's own k_t and the ratio, as a lab file states them
        constants["k_t"] = known.motor_k_t if known.motor_k_t is not None else known.k_t / known.gear_ratio
        constants["gear_ratio"] = known.gear_ratio
    constants["motor_friction"] = {"viscous": known.friction_viscous, "coulomb": known.friction_coulomb}
    return LabConfig(name=str(preset.get("name", name_or_path)), constants=constants,
                     experiment=dict(preset.get("experiment") or {}), source=preset["_path"])


def lab_from_mapping(data: Any, where: str) -> LabConfig:
    """Check a lab file's mapping (``where`` names it in errors); raises ``ConfigError``."""
    check_keys(data, LAB_KEYS, where)
    constants: dict[str, Any] = {}
    for key in MECHANICAL_KEYS:
        if key not in data:
            raise ConfigError(f"{where}: missing key {key!r} (SI units; see hw_adapter/labs/example.yaml)")
        v = data[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ConfigError(f"{where}: {key} = {v!r}: expected a finite number (SI units)")
        if key in POSITIVE_KEYS and v <= 0:
            raise ConfigError(f"{where}: {key} = {v!r}: expected a number > 0 (SI units)")
        constants[key] = float(v)
    friction = data.get("motor_friction", {"viscous": 0.0, "coulomb": 0.0})
    if not isinstance(friction, dict) or set(friction) - {"viscous", "coulomb"}:
        raise ConfigError(f"{where}: motor_friction = {friction!r}: expected a mapping with 'viscous' and 'coulomb'")
    for k, v in friction.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ConfigError(f"{where}: motor_friction.{k} = {v!r}: expected a finite number >= 0")
    constants["motor_friction"] = {k: float(v) for k, v in friction.items()}
    if "gear_ratio" in data:
        g = data["gear_ratio"]
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not math.isfinite(g) or g < 1:
            raise ConfigError(f"{where}: gear_ratio = {g!r}: expected a number >= 1 (motor turns per flywheel turn)")
        constants["gear_ratio"] = float(g)
    limits = data.get("limits") or {}
    allowed = {f.name for f in dataclasses.fields(SafetyLimits)}
    if not isinstance(limits, dict) or set(limits) - allowed:
        raise ConfigError(f"{where}: limits = {limits!r}: allowed keys are {sorted(allowed)}")
    experiment = data.get("experiment") or {}
    if not isinstance(experiment, dict):
        raise ConfigError(f"{where}: experiment = {experiment!r}: expected a mapping of ExperimentPlan fields")
    lab = LabConfig(name=str(data.get("name", Path(where).stem)), constants=constants, limits=dict(limits),
                    experiment=dict(experiment), source=where)
    lab.safety_limits()  # validate now, with the file named
    lab.plan()
    return lab


def known_rig(lab: LabConfig, caps: Caps) -> KnownRig:
    """What the experimenter knows of this bench: the lab's constants joined with the board's
    CAPS (limits, encoder counts, sample rate); the board and lab names ride along in ``extra``."""
    c, fric = lab.constants, lab.constants["motor_friction"]
    gear = c.get("gear_ratio")  # a geared bench: k_t at the flywheel, the motor's own kept for the record
    return KnownRig(J_hull=c["J_hull"], J_flywheel=c["J_flywheel"], c_torsion=c["c_torsion"],
                    phi_neutral=c["phi_neutral"], k_t=c["k_t"] * (gear or 1.0), gear_ratio=gear or 1.0,
                    motor_k_t=c["k_t"] if gear is not None else None, R=c["R"], L=c["L"], i_max=caps.i_max,
                    u_max=caps.u_max, friction_viscous=fric.get("viscous", 0.0),
                    friction_coulomb=fric.get("coulomb", 0.0), phi_counts=caps.phi_counts,
                    psi_counts=caps.psi_counts, sample_rate=caps.sample_rate,
                    extra={"board": {"id": caps.board_id, "firmware": caps.firmware_version,
                                     "emulator": bool(caps.flags & CAP_EMULATOR), "watchdog_ms": caps.watchdog_ms,
                                     "brake_response_ms": caps.brake_response_ms},
                           "lab": lab.name})

