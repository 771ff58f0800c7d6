"""The set of hidden effects in one simulated rig, and the seeded draw of one effect."""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

import numpy as np

from addedinertia_env.sim.effects import registry


class Effects:
    """Which registered effects are on in a simulated rig, with their parameters.

    ``Effects(bearing_coulomb=BearingCoulomb(0.05))``; an effect not given is off, and
    reads as ``None`` (``effects.fluid_memory is None``). Immutable and hashable, like the
    frozen :class:`~addedinertia_env.sim.params.RigParams` that holds it.
    """

    __slots__ = ("_on", "_hooked")

    def __init__(self, **on: Any):
        for name, value in on.items():
            spec = registry.get(name)
            if value is not None and not isinstance(value, spec.params_type):
                raise TypeError(f"Effects({name}=...): expected {spec.params_type.__name__} or None, "
                                f"got {type(value).__name__}")
        order = registry.effect_names()
        items = tuple((n, on[n]) for n in order if on.get(n) is not None)
        object.__setattr__(self, "_on", items)
        object.__setattr__(self, "_hooked", registry.hook_table(self))

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        for n, value in self._on:
            if n == name:
                return value
        if name in registry.effect_names():
            return None
        raise AttributeError(f"Effects has no effect {name!r}; registered: {', '.join(registry.effect_names())}")

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("Effects is immutable")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Effects) and self._on == other._on

    def __hash__(self) -> int:
        return hash(self._on)

    def __repr__(self) -> str:
        return f"Effects({', '.join(f'{n}={v!r}' for n, v in self._on)})"

    def __reduce__(self):
        return (_rebuild, (dict(self._on),))

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the effects that are on, in registry order."""
        return tuple(n for n, _ in self._on)

    def to_dict(self) -> dict[str, dict[str, float]]:
        """``{name: {parameter: value}}`` of the effects that are on (the record's ``truth.effects``)."""
        return {n: asdict(v) for n, v in self._on}

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None, where: str = "effects") -> "Effects":
        """From ``{name: {parameter: value}}`` (a preset's ``effects``); ``ValueError`` naming ``where``."""
        if not data:
            return cls()
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a mapping of effect name to parameters, got {data!r}")
        kwargs = {}
        for name, params in data.items():
            if name not in registry.effect_names():
                raise ValueError(f"{where}: unknown effect {name!r}; expected one of "
                                 f"{', '.join(registry.effect_names())}")
            spec = registry.get(name)
            allowed = set(spec.param_names)
            if not isinstance(params, dict) or set(params) != allowed:
                raise ValueError(f"{where}.{name}: expected keys {sorted(allowed)}, got {params!r}")
            for key, value in params.items():
                if not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise ValueError(f"{where}.{name}.{key} = {value!r}: expected a finite number")
            kwargs[name] = spec.params_type(**{k: float(v) for k, v in params.items()})
        return cls(**kwargs)


def _rebuild(on: dict[str, Any]) -> Effects:
    return Effects(**on)


def draw_effect(name: str, rng: np.random.Generator) -> Effects:
    """One effect (or ``none``) at a realistic size drawn from ``rng`` (each effect's ``draw``)."""
    if name == "none":
        return Effects()
    if name not in registry.effect_names():
        raise ValueError(f"unknown effect {name!r}; expected 'none' or one of {', '.join(registry.effect_names())}")
    spec = registry.get(name)
    return Effects(**{name: spec.params_type(**spec.draw_values(rng))})
