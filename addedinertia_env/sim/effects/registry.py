"""The registry of hidden effects: one :class:`EffectSpec` per effect, looked up by name.

An effect's file declares, in one place (see ``bearing_coulomb.py`` for the pattern):

* its name (the run-record vocabulary), a one-line summary and a frozen dataclass of its
  parameters;
* each parameter (:class:`Param`): unit, meaning, the realistic range a scenario draws
  from, the value at which the effect does nothing, and its discovery fit range;
* its physics, as *hooks* (below). Each hook works on floats and on numpy arrays alike,
  so the one function serves the scalar MuJoCo engine, the batched engine (per-environment
  arrays) and the discovery model (one row per parameter set);
* its discovery candidate: the parameter that measures its size and the smallest size
  that discovery calls an effect.

Everything else reads the registry: :mod:`..forces` (both engines), the batched parameter
arrays, the scenario draws (:func:`~.set.draw_effect`), presets (:meth:`~.set.Effects.from_dict`)
and discovery (``discover/model.py``, ``discover/diagnose.py``). Adding an effect is one
new file plus one line in ``effects/__init__.py`` (docs/ARCHITECTURE.md).

Hooks (``e`` is the effect's parameter object, ``p`` the rig's parameters):

==========================  =============================================  ========
hook                        meaning                                        returns
==========================  =============================================  ========
``hull_torque(e, phi, w, p)``  extra torque on the hull (phi rad, w rad/s)    N m
``spring_energy(e, d, p)``     extra rod energy at twist d = phi - neutral    J
``neutral_shift(e)``           true minus calibrated neutral angle            rad
``torque_ratio(e)``            true / data-sheet torque constant              -
``channel_delay(e)``           lag of the current and voltage channel         s
``water_rate_derivative(e, w, r)``  d(water rate)/dt, r the water's rate      rad/s^2
``water_rate_after_rest(e, r, s)``  water rate after s seconds, hull at rest  rad/s
==========================  =============================================  ========
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

HOOKS = ("hull_torque", "spring_energy", "neutral_shift", "torque_ratio", "channel_delay",
         "water_rate_derivative", "water_rate_after_rest")
# Parameter names of the nominal discovery model; an effect's parameters must differ.
NOMINAL_PARAM_NAMES = ("lambda66", "b1", "b2")


@dataclass(frozen=True)
class FitRange:
    """How discovery fits a parameter: start value, bounds, typical size (same unit)."""

    start: float
    low: float
    high: float
    scale: float  # typical size, for the optimiser's scaling and finite differences


@dataclass(frozen=True)
class Param:
    """One parameter of an effect."""

    name: str
    unit: str
    meaning: str
    realistic: tuple[float, float]  # (low, high) drawn uniformly for scenarios and tests
    neutral: float  # the value at which the effect does nothing
    fit: FitRange  # discovery's start and bounds


@dataclass(frozen=True)
class EffectSpec:
    """Everything about one effect; see the module docstring for the hooks."""

    name: str
    summary: str
    params_type: type  # frozen dataclass with one field per :class:`Param`, same order
    params: tuple[Param, ...]
    size_param: str  # the parameter whose departure from neutral measures the effect
    min_size: float  # smallest |size - neutral| discovery names as an effect (clear of known imperfections)
    draw: Callable[[np.random.Generator], dict[str, float]] | None = None  # default: uniform in ``realistic``
    hull_torque: Callable | None = None
    spring_energy: Callable | None = None
    neutral_shift: Callable | None = None
    torque_ratio: Callable | None = None
    channel_delay: Callable | None = None
    water_rate_derivative: Callable | None = None
    water_rate_after_rest: Callable | None = None

    def param(self, name: str) -> Param:
        """The parameter called ``name``."""
        return next(p for p in self.params if p.name == name)

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the parameters, in order."""
        return tuple(p.name for p in self.params)

    def draw_values(self, rng: np.random.Generator) -> dict[str, float]:
        """Parameter values at a realistic size drawn from ``rng``."""
        if self.draw is not None:
            return self.draw(rng)
        return {p.name: float(rng.uniform(*p.realistic)) for p in self.params}

    def neutral_values(self) -> dict[str, float]:
        """Parameter values at which the effect does nothing."""
        return {p.name: p.neutral for p in self.params}


_REGISTRY: dict[str, EffectSpec] = {}


def register(spec: EffectSpec) -> EffectSpec:
    """Add ``spec`` under its name after checking that it is complete; returns it."""
    where = f"effect {spec.name!r}"
    if not spec.name.isidentifier() or spec.name in ("none", "unexplained"):
        raise ValueError(f"{where}: the name must be a Python identifier other than 'none' and 'unexplained'")
    if spec.name in _REGISTRY and _REGISTRY[spec.name] is not spec:
        raise ValueError(f"{where} is already registered")
    fields = tuple(f.name for f in dataclasses.fields(spec.params_type))
    if fields != spec.param_names:
        raise ValueError(f"{where}: params_type fields {fields} differ from the declared parameters {spec.param_names}")
    taken = {n for s in _REGISTRY.values() if s.name != spec.name for n in s.param_names} | set(NOMINAL_PARAM_NAMES)
    clash = sorted(set(spec.param_names) & taken)
    if clash:
        raise ValueError(f"{where}: parameter name(s) {clash} already used; discovery needs unique names")
    if spec.size_param not in spec.param_names:
        raise ValueError(f"{where}: size_param {spec.size_param!r} is not one of {spec.param_names}")
    if not any(getattr(spec, h) is not None for h in HOOKS):
        raise ValueError(f"{where}: no physics hook; expected at least one of {HOOKS}")
    _REGISTRY[spec.name] = spec
    return spec


def unregister(name: str) -> None:
    """Remove an effect (tests that register a toy effect clean up with this)."""
    _REGISTRY.pop(name, None)


def get(name: str) -> EffectSpec:
    """The spec of effect ``name``; ``ValueError`` naming the known effects otherwise."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; expected one of {', '.join(_REGISTRY)}") from None


def specs() -> tuple[EffectSpec, ...]:
    """Every registered effect, in registration order."""
    return tuple(_REGISTRY.values())


def effect_names() -> tuple[str, ...]:
    """Names of every registered effect, in registration order."""
    return tuple(_REGISTRY)


def with_hook(hook: str) -> tuple[EffectSpec, ...]:
    """The registered effects that define ``hook``."""
    return tuple(s for s in _REGISTRY.values() if getattr(s, hook) is not None)


def active_params(effects: Any, hook: str) -> tuple[tuple[EffectSpec, Any], ...]:
    """(spec, parameters) of each effect that defines ``hook`` and is on in ``effects``.

    ``effects`` is an :class:`~.effect_set.Effects` or any namespace with one attribute per
    effect (``None`` or missing: off), such as the batched arrays or discovery's parameter
    rows. The physics calls this every step, so the answer is read from the table that
    :func:`hook_table` made when there is one."""
    table = getattr(effects, "_hooked", None)
    if table is not None:
        return table[hook]
    return hook_table(effects)[hook]


def hook_table(effects: Any) -> dict[str, tuple[tuple[EffectSpec, Any], ...]]:
    """For every hook, (spec, parameters) of the effects in ``effects`` that are on and define it."""
    on = [(spec, getattr(effects, spec.name, None)) for spec in _REGISTRY.values()]
    return {hook: tuple((spec, e) for spec, e in on if e is not None and getattr(spec, hook) is not None)
            for hook in HOOKS}
