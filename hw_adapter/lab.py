"""What the lab knows about its bench: the half of the run record's ``rig`` block that the
board cannot tell (inertias, stiffness, motor constants from calibration), plus the
safety limits and the experiment plan for this bench.

The board's half (encoder counts, sample rate, current and voltage limits) comes from
its CAPS message at connection time; :func:`known_rig` joins the two into the typed
:class:`~addedinertia_env.rig.known.KnownRig` (the run record's ``rig`` block). Which keys are
the lab's, which are required and what each must be come from the block's one schema,
:data:`~addedinertia_env.rig.known.RIG_BLOCK` (the keys whose source is ``lab``).

A lab file is YAML (example: ``hw_adapter/labs/example.yaml``)::

    name: tank-1
    J_hull: 5.8            # kg m^2, hull + rod + frame + stator, test in air
    J_flywheel: 0.1        # kg m^2
    c_torsion: 43.4        # N m/rad, static calibration
    phi_neutral: 0.0       # rad, encoder frame
    k_t: 0.25              # N m/A
    R: 0.5                 # ohm
    L: 0.0005              # H; optional (0: neglected, absent: unknown)
    motor_friction: {viscous: 0.0001, coulomb: 0.002}   # optional (absent: 0)
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

from addedinertia_env.foundation.config_io import check_keys, read_yaml

from addedinertia_env.rig.known import FRICTION_KEYS, RIG_BLOCK, KnownRig, block_problems
from addedinertia_env.sim.presets import ConfigError, load_preset, rig_from_mapping
from addedinertia_env.experiment.protocol import plan_from_preset

from hw_adapter.messages import CAP_EMULATOR, Caps
from hw_adapter.safety import SafetyLimits

# The rig block's keys a lab states (calibration, data sheet); the board states the others.
LAB_RIG_KEYS = tuple(key.name for key in RIG_BLOCK if key.source == "lab")
LAB_KEYS = {"name", *LAB_RIG_KEYS, "limits", "experiment"}


@dataclass(frozen=True)
class LabConfig:
    """A lab file, checked: the bench's constants, safety limits and experiment plan."""

    name: str
    constants: dict[str, Any]  # the stated LAB_RIG_KEYS (rig-block names, SI units)
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
    block = rig_from_mapping(preset).known().to_block()
    constants = {k: block[k] for k in LAB_RIG_KEYS if k in block}
    return LabConfig(name=str(preset.get("name", name_or_path)), constants=constants,
                     experiment=dict(preset.get("experiment") or {}), source=preset["_path"])


def lab_from_mapping(data: Any, where: str) -> LabConfig:
    """Check a lab file's mapping (``where`` names it in errors); raises ``ConfigError``."""
    check_keys(data, LAB_KEYS, where)
    for key, shown, expected in block_problems(data, LAB_RIG_KEYS):  # the first, as the schema orders them
        if expected == "missing":
            raise ConfigError(f"{where}: missing key {key!r} (SI units; see hw_adapter/labs/example.yaml)")
        raise ConfigError(f"{where}: {key} = {shown}: expected {expected}")
    friction = data.get("motor_friction") or {}
    if set(friction) - set(FRICTION_KEYS):
        raise ConfigError(f"{where}: motor_friction = {friction!r}: expected a mapping with 'viscous' and 'coulomb'")
    constants: dict[str, Any] = {k: float(data[k]) for k in LAB_RIG_KEYS
                                 if data.get(k) is not None and k != "motor_friction"}
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
    block = {**lab.constants, "i_max": caps.i_max, "u_max": caps.u_max,
             "encoder_counts": {"phi": caps.phi_counts, "psi": caps.psi_counts}, "sample_rate": caps.sample_rate}
    board = {"id": caps.board_id, "firmware": caps.firmware_version, "emulator": bool(caps.flags & CAP_EMULATOR),
             "watchdog_ms": caps.watchdog_ms, "brake_response_ms": caps.brake_response_ms}
    return dataclasses.replace(KnownRig.from_block(block), extra={"board": board, "lab": lab.name})

