"""Rig presets: validated YAML in ``configs/rigs/`` turned into :class:`RigParams`.

Unknown keys are refused by name, with the keys that are allowed; every number must be
finite and of the right sign (the dataclasses check that). ``hull.added_inertia`` and
``hull.J_hull`` may be computed from geometry (Lamb's spheroid), so that a preset never
types in a number that a closed form gives.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import Any

from addedinertia_env.foundation.config_io import CONFIG_DIR, RIG_DIR, ConfigError, check_keys, read_yaml

from addedinertia_env.hydro.geometry import shape_from_mapping
from addedinertia_env.hydro import closed_forms as hydro, radiation
from addedinertia_env.sim.drive import drive_from_block
from addedinertia_env.sim.effects import Effects
from addedinertia_env.sim.params import HullParams, MotorParams, RigParams, SensorParams, SpringParams


def available_rigs() -> list[str]:
    """Names of the rig presets in ``configs/rigs/`` (file stems), sorted."""
    return sorted(p.stem for p in RIG_DIR.glob("*.yaml"))


def config_path(kind: str, name: str, folder: Path) -> Path:
    """``name`` as a YAML path, or as the stem of a file in ``folder``; else a ConfigError."""
    p = Path(name)
    if p.suffix in (".yaml", ".yml") and p.exists():
        return p
    candidate = folder / f"{name}.yaml"
    if not candidate.exists():
        known = ", ".join(sorted(q.stem for q in folder.glob("*.yaml")))
        raise ConfigError(f"unknown {kind} {name!r}; expected one of {known} or a path to a {kind} .yaml file")
    return candidate


def rig_path(name: str) -> Path:
    """The YAML file of rig preset ``name`` (a preset name or a path); ConfigError if there is none."""
    return config_path("rig", name, RIG_DIR)


REQUIRED_BLOCKS = ("hull", "spring", "motor")  # what a rig file must state; sensors and the rest have defaults
TOP_KEYS = ("name", "hull", "spring", "motor", "sensors", "brake_torque", "physics_substeps", "effects", "experiment",
            "hydrodynamics", "extends", "drive")
HYDRO_KEYS = ("model", "source", "cache")


_PRESET_CACHE: dict[tuple[str, int], dict[str, Any]] = {}


def load_preset(name: str) -> dict[str, Any]:
    """The raw preset mapping (validated for top-level keys); a fresh copy each call, parsed
    once per file version (environments draw a scenario per episode)."""
    path = rig_path(name)
    key = (str(path.resolve()), path.stat().st_mtime_ns)
    if key not in _PRESET_CACHE:
        _PRESET_CACHE[key] = _parse_preset(path)
    data = copy.deepcopy(_PRESET_CACHE[key])
    return _extend(data, path) if "extends" in data else data


def _extend(data: dict[str, Any], path: Path) -> dict[str, Any]:
    """A preset that ``extends: BASE`` (a preset name, or a .yaml path relative to its own file):
    the base's mapping with this file's top-level blocks replacing the base's whole blocks
    (e.g. ``wigley-2m-memory``: wigley-2m with ``hydrodynamics: {model: cummins}``). One level:
    a base that extends another is refused. The base is read afresh (its own cache entry)."""
    base_name = data["extends"]
    if not isinstance(base_name, str) or not base_name:
        raise ConfigError(f"{path}: extends = {base_name!r}: expected the name of a rig preset or a .yaml path")
    if base_name.endswith((".yaml", ".yml")) and not Path(base_name).is_absolute():
        base_name = str(path.parent / base_name)
    try:
        base = load_preset(base_name)
    except ConfigError as e:
        raise ConfigError(f"{path}: extends = {data['extends']!r}: {e}") from None
    if "extends" in base:
        raise ConfigError(f"{path}: extends = {data['extends']!r}, which itself extends {base['extends']!r}; "
                          "expected a preset without 'extends' (one level)")
    merged = {**base, **data}
    _check_required(merged, path)
    return merged


def _check_required(data: dict[str, Any], path: Path) -> None:
    missing = [key for key in REQUIRED_BLOCKS if not isinstance(data.get(key), dict)]
    if missing:
        raise ConfigError(f"{path}: missing block(s) {missing}; a rig file states its {', '.join(REQUIRED_BLOCKS)} "
                          "(no silent defaults; see configs/rigs/wigley-2m.yaml)")


def _parse_preset(path: Path) -> dict[str, Any]:
    data = read_yaml(path, "rig preset")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    check_keys(data, set(TOP_KEYS), str(path))
    data["_path"] = str(path)
    if "extends" not in data:  # a preset that extends another gets the blocks it lacks from it (_extend)
        _check_required(data, path)
    return data


def load_rig(name: str, effects: Effects | None = None, sensors: SensorParams | None = None,
             hydrodynamics: str | dict | None = None) -> RigParams:
    """A :class:`RigParams` from preset ``name`` (or a YAML path); ``hydrodynamics`` overrides
    the preset's hydrodynamic model (``"constant"``, ``"cummins"`` or a mapping, :func:`hydrodynamics_from`)."""
    return rig_from_mapping(load_preset(name), effects=effects, sensors=sensors, hydrodynamics=hydrodynamics)


def rig_from_mapping(data: dict[str, Any], effects: Effects | None = None,
                     sensors: SensorParams | None = None, hydrodynamics: str | dict | None = None) -> RigParams:
    """:class:`RigParams` from a preset's parsed mapping (blocks ``hull``, ``spring``, ``motor``, ...).

    ``effects`` and ``sensors``, when given, replace the mapping's own blocks; ``hydrodynamics``
    replaces its hydrodynamic model (:func:`hydrodynamics_from`). Every value
    is in SI units. Raises ConfigError naming the file (``data['_path']``) and the field for
    an unknown key or an invalid value.
    """
    where = data.get("_path", "rig")
    check_keys(data, set(TOP_KEYS), where)
    hull_block = data.get("hull") or {}
    check_keys(hull_block, set(HULL_KEYS), f"{where}: hull")
    hull = _hull({"name": data.get("name", "custom"), **hull_block}, f"{where}: hull")
    spring = _build(SpringParams, data.get("spring") or {}, f"{where}: spring")
    motor = _build(MotorParams, data.get("motor") or {}, f"{where}: motor")
    sens = sensors or _build(SensorParams, data.get("sensors") or {}, f"{where}: sensors")
    try:
        eff = effects if effects is not None else Effects.from_dict(data.get("effects"), f"{where}: effects")
    except ValueError as e:
        raise ConfigError(str(e)) from None
    kwargs: dict[str, Any] = {}
    hydro_block = data.get("hydrodynamics") if hydrodynamics is None else hydrodynamics
    kwargs["hydrodynamics"] = hydrodynamics_from(hydro_block, data.get("_path"), data.get("name"),
                                                 f"{where}: hydrodynamics")
    for key in ("brake_torque", "physics_substeps"):
        if key in data:
            kwargs[key] = data[key]
    if data.get("drive") is not None:  # the drive's flaws, each value with its unit (sim/drive.py)
        motor_block = data.get("motor") or {}
        drive, supply = drive_from_block(data["drive"], f"{where}: drive", R=motor.R, i_max=motor.i_max)
        if supply is not None:
            if "u_max" in motor_block:
                raise ConfigError(f"{where}: both motor.u_max and drive.supply give the supply voltage; expected one")
            motor = dataclasses.replace(motor, u_max=supply)
        kwargs["drive"] = drive
    try:
        return RigParams(hull=hull, spring=spring, motor=motor, sensors=sens, effects=eff, **kwargs)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: {e}") from None


def hydrodynamics_from(block: str | dict | None, preset_path: str | None, preset_name: str | None, where: str):
    """The hydrodynamic model of a rig: None (``constant``: added inertia lambda66, the default) or a
    :class:`~.radiation.CumminsModel` (``cummins``: radiation memory from the hull's BEM cache).

    ``block``: ``None``, a model name, or ``{model: constant|cummins, source: bem-cache, cache: PATH}``;
    the cache defaults to ``<preset>.bem.json`` beside the preset file. A ConfigError names the
    field, the value and what was expected (or the cache and the command that writes its fit).
    """
    if block is None:
        return None
    if isinstance(block, str):
        block = {"model": block}
    if not isinstance(block, dict):
        raise ConfigError(f"{where} = {block!r}: expected a model name or a mapping with keys {list(HYDRO_KEYS)}")
    check_keys(block, set(HYDRO_KEYS), where)
    model = block.get("model", "constant")
    if model not in radiation.MODELS:
        raise ConfigError(f"{where}.model = {model!r}: expected one of {', '.join(radiation.MODELS)}")
    if model == "constant":
        if set(block) - {"model"}:
            raise ConfigError(f"{where}: 'source' and 'cache' apply to model 'cummins' only")
        return None
    source = block.get("source", "bem-cache")
    if source not in radiation.SOURCES:
        raise ConfigError(f"{where}.source = {source!r}: expected one of {', '.join(radiation.SOURCES)}")
    if "cache" in block:
        cache = Path(str(block["cache"]))
        if not cache.is_absolute() and preset_path:
            cache = Path(preset_path).parent / cache
    elif preset_path:
        cache = Path(preset_path).with_name(Path(preset_path).stem + ".bem.json")
    elif preset_name:
        cache = RIG_DIR / f"{preset_name}.bem.json"
    else:
        raise ConfigError(f"{where}: model 'cummins' needs the hull's BEM cache: give 'cache: PATH.bem.json'")
    try:
        return radiation.model_from_cache(cache)
    except radiation.HydrodynamicsError as e:
        raise ConfigError(f"{where}: {e}") from None


HULL_KEYS = ("J_hull", "added_inertia", "lambda66", "b1", "b2", "damping", "name", "geometry")


def _hull(d: dict[str, Any], where: str) -> HullParams:
    check_keys(d, set(HULL_KEYS), where)
    out: dict[str, Any] = {}
    if "geometry" in d:  # the analytic hull shape, for `addedinertia hull` (addedinertia_env/hydro)
        shape_from_mapping(d["geometry"], f"{where}.geometry")
    if "name" in d:
        out["name"] = str(d["name"])
    J = d.get("J_hull", HullParams.J_hull)
    if isinstance(J, dict):
        check_keys(J, {"model", "length", "beam", "extra"}, f"{where}.J_hull")
        if J.get("model") != "floating-spheroid":
            raise ConfigError(f"{where}.J_hull.model = {J.get('model')!r}: expected 'floating-spheroid' or a number")
        a, b = 0.5 * _num(J, "length", f"{where}.J_hull"), 0.5 * _num(J, "beam", f"{where}.J_hull")
        extra = J.get("extra", 0.0)
        if isinstance(extra, bool) or not isinstance(extra, (int, float)) or not math.isfinite(extra) or extra < 0:
            raise ConfigError(f"{where}.J_hull.extra = {extra!r}: expected a finite number >= 0 (kg m^2)")
        J = hydro.spheroid_displaced_yaw_inertia(a, b, immersed_fraction=0.5) + float(extra)
    out["J_hull"] = J
    if "lambda66" in d and "added_inertia" in d:
        raise ConfigError(f"{where}: give either 'lambda66' or 'added_inertia', not both")
    if "added_inertia" in d:
        ai = d["added_inertia"]
        if not isinstance(ai, dict):
            raise ConfigError(f"{where}.added_inertia = {ai!r}: expected a mapping with 'model'")
        model = ai.get("model")
        if model == "given":
            check_keys(ai, {"model", "value", "source"}, f"{where}.added_inertia")
            out["lambda66"] = _num(ai, "value", f"{where}.added_inertia")
        elif model == "lamb-spheroid":
            check_keys(ai, {"model", "length", "beam", "immersion", "source"}, f"{where}.added_inertia")
            immersion = ai.get("immersion", "half")
            if immersion not in ("half", "full"):
                raise ConfigError(f"{where}.added_inertia.immersion = {immersion!r}: expected 'half' or 'full'")
            out["lambda66"] = hydro.spheroid_added_yaw_inertia(
                _num(ai, "length", f"{where}.added_inertia"), _num(ai, "beam", f"{where}.added_inertia"), immersion)
        else:
            raise ConfigError(f"{where}.added_inertia.model = {model!r}: expected 'given' or 'lamb-spheroid'")
    elif "lambda66" in d:
        out["lambda66"] = d["lambda66"]
    if "b1" in d:
        out["b1"] = d["b1"]
    if "b2" in d and "damping" in d:
        raise ConfigError(f"{where}: give either 'b2' or 'damping', not both")
    if "damping" in d:
        dm = d["damping"]
        check_keys(dm, {"model", "length", "draft", "drag_coefficient"}, f"{where}.damping")
        if dm.get("model") != "cross-flow":
            raise ConfigError(f"{where}.damping.model = {dm.get('model')!r}: expected 'cross-flow'")
        out["b2"] = hydro.quadratic_yaw_damping(_num(dm, "length", f"{where}.damping"),
                                                _num(dm, "draft", f"{where}.damping"),
                                                _num(dm, "drag_coefficient", f"{where}.damping"))
    elif "b2" in d:
        out["b2"] = d["b2"]
    return _build(HullParams, out, where)


def _build(cls, d: dict[str, Any], where: str):
    allowed = {f.name for f in dataclasses.fields(cls)}
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: expected a mapping of {sorted(allowed)}")
    check_keys(d, allowed, where)
    for key, value in d.items():
        if key != "name" and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ConfigError(f"{where}.{key} = {value!r}: expected a number (SI units)")
    try:
        return cls(**d)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: {e}") from None


def _num(d: dict[str, Any], key: str, where: str) -> float:
    if key not in d:
        raise ConfigError(f"{where}: missing key {key!r}; expected a number > 0 (SI units)")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise ConfigError(f"{where}.{key} = {v!r}: expected a finite number > 0")
    return float(v)


SENSOR_QUALITY = ("ideal", "good", "realistic", "poor")


def sensors_for_quality(quality: str, base: SensorParams | None = None) -> SensorParams:
    """Sensor sets used by scenarios: ``realistic`` is physics.md section 7."""
    base = base or SensorParams()
    if quality == "ideal":
        return SensorParams.ideal(base.sample_rate)
    if quality == "good":
        return dataclasses.replace(base, phi_counts=2**20, psi_counts=2**16, current_noise=0.003,
                                   current_offset=0.001, current_gain_error=0.002)
    if quality == "realistic":
        return base
    if quality == "poor":
        return dataclasses.replace(base, phi_counts=2**16, psi_counts=4096, current_noise=0.03,
                                   current_offset=0.01, current_gain_error=0.01)
    raise ConfigError(f"sensor quality {quality!r}: expected one of {', '.join(SENSOR_QUALITY)}")
