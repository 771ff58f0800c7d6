"""Optional effects of the simulated truth that the nominal model lacks.

The names are the vocabulary of ``run-record.md`` (physics.md section 8). All are off
by default. They exist so that tests can hide one in the data and require a diagnosis
to find it; no estimator, controller or diagnosis may read them.

Magnitude ranges used by :func:`draw_effect` are "realistic" in the sense of physics.md:
big enough to bias lambda66 or leave a fingerprint above the sensor noise of the default
rig, small enough to be plausible on a real bench.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

EFFECT_NAMES = (
    "bearing_coulomb",
    "fluid_memory",
    "spring_stiffening",
    "neutral_offset",
    "sensor_delay",
    "torque_constant",
)
DIAGNOSIS_WORDS = ("none",) + EFFECT_NAMES + ("unexplained",)


@dataclass(frozen=True)
class BearingCoulomb:
    torque: float  # N m, dry friction in the hull's shaft bearing


@dataclass(frozen=True)
class FluidMemory:
    tau: float  # s, time constant of the water's rotation
    beta: float  # -, fraction of the hull rate the water takes up


@dataclass(frozen=True)
class SpringStiffening:
    k3: float  # 1/rad^2, torque = -c (d + k3 d^3), d = phi - phi_neutral


@dataclass(frozen=True)
class NeutralOffset:
    offset: float  # rad, true neutral minus calibrated neutral


@dataclass(frozen=True)
class SensorDelay:
    delay: float  # s, lag of the current and voltage channel behind the encoders


@dataclass(frozen=True)
class TorqueConstant:
    ratio: float  # -, true k_t / data-sheet k_t


_TYPES = {
    "bearing_coulomb": BearingCoulomb,
    "fluid_memory": FluidMemory,
    "spring_stiffening": SpringStiffening,
    "neutral_offset": NeutralOffset,
    "sensor_delay": SensorDelay,
    "torque_constant": TorqueConstant,
}

# (low, high) per field, for seeded random draws in tests and scenarios.
REALISTIC_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "bearing_coulomb": {"torque": (0.03, 0.10)},
    "fluid_memory": {"tau": (5.0, 30.0), "beta": (0.1, 0.3)},
    "spring_stiffening": {"k3": (3.0, 10.0)},
    "neutral_offset": {"offset": (0.004, 0.015)},
    "sensor_delay": {"delay": (0.004, 0.012)},
    "torque_constant": {"ratio": (0.03, 0.08)},  # |ratio - 1|, sign drawn separately
}


@dataclass(frozen=True)
class Effects:
    """The set of hidden effects in a simulated rig; each is ``None`` when off."""

    bearing_coulomb: BearingCoulomb | None = None
    fluid_memory: FluidMemory | None = None
    spring_stiffening: SpringStiffening | None = None
    neutral_offset: NeutralOffset | None = None
    sensor_delay: SensorDelay | None = None
    torque_constant: TorqueConstant | None = None

    @property
    def active(self) -> tuple[str, ...]:
        return tuple(n for n in EFFECT_NAMES if getattr(self, n) is not None)

    def to_dict(self) -> dict[str, dict[str, float]]:
        return {n: asdict(getattr(self, n)) for n in self.active}

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None, where: str = "effects") -> "Effects":
        if not data:
            return cls()
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a mapping of effect name to parameters, got {data!r}")
        kwargs = {}
        for name, params in data.items():
            if name not in _TYPES:
                raise ValueError(f"{where}: unknown effect {name!r}; expected one of {', '.join(EFFECT_NAMES)}")
            typ = _TYPES[name]
            allowed = {f.name for f in fields(typ)}
            if not isinstance(params, dict) or set(params) != allowed:
                raise ValueError(f"{where}.{name}: expected keys {sorted(allowed)}, got {params!r}")
            for key, value in params.items():
                if not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise ValueError(f"{where}.{name}.{key} = {value!r}: expected a finite number")
            kwargs[name] = typ(**{k: float(v) for k, v in params.items()})
        return cls(**kwargs)


def draw_effect(name: str, rng: np.random.Generator) -> Effects:
    """One effect (or ``none``) with magnitudes drawn uniformly from :data:`REALISTIC_RANGES`."""
    if name == "none":
        return Effects()
    if name not in _TYPES:
        raise ValueError(f"unknown effect {name!r}; expected 'none' or one of {', '.join(EFFECT_NAMES)}")
    values = {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in REALISTIC_RANGES[name].items()}
    if name == "torque_constant":
        values["ratio"] = 1.0 + float(rng.choice([-1.0, 1.0])) * values["ratio"]
    if name == "neutral_offset":
        values["offset"] *= float(rng.choice([-1.0, 1.0]))
    return Effects(**{name: _TYPES[name](**values)})
