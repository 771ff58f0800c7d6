"""``fluid_memory``: the water around the hull takes up part of its rotation and keeps it
(a first-order water state, physics.md section 6). The hull's damping acts on its rate
relative to the water's rate ``r``; the state is carried by both engines and by discovery."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from addedinertia_env.sim.effects.registry import EffectSpec, FitRange, Param, register


@dataclass(frozen=True)
class FluidMemory:
    """Parameters of ``fluid_memory``: ``tau`` (s), the water's time constant, and ``beta`` (dimensionless), the fraction of the hull's rate the water takes up."""

    tau: float  # s, time constant of the water's rotation
    beta: float  # -, fraction of the hull rate the water takes up


def water_rate_derivative(e, w, r):
    """d(water rate)/dt for hull rate ``w`` and water rate ``r`` (rad/s); rad/s^2."""
    return (e.beta * w - r) / e.tau


def water_rate_after_rest(e, r, seconds):
    """The water rate (rad/s) after ``seconds`` with the hull held still (the brake hold)."""
    return r * np.exp(-seconds / e.tau)


SPEC = register(EffectSpec(
    name="fluid_memory",
    summary="the water keeps part of the hull's rotation (first-order memory)",
    params_type=FluidMemory,
    params=(Param("tau", "s", "time constant of the water's rotation", realistic=(5.0, 30.0), neutral=1.0,
                  fit=FitRange(10.0, 0.3, 300.0, 1.0)),
            Param("beta", "-", "fraction of the hull rate the water takes up", realistic=(0.1, 0.3), neutral=0.0,
                  fit=FitRange(0.15, 0.0, 0.95, 0.05))),
    size_param="beta",
    min_size=0.03,
    water_rate_derivative=water_rate_derivative,
    water_rate_after_rest=water_rate_after_rest,
))
