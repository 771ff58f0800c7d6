"""``neutral_offset``: the rod's true neutral differs from the calibrated one."""

from __future__ import annotations

from dataclasses import dataclass

from addedinertia_env.sim.effects.registry import EffectSpec, FitRange, Param, register


@dataclass(frozen=True)
class NeutralOffset:
    """Parameters of ``neutral_offset``: ``offset`` (rad), the rod's true neutral minus the calibrated one."""

    offset: float  # rad, true neutral minus calibrated neutral


def neutral_shift(e):
    """True minus calibrated neutral angle; rad."""
    return e.offset


def draw(rng):
    """A size in the realistic range, either sign."""
    size = float(rng.uniform(*SPEC.param("offset").realistic))
    return {"offset": size * float(rng.choice([-1.0, 1.0]))}


SPEC = register(EffectSpec(
    name="neutral_offset",
    summary="the rod's true neutral angle differs from its calibration",
    params_type=NeutralOffset,
    params=(Param("offset", "rad", "true minus calibrated neutral; realistic range of |offset|",
                  realistic=(0.004, 0.015), neutral=0.0, fit=FitRange(0.0, -0.2, 0.2, 1e-3)),),
    size_param="offset",
    min_size=1.0e-3,  # rad
    draw=draw,
    neutral_shift=neutral_shift,
))
