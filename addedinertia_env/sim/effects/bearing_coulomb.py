"""``bearing_coulomb``: dry friction in the hull's shaft bearing (physics.md section 8)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from addedinertia_env.sim.friction import DRY_FRICTION_RATE_SCALE
from addedinertia_env.sim.effects.registry import EffectSpec, FitRange, Param, register


@dataclass(frozen=True)
class BearingCoulomb:
    """Parameters of ``bearing_coulomb``: ``torque`` (N m), the dry friction opposing the hull's rotation."""

    torque: float  # N m, dry friction in the hull's shaft bearing


def hull_torque(e, d, w, p):
    """Dry friction opposing the hull rate ``w`` (rad/s), smoothed near rest; N m."""
    return -e.torque * np.tanh(w / DRY_FRICTION_RATE_SCALE)


SPEC = register(EffectSpec(
    name="bearing_coulomb",
    summary="dry friction in the hull's shaft bearing",
    params_type=BearingCoulomb,
    params=(Param("torque", "N m", "friction torque", realistic=(0.03, 0.10), neutral=0.0,
                  fit=FitRange(0.02, 0.0, 2.0, 0.01)),),
    size_param="torque",
    min_size=0.01,  # N m: a third of the smallest realistic 0.03; 0.5 % of the spring torque at 0.05 rad
    hull_torque=hull_torque,
))
