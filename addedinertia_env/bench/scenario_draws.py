"""What a suite adds to a scenario beyond configs/randomization.yaml: hidden effects, the
control loop, motor overrides. Each is drawn per scenario seed from its own random stream,
so adding or changing one never shifts the others' numbers (or standard-v0's scenarios).

Suite keys (all optional; a value is a number, or ``[low, high]`` drawn uniformly)::

    effects:                 # hidden effects (run-record.md vocabulary), each with probability p
      bearing_coulomb: {p: 1.0, torque: [0.05, 0.12]}      # N m
      torque_constant: {p: 1.0, ratio: [0.85, 1.15]}       # true k_t / data-sheet k_t
    loop:                    # addedinertia_env/loop/control_loop.py
      obs_delay_s: [0.004, 0.010]    # s
      command_period_s: 0.01         # s (100 Hz set-points, zero-order hold)
      current_step_A: 0.1            # A
    motor:                   # MotorParams fields replaced (known to the controller: the rig block)
      i_max: [3.0, 5.0]              # A
    link:                    # the loop's round trip stated to the controllers (needs loop.obs_delay_s)
      stated: measured               # exact: the drawn obs_delay_s; measured: plus a lab's ping error
      error_s: 0.001                 # s, that error's bound: uniform in [-error_s, +error_s], drawn per seed

The stated round trip reaches a controller as ``ControllerContext.link_round_trip_s``; without a
``link:`` block no round trip is stated (the suites before drive-v3).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.loop.control_loop import ControlLoop
from addedinertia_env.sim.effects import EFFECT_NAMES, Effects
from addedinertia_env.sim.params import MotorParams
from addedinertia_env.sim.presets import ConfigError
from addedinertia_env.experiment.scenarios import Scenario
from addedinertia_env.bench.drive_draws import apply_drive, validate_drive

LOOP_KEYS = tuple(f.name for f in dataclasses.fields(ControlLoop) if f.name != "stated_round_trip_s")  # that one: ``link:``
LINK_STATED = ("exact", "measured")
LINK_MAX_ERROR_S = 0.005  # s: a loopback ping that is off by more than this is no statement of the round trip
MOTOR_KEYS = tuple(f.name for f in dataclasses.fields(MotorParams))
# Spawn keys of the streams (the scenario's own streams are SeedSequence(seed).spawn(3): 0, 1, 2).
_STREAM = {"effects": 100, "loop": 101, "motor": 102, "link": 103}


def _is_value(v: Any) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return math.isfinite(v)
    return (isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                          and math.isfinite(x) for x in v) and v[0] <= v[1])


def _bad(path: Path, where: str, value: Any, expected: str) -> ConfigError:
    return ConfigError(f"{path}: {where} = {value!r}; expected {expected}")


def validate_extras(data: dict[str, Any], path: Path) -> dict[str, Any]:
    """The suite's ``effects``, ``loop`` and ``motor`` blocks, checked (one-line errors)."""
    out: dict[str, Any] = {"effects": {}, "loop": {}, "motor": {}}
    effects = data.get("effects") or {}
    if not isinstance(effects, dict):
        raise _bad(path, "effects", effects, "a mapping of effect name to {p: probability, field: value}")
    for name, spec in effects.items():
        if name not in EFFECT_NAMES:
            raise _bad(path, "effects", name, f"an effect name, one of {', '.join(EFFECT_NAMES)}")
        if not isinstance(spec, dict):
            raise _bad(path, f"effects.{name}", spec, "{p: probability, field: number or [low, high]}")
        p = spec.get("p", 1.0)
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0 <= p <= 1:
            raise _bad(path, f"effects.{name}.p", p, "a probability in [0, 1]")
        fields = {k: v for k, v in spec.items() if k != "p"}
        for k, v in fields.items():
            if not _is_value(v):
                raise _bad(path, f"effects.{name}.{k}", v, "a number or [low, high] with low <= high")
        try:  # the field names must be the effect's own
            Effects.from_dict({name: {k: (v[0] if isinstance(v, list) else v) for k, v in fields.items()}},
                              where=f"{path}: effects")
        except ValueError as e:
            raise ConfigError(str(e)) from None
        out["effects"][name] = {"p": float(p), **fields}
    for block, keys in (("loop", LOOP_KEYS), ("motor", MOTOR_KEYS)):
        spec = data.get(block) or {}
        if not isinstance(spec, dict):
            raise _bad(path, block, spec, f"a mapping with keys among {list(keys)}")
        for k, v in spec.items():
            if k not in keys:
                raise _bad(path, f"{block}.{k}", v, f"keys among {list(keys)}")
            if not _is_value(v) or (isinstance(v, (int, float)) and v < 0) or (isinstance(v, list) and v[0] < 0):
                raise _bad(path, f"{block}.{k}", v, "a number >= 0 or [low, high] with 0 <= low <= high")
        out[block] = dict(spec)
    out["drive"] = validate_drive(data.get("drive"), path)  # the drive's flaws, with units (drive_draws.py)
    out["link"] = validate_link(data.get("link"), out["loop"], path)
    return out


def validate_link(spec: Any, loop: dict[str, Any], path: Path) -> dict[str, Any]:
    """The suite's ``link:`` block, checked: ``stated`` (``exact`` or ``measured``) and, for ``measured``,
    ``error_s`` (s, in (0, LINK_MAX_ERROR_S]); it needs a drawn ``loop.obs_delay_s`` to state. {} when absent."""
    if spec is None:
        return {}
    if not isinstance(spec, dict):
        raise _bad(path, "link", spec, "a mapping {stated: exact | measured, error_s: s}")
    for k, v in spec.items():
        if k not in ("stated", "error_s"):
            raise _bad(path, f"link.{k}", v, "keys among ['stated', 'error_s']")
    stated = spec.get("stated")
    if stated not in LINK_STATED:
        raise _bad(path, "link.stated", stated, f"one of {list(LINK_STATED)} (how the round trip is stated)")
    if "obs_delay_s" not in loop:
        raise _bad(path, "link", spec, "a suite whose loop draws obs_delay_s (the round trip to state)")
    if stated == "exact":
        if "error_s" in spec:
            raise _bad(path, "link.error_s", spec["error_s"], "no error_s with stated: exact")
        return {"stated": "exact", "error_s": 0.0}
    e = spec.get("error_s")
    if isinstance(e, bool) or not isinstance(e, (int, float)) or not math.isfinite(e) or not 0 < e <= LINK_MAX_ERROR_S:
        raise _bad(path, "link.error_s", e, f"a number of seconds in (0, {LINK_MAX_ERROR_S}] (the ping's error bound)")
    return {"stated": "measured", "error_s": float(e)}


def _rng(seed: int, stream: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=(_STREAM[stream],)))


def _draw(v: Any, rng: np.random.Generator) -> float:
    return float(rng.uniform(v[0], v[1])) if isinstance(v, list) else float(v)


def apply_extras(scenario: Scenario, extras: dict[str, Any]) -> Scenario:
    """``scenario`` with the suite's effects, loop and motor overrides drawn for its seed."""
    seed = scenario.seed
    rig = scenario.rig
    if extras.get("effects"):
        rng = _rng(seed, "effects")
        chosen: dict[str, dict[str, float]] = {}
        for name in EFFECT_NAMES:  # fixed order: every listed effect draws whether on or off
            spec = extras["effects"].get(name)
            if spec is None:
                continue
            on = rng.uniform() < spec["p"]
            values = {k: _draw(v, rng) for k, v in sorted(spec.items()) if k != "p"}
            if on:
                chosen[name] = values
        merged = {**rig.effects.to_dict(), **chosen}
        rig = rig.replace(effects=Effects.from_dict(merged))
    if extras.get("motor"):
        rng = _rng(seed, "motor")
        rig = rig.replace(motor=dataclasses.replace(
            rig.motor, **{k: _draw(v, rng) for k, v in sorted(extras["motor"].items())}))
    loop = scenario.loop
    if extras.get("loop"):
        rng = _rng(seed, "loop")
        loop = ControlLoop(**{k: _draw(v, rng) for k, v in sorted(extras["loop"].items())})
    if extras.get("link") and loop is not None:  # the round trip stated to the controllers (its own stream)
        error = _rng(seed, "link").uniform(-1.0, 1.0) * extras["link"]["error_s"]
        loop = dataclasses.replace(loop, stated_round_trip_s=max(0.0, loop.obs_delay_s + float(error)))
    out = dataclasses.replace(scenario, rig=rig, loop=loop)
    return apply_drive(out, extras["drive"]) if extras.get("drive") else out
