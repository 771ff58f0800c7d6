"""Seeded scenarios: a rig preset with hull, damping, sensors and protocol randomised.

One seed makes one scenario. Its randomness is split with ``np.random.SeedSequence.spawn``
into independent streams (hull draw, sensor noise, controller/experiment), so that
changing how one component draws never shifts another's numbers.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from addedinertia_env.foundation.config_io import check_keys, read_yaml

from addedinertia_env.experiment.protocol import ExperimentPlan
from addedinertia_env.loop.control_loop import ControlLoop, LoopRig
from addedinertia_env.sim.effects import Effects
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.presets import (
    CONFIG_DIR,
    ConfigError,
    load_preset,
    rig_from_mapping,
    rig_path,
    sensors_for_quality,
)
from addedinertia_env.experiment.protocol import plan_from_preset

RANGE_KEYS = {"lambda_ratio", "drag_coefficient", "b1", "period_s", "J_flywheel", "k_t", "alpha", "hold_s",
              "sensor_quality"}


@dataclass(frozen=True)
class Scenario:
    """One seeded scenario: the rig (true parameters), the experiment plan and the seed streams.

    ``sensor_seed`` and ``controller_seed`` are independent streams spawned from ``seed``;
    ``sensor_quality`` is one of :data:`~addedinertia_env.sim.presets.SENSOR_QUALITY`;
    ``loop`` the control loop's delay, command rate and quantisation (``None``: ideal).
    """

    name: str
    seed: int
    rig: RigParams
    plan: ExperimentPlan
    sensor_seed: np.random.SeedSequence
    controller_seed: np.random.SeedSequence
    sensor_quality: str
    loop: ControlLoop | None = None  # the control loop's delay, command rate, quantisation (None: ideal)


def build_rig(scenario: Scenario, seed: int | np.random.SeedSequence | None = None) -> Any:
    """The simulated rig of ``scenario`` (MuJoCo), seen through its control loop if it has one.

    ``seed`` seeds the sensor noise (default: the scenario's own sensor stream)."""
    from addedinertia_env.sim.mujoco_rig import MujocoRig  # noqa: PLC0415 - MuJoCo only where a rig is built

    rig = MujocoRig(scenario.rig, seed=scenario.sensor_seed if seed is None else seed)
    return rig if scenario.loop is None or scenario.loop.ideal else LoopRig(rig, scenario.loop)


def load_ranges(path: str | Path | None = None) -> dict[str, Any]:
    """The randomisation ranges (``configs/randomization.yaml``, or ``path``) as ``{key: [low, high]}``.

    Keys are :data:`RANGE_KEYS`, each in its own unit (``period_s`` s, ``J_flywheel`` kg m^2,
    ``k_t`` N m/A, ...). Raises ConfigError naming the file for an unknown key or a range
    that is not ``[low, high]`` with ``low <= high``.
    """
    path = Path(path) if path else CONFIG_DIR / "randomization.yaml"
    data = check_keys(read_yaml(path, "randomisation ranges") or {}, RANGE_KEYS, str(path))
    for key, value in data.items():
        if key == "sensor_quality":
            continue
        if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)
                and value[0] <= value[1]):
            raise ConfigError(f"{path}: {key} = {value!r}; expected [low, high] with low <= high")
    return data


_BASE_CACHE: dict[tuple, tuple[dict[str, Any], RigParams]] = {}


def _preset_base(preset: str, hydrodynamics: str | dict | None) -> tuple[dict[str, Any], RigParams]:
    """Preset ``preset``'s mapping (read only: callers must not change it) and its rig, built once
    per file version and hydrodynamic model (environments draw a scenario per episode; the rig's
    parameter blocks are frozen dataclasses, so sharing them is safe)."""
    if isinstance(hydrodynamics, dict):  # not hashable: built each time
        data = load_preset(preset)
        return data, rig_from_mapping(data, hydrodynamics=hydrodynamics)
    path = rig_path(preset)
    key = (str(path.resolve()), path.stat().st_mtime_ns, hydrodynamics)
    if key not in _BASE_CACHE:
        if len(_BASE_CACHE) >= 64:  # a bounded cache: many presets or file versions start it afresh
            _BASE_CACHE.clear()
        data = load_preset(preset)
        _BASE_CACHE[key] = (data, rig_from_mapping(data, hydrodynamics=hydrodynamics))
    return _BASE_CACHE[key]


def make_scenario(seed: int, preset: str = "wigley-2m", ranges: dict[str, Any] | None = None,
                  fixed: dict[str, Any] | None = None, effects: Effects | None = None,
                  name: str | None = None, hydrodynamics: str | dict | None = None) -> Scenario:
    """Scenario number ``seed``: draws each key of ``ranges`` unless ``fixed`` pins it.

    ``hydrodynamics``: overrides the preset's hydrodynamic model (``"cummins"``: radiation
    memory from the hull's BEM cache; presets.hydrodynamics_from)."""
    ranges = load_ranges() if ranges is None else ranges
    fixed = dict(fixed or {})
    hull_ss, sensor_ss, ctrl_ss = np.random.SeedSequence(seed).spawn(3)
    rng = np.random.default_rng(hull_ss)
    draw: dict[str, Any] = {}
    for key in sorted(RANGE_KEYS):  # fixed order: one draw per key whether used or not
        if key == "sensor_quality":
            options = ranges.get(key, ["realistic"])
            pick = options[int(rng.integers(len(options)))]
        else:
            lo, hi = ranges.get(key, [math.nan, math.nan])
            pick = float(rng.uniform(lo, hi)) if math.isfinite(lo) else None
        draw[key] = fixed.get(key, pick)
    preset_data, base = _preset_base(preset, hydrodynamics)
    hull, motor, spring = base.hull, base.motor, base.spring
    if draw["lambda_ratio"] is not None:
        hull = dataclasses.replace(hull, lambda66=draw["lambda_ratio"] * hull.J_hull)
    if draw["drag_coefficient"] is not None:
        # b2 scales with Cd: rescale the preset's (which is for its own Cd).
        cd0 = (preset_data.get("hull", {}).get("damping") or {}).get("drag_coefficient", 2.0)
        hull = dataclasses.replace(hull, b2=hull.b2 * draw["drag_coefficient"] / cd0)
    if draw["b1"] is not None:
        hull = dataclasses.replace(hull, b1=draw["b1"])
    if draw["J_flywheel"] is not None:
        motor = dataclasses.replace(motor, J_flywheel=draw["J_flywheel"])
    if draw["k_t"] is not None:
        # the drawn k_t is the torque per ampere at the flywheel: a geared motor's own constant is k_t / ratio
        motor = dataclasses.replace(motor, k_t=draw["k_t"] / base.drive.gear_ratio)
    if draw["period_s"] is not None:
        spring = dataclasses.replace(spring, c=(hull.J_hull + hull.lambda66) * (2 * math.pi / draw["period_s"]) ** 2)
    quality = draw["sensor_quality"] or "realistic"
    rig = RigParams(hull=hull, spring=spring, motor=motor, sensors=sensors_for_quality(quality, base.sensors),
                    effects=effects if effects is not None else base.effects, brake_torque=base.brake_torque,
                    physics_substeps=base.physics_substeps, hydrodynamics=base.hydrodynamics, drive=base.drive)
    plan = plan_from_preset(preset_data, alpha=draw["alpha"], hold_s=draw["hold_s"])
    return Scenario(name=name or f"{preset}/{seed}", seed=seed, rig=rig, plan=plan, sensor_seed=sensor_ss,
                    controller_seed=ctrl_ss, sensor_quality=quality)
