"""Optional effects of the simulated truth that the nominal model lacks: one file per effect.

The names are the vocabulary of ``run-record.md`` (physics.md section 8). All are off by
default. They exist so that tests can hide one in the data and require a diagnosis to
find it; no estimator, controller or diagnosis may read them.

Each effect is one module here that declares its parameters (units, realistic ranges,
neutral values), its physics hooks and its discovery candidate, and registers itself
(:mod:`.registry`). Magnitude ranges are "realistic" in the sense of physics.md: big
enough to bias lambda66 or leave a fingerprint above the sensor noise of the default rig,
small enough to be plausible on a real bench.

To add an effect: write ``effects/<name>.py`` after the pattern of ``bearing_coulomb.py``
and import it below (docs/ARCHITECTURE.md, "How to add an effect").
"""

from __future__ import annotations

# Registration order is the vocabulary's order (run-record.md); keep it when adding one.
from addedinertia_env.sim.effects.bearing_coulomb import BearingCoulomb  # noqa: I001 - order matters
from addedinertia_env.sim.effects.fluid_memory import FluidMemory
from addedinertia_env.sim.effects.spring_stiffening import SpringStiffening
from addedinertia_env.sim.effects.neutral_offset import NeutralOffset
from addedinertia_env.sim.effects.sensor_delay import SensorDelay
from addedinertia_env.sim.effects.torque_constant import TorqueConstant
from addedinertia_env.sim.effects.effect_set import Effects, draw_effect
from addedinertia_env.sim.effects.registry import (
    EffectSpec,
    FitRange,
    Param,
    effect_names,
    get,
    register,
    specs,
    unregister,
)

# The vocabulary of run-record.md: the effects shipped with the package (a test may register more).
EFFECT_NAMES = effect_names()
DIAGNOSIS_WORDS = ("none",) + EFFECT_NAMES + ("unexplained",)

__all__ = ["BearingCoulomb", "DIAGNOSIS_WORDS", "EFFECT_NAMES", "EffectSpec", "Effects", "FitRange", "FluidMemory",
           "NeutralOffset", "Param", "SensorDelay", "SpringStiffening", "TorqueConstant", "draw_effect",
           "effect_names", "get", "register", "specs", "unregister"]
