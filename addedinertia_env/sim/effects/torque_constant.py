"""``torque_constant``: the motor's true torque constant differs from its data sheet."""

from __future__ import annotations

from dataclasses import dataclass

from addedinertia_env.sim.effects.registry import EffectSpec, FitRange, Param, register


@dataclass(frozen=True)
class TorqueConstant:
    """Parameters of ``torque_constant``: ``ratio`` (dimensionless), the true ``k_t`` over the data sheet's."""

    ratio: float  # -, true k_t / data-sheet k_t


def torque_ratio(e):
    """True / data-sheet torque constant; -."""
    return e.ratio


def draw(rng):
    """``1 +- size`` with the size in the realistic range and either sign."""
    size = float(rng.uniform(*SPEC.param("ratio").realistic))
    return {"ratio": 1.0 + float(rng.choice([-1.0, 1.0])) * size}


SPEC = register(EffectSpec(
    name="torque_constant",
    summary="the motor's true torque constant differs from its data sheet",
    params_type=TorqueConstant,
    params=(Param("ratio", "-", "true / data-sheet k_t; realistic range of |ratio - 1|", realistic=(0.03, 0.08),
                  neutral=1.0, fit=FitRange(1.0, 0.5, 1.5, 0.01)),),
    size_param="ratio",
    min_size=0.015,  # three times the current sensor's gain error
    draw=draw,
    torque_ratio=torque_ratio,
))
