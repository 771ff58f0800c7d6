"""Feedforward from the recorded law + PD feedback, with flywheel pre-spin: the default.

Tuning procedure (documented in docs/CONTROLLERS.md): the loop is placed at
``omega_c`` rad/s with damping ``zeta``: ``Kp = omega_c^2``, ``Kd = 2 zeta omega_c``,
scaled by the prior inertia. ``omega_c`` is limited by encoder quantisation noise fed
through ``Kd`` (physics.md section 7); 10 rad/s keeps the chatter under about 1 A.
"""

from __future__ import annotations

import numpy as np

from .base import Controller, ControllerContext, stroke_feedforward_current, stroke_impulse


class FeedforwardPD(Controller):
    name = "feedforward-pd"

    def __init__(self, omega_c: float = 10.0, zeta: float = 1.0, feedforward: bool = True,
                 prespin: bool = True, spinup_time_s: float = 0.4):
        self.kp, self.kd = omega_c**2, 2.0 * zeta * omega_c
        self.feedforward, self.prespin, self.spinup_time_s = feedforward, prespin, spinup_time_s

    def reset(self, context: ControllerContext) -> None:
        super().reset(context)
        self.J = context.inertia_prior
        impulse = stroke_impulse(context, self.J) if (self.feedforward and self.prespin) else 0.0
        self.omega_start = -impulse / (2.0 * float(context.rig["J_flywheel"]))

    def current(self, obs: dict[str, float]) -> float:
        ctx = self.ctx
        if obs["is_hold"] > 0.5:
            if not self.prespin:
                return 0.0
            J_f = float(ctx.rig["J_flywheel"])
            return J_f * (self.omega_start - obs["flywheel_rate"]) / (self.spinup_time_s * ctx.k_t)
        i = 0.0
        if self.feedforward:
            i += stroke_feedforward_current(ctx, obs["phi_ref"], obs["accel_ref"], self.J)
        i -= self.J * (self.kp * obs["tracking_error"] + self.kd * obs["rate_error"]) / ctx.k_t
        return float(np.clip(i, -ctx.i_max, ctx.i_max))


class PD(FeedforwardPD):
    """The bare PD baseline: the same loop without feedforward or pre-spin."""

    name = "pd"

    def __init__(self, omega_c: float = 10.0, zeta: float = 1.0):
        super().__init__(omega_c=omega_c, zeta=zeta, feedforward=False, prespin=False)
