"""The stroke feed-forward: the current that makes the hull retrace the mirrored stroke,
from the recorded law and the known rig only. Shared by the classical controllers
(``agents``) and the two-rate segment planner (``experiment/two_rate.py``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from addedinertia_env.experiment.task import ControllerContext


def stroke_feedforward_current(ctx: ControllerContext, phi_ref_rel: float, accel_ref: float, J: float) -> float:
    """Current that makes the hull retrace the mirrored stroke, from the recorded law, A.

    On the free stroke ``J f'' + c (f - phi_n) = Q_w(f')`` (the damping torque). On the
    mirror the rate changes sign, so the motor must supply ``-2 Q_w``; its reaction on
    the hull is ``-k_t i``, hence ``i = -2 (J f'' + c (f - phi_n)) / k_t``.
    """
    c = ctx.rig.c_torsion
    return -2.0 * (J * accel_ref + c * phi_ref_rel) / ctx.k_t


def stroke_impulse(ctx: ControllerContext, J: float, n: int = 400) -> float:
    """Angular impulse (N m s) the feedforward puts on the flywheel over the reverse stroke."""
    law = ctx.reference.law
    s = np.linspace(law.t_start, law.t_stop, n)
    phi_n = ctx.rig.phi_neutral
    torque = -2.0 * (J * law.accel(s) + ctx.rig.c_torsion * (law.phi(s) - phi_n))
    return float(np.trapezoid(torque, s))
