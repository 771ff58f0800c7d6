"""Feedforward from the recorded law + PD feedback, with flywheel pre-spin; and the bare PD.

:class:`StrokeController` holds what every classical controller here shares: the hold
phase (flywheel pre-spin), the hull observer (:mod:`agents.observer`), the feedforward
current that retraces the mirrored stroke, and the current limit. Subclasses write only
:meth:`StrokeController.feedback`, in amperes.

Tuning procedure (docs/CONTROLLERS.md): the loop is placed at ``omega_c`` rad/s with
damping ``zeta``: ``Kp = omega_c^2``, ``Kd = 2 zeta omega_c``, scaled by the prior
inertia. ``omega_c`` is limited by encoder quantisation noise fed through ``Kd``
(physics.md section 7); the observer lowers that noise. The knobs and their ranges are
:attr:`FeedforwardPD.KNOBS`; tuned values live in configs/controllers/tuned.yaml.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import Controller, ControllerContext, stroke_feedforward_current, stroke_impulse
from agents.observer import HullObserver
from agents.tuned import resolve_params


class StrokeController(Controller):
    """Shared machinery: pre-spin in the hold, observer, feedforward, limit; see module doc.

    Parameters common to all subclasses:
    ``feedforward`` (bool) add the recorded-law current; ``prespin`` (bool) spin the
    flywheel during the hold so that it ends the stroke with the speed it started with,
    reversed; ``spinup_time_s`` (s) time constant of that spin-up; ``observer`` (bool)
    use :class:`~agents.observer.HullObserver` (else the task's windowed rate
    estimate); ``observer_bandwidth`` (rad/s) its residual-torque bandwidth.
    """

    name = "stroke"
    DEFAULTS: dict[str, Any] = {"feedforward": True, "prespin": True, "spinup_time_s": 0.4,
                                "observer": True, "observer_bandwidth": 20.0}
    KNOBS: dict[str, tuple[float, float, str]] = {}  # name -> (low, high, "log" | "lin"), for tuning

    def __init__(self, tuned: bool = True, **overrides: Any):
        self.params = resolve_params(getattr(self, "tuned_as", self.name) if tuned else None, self.DEFAULTS, overrides)
        for key, value in self.params.items():
            setattr(self, key, value)

    # --- per stroke -------------------------------------------------------------------
    def reset(self, context: ControllerContext) -> None:
        """Start of the controlled part: take the inertia prior and rod stiffness, size the
        pre-spin and the observer."""
        super().reset(context)
        rig = context.rig
        self.J = context.inertia_prior
        self.c = rig.c_torsion
        impulse = stroke_impulse(context, self.J) if self.prespin else 0.0
        self.omega_start = -impulse / (2.0 * rig.J_flywheel)
        counts = rig.phi_counts
        self.obs_filter = HullObserver(self.J, self.c, context.k_t, context.dt, counts,
                                       disturbance_bandwidth=float(self.observer_bandwidth))
        self.started = False
        self.i_prev = 0.0
        self.d_expected_prev = 0.0

    def hold_current(self, obs: dict[str, float]) -> float:
        """Current (A) during the hold: spins the flywheel up to the pre-spin rate (0 without pre-spin)."""
        if not self.prespin:
            return 0.0
        J_f = self.ctx.rig.J_flywheel
        return J_f * (self.omega_start - obs["flywheel_rate"]) / (self.spinup_time_s * self.ctx.k_t)

    def expected_damping(self, obs: dict[str, float]) -> float:
        """Damping torque (N m) the mirrored stroke meets: ``-(J accel_ref + c phi_ref)``."""
        return -(self.J * obs["accel_ref"] + self.c * obs["phi_ref"])

    def track_state(self, obs: dict[str, float]) -> tuple[float, float]:
        """Tracking errors ``(phi_ref - phi, rate_ref - w)`` from the observer (or the task)."""
        if not self.observer:
            return obs["tracking_error"], obs["rate_error"]
        if not self.started:
            self.obs_filter.start(obs["phi"], 0.0, 0.0)  # braked until now: at rest
            self.started = True
        else:
            self.obs_filter.predict(self.i_prev, self.d_expected_prev)
            self.obs_filter.correct(obs["phi"])
        self.d_expected_prev = self.expected_damping(obs)
        return obs["phi_ref"] - self.obs_filter.phi, obs["rate_ref"] - self.obs_filter.rate

    def feedforward_current(self, obs: dict[str, float]) -> float:
        """Feed-forward current (A) that retraces the mirrored stroke at this observation."""
        if not self.feedforward:
            return 0.0
        return stroke_feedforward_current(self.ctx, obs["phi_ref"], obs["accel_ref"], self.J)

    def feedback(self, obs: dict[str, float], e: float, e_rate: float) -> float:  # pragma: no cover
        """Feedback current, A, added to the feed-forward on the reverse stroke (subclasses write it).

        ``e = phi_ref - phi`` (rad) and ``e_rate`` (rad/s) are the tracking errors from
        :meth:`track_state`; a positive error (hull behind) needs negative current.
        """
        raise NotImplementedError

    # --- two-rate bench, board mode "pd" (addedinertia_env/experiment/two_rate.py) -------
    def board_pd(self, obs: dict[str, float]) -> tuple[float, float, float]:
        """Gains of the board-side PD, ``kp`` (A/rad) and ``kd`` (A/(rad/s)) on
        ``phi_ref - phi`` and its rate, and the host's slowly varying correction (A) added to
        the feed-forward knots; called once per host period in the reverse stroke.
        Default: the loop at ``omega_c`` rad/s with damping ``zeta`` (10 rad/s, 1 if unset)."""
        w, z = float(getattr(self, "omega_c", 10.0)), float(getattr(self, "zeta", 1.0))
        scale = -self.J / self.ctx.k_t  # positive error (hull behind) needs negative current
        return scale * w * w, scale * 2.0 * z * w, 0.0

    def current(self, obs: dict[str, float]) -> float:
        """The command (A) for this observation: hold current, or feed-forward plus feedback on the reverse stroke."""
        ctx = self.ctx
        if obs["is_hold"] > 0.5:
            i = self.hold_current(obs)
        elif obs["is_reverse"] > 0.5:
            i = self.stroke_current(obs)
        else:
            i = 0.0
        i = float(np.clip(i, -ctx.i_max, ctx.i_max))
        self.i_prev = i
        return i

    def stroke_current(self, obs: dict[str, float]) -> float:
        """The reverse stroke's command before the drive's limit (A): feed-forward plus feedback on the tracked state."""
        e, e_rate = self.track_state(obs)
        return self.feedforward_current(obs) + self.feedback(obs, e, e_rate)


class FeedforwardPD(StrokeController):
    """Feedforward + PD on the observer's state + pre-spin: the project's default controller."""

    name = "feedforward-pd"
    DEFAULTS = {**StrokeController.DEFAULTS, "omega_c": 10.0, "zeta": 1.0}
    KNOBS = {"omega_c": (3.0, 40.0, "log"), "zeta": (0.5, 2.0, "lin"), "observer_bandwidth": (2.0, 80.0, "log")}

    def feedback(self, obs: dict[str, float], e: float, e_rate: float) -> float:
        """PD on the tracking error, A: ``-J (omega_c^2 e + 2 zeta omega_c e_rate) / k_t`` (``J`` the inertia prior, kg m^2)."""
        kp, kd = self.omega_c**2, 2.0 * self.zeta * self.omega_c
        # Positive error (hull behind) needs more hull torque, i.e. negative current.
        return -self.J * (kp * e + kd * e_rate) / self.ctx.k_t


class PD(FeedforwardPD):
    """The bare PD baseline: the same loop without feedforward, pre-spin or observer. It reads no tuned
    file; a suite that tunes every entry with one budget (drive-v1) passes its tuned gains explicitly."""

    name = "pd"
    KNOBS = {"omega_c": (3.0, 40.0, "log"), "zeta": (0.5, 2.0, "lin")}  # no observer to tune

    def __init__(self, omega_c: float = 10.0, zeta: float = 1.0, tuned: bool = False):  # noqa: ARG002 - never reads one
        super().__init__(tuned=False, omega_c=omega_c, zeta=zeta, feedforward=False, prespin=False,
                         observer=False)
