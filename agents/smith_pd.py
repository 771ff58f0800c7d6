"""Feed-forward + PD behind a stated link: a Smith predictor and a supply plan with the feedback's share
(issue 28, drive-v3; docs/DRIVE.md "drive-v3 and smith-pd").

What a control engineer brings to a slow link and a short supply:

* **Dead-time compensation** (Smith 1957; Astrom & Hagglund 2006, section 7.x). The lab states its
  link's round trip (a loopback ping: ``ControllerContext.link_round_trip_s``, s; a suite's ``link:``
  block). The PD acts on the hull's state predicted that many samples ahead from the commands already
  sent (:class:`~agents.dead_time.DeadTimePredictor` on the hull observer), so its crossover is not
  bounded by the link's phase lag. The flywheel's reported rate is predicted the same way,
  ``Omega(k) = Omega(k - n) + (k_t / J_f) dt sum i`` over the n commands since.
* **The whole stroke's inertia, and room for the feedback.** The loop, the observer and the feed-forward run
  on the whole free stroke's inertia (:mod:`agents.stroke_inertia`), not the task's prior read at the stop,
  which a geared drive's dry friction biases by up to 2.3 times (docs/DRIVE.md). On that inertia the
  feed-forward ``-2 (J f'' + c (f - phi_n)) / k_t`` is an estimate (at the stroke's start, the free stroke's
  stop, it steps to the stop's residual torque, up to the current limit); it is cut to
  ``(1 - feedback_reserve) i_max`` so the feedback always has ``feedback_reserve i_max`` to correct it with.
* **A pre-spin planned on the supply with the feedback's share.** The stroke's plan
  (:func:`~agents.supply_aware.stroke_plan`: the feed-forward current and the flywheel's path) must keep
  ``|R i + k_t Omega| <= m u_max - R i_fb`` at every sample, where ``i_fb = feedback_reserve i_max`` is the
  current kept for the feedback (drive-v2's supply failures: the feed-forward plan under-predicted the
  voltage by ~3 V, the feedback's ~6 A at 0.5 Ohm; docs/DRIVE.md "supply-aware"). The symmetric pre-spin
  where it fits, else the nearest one that fits; where none fits, **no pre-spin** (as ``pd``, which kept
  tracking where every pre-spinning entry failed: the flywheel's measured path differs from the plan's by
  a factor 0.5-1.5 and once in sign, so a pre-spin that the plan cannot fit is a guess).
* **The command clamped to the supply's reach**, ``(+-u_max - k_t Omega) / R`` with the predicted
  ``Omega``, so the observer is fed a current the driver can drive.

Known constants only (``ctx.rig``: ``u_max``, ``R``, ``k_t``, ``J_flywheel``; the inertia prior; the stated
round trip); never the truth. It refuses a context without a stated round trip (or one that is not a
finite number of seconds in [0, 0.2]), naming it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from agents.base import ControllerContext
from agents.dead_time import DeadTimePredictor
from agents.feedforward_pd import FeedforwardPD
from agents.stroke_inertia import stroke_fit_inertia
from agents.supply_aware import prespin_bounds, stroke_plan

MAX_ROUND_TRIP_S = 0.2  # s: a link slower than this is no loop to close at the stroke's 0.5-2 s


def link_delay_samples(context: ControllerContext, who: str = "smith-pd") -> int:
    """Whole control periods of the stated round trip; ValueError naming the field where none is stated."""
    rtt = context.link_round_trip_s
    if rtt is None:
        raise ValueError(f"{who}: the controller context states no link round trip (link_round_trip_s = None); "
                         "expected the round trip in s, as a suite's `link:` block or a lab's loopback ping states it")
    if isinstance(rtt, bool) or not isinstance(rtt, (int, float)) or not math.isfinite(rtt) \
            or not 0.0 <= rtt <= MAX_ROUND_TRIP_S:
        raise ValueError(f"{who}: link_round_trip_s = {rtt!r}; expected a finite number of seconds in "
                         f"[0, {MAX_ROUND_TRIP_S}]")
    return int(round(rtt / context.dt))


def fit_prespin(lo: float, hi: float, target: float) -> float:
    """``target`` (rad/s) moved to the nearest pre-spin in ``[lo, hi]``; 0 (none) where the interval is empty."""
    if lo > hi:
        return 0.0
    return float(min(max(target, lo), hi))


class SmithPD(FeedforwardPD):
    """Feed-forward + PD on the Smith-predicted hull, with a supply plan that keeps room for the feedback."""

    name = "smith-pd"
    needs_stated_link = True  # reset refuses a context without link_round_trip_s (the CLI says so up front)
    DEFAULTS: dict[str, Any] = {**FeedforwardPD.DEFAULTS, "omega_c": 25.0, "margin": 0.9, "feedback_reserve": 0.3,
                                "inertia": "stroke-fit", "dead_time_compensation": True}
    # feedforward-pd's loop knobs and ranges (its crossover bounded by the encoder's quantisation through the gains,
    # physics.md section 7; a first tuning over 8-60 rad/s picked 59.7, whose gain turns one encoder count into
    # ~20 A: docs/DRIVE.md), and the feedback's share of the current and the supply
    KNOBS = {**FeedforwardPD.KNOBS, "feedback_reserve": (0.0, 0.6, "lin")}

    def __init__(self, tuned: bool = True, **overrides: Any):
        super().__init__(tuned=tuned, **overrides)
        m, r = self.params["margin"], self.params["feedback_reserve"]
        if self.params["inertia"] not in ("stroke-fit", "prior"):
            raise ValueError(f"smith-pd: inertia = {self.params['inertia']!r}; expected 'stroke-fit' (the whole free "
                             "stroke's least-squares inertia) or 'prior' (the task's prior at the stop)")
        if isinstance(m, bool) or not isinstance(m, (int, float)) or not math.isfinite(m) or not 0.0 < m <= 1.0:
            raise ValueError(f"smith-pd: margin = {m!r}; expected the share of the supply the plan may use, in (0, 1]")
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) or not 0.0 <= r <= 1.0:
            raise ValueError(f"smith-pd: feedback_reserve = {r!r}; expected the share of i_max kept for the "
                             "feedback, in [0, 1]")

    def reset(self, context: ControllerContext) -> None:
        """As :class:`FeedforwardPD` on the whole-stroke inertia (``inertia: stroke-fit``; :mod:`agents.stroke_inertia`),
        with the link's delay taken from the context and the pre-spin planned."""
        self.delay = link_delay_samples(context) if self.dead_time_compensation else 0  # False: an ablation only
        self.inertia_source = context.inertia_prior
        if self.inertia == "stroke-fit":
            context = dataclasses.replace(context, inertia_prior=stroke_fit_inertia(context))
        super().reset(context)
        self.predictor = DeadTimePredictor(self.obs_filter, self.delay)
        self.sent: list[float] = []  # every command sent this episode, A (the flywheel's prediction)
        rig = context.rig
        self.plan_peak_v = None
        self.i_ff_max = (1.0 - float(self.feedback_reserve)) * context.i_max  # A, the feed-forward's share
        if rig.u_max is not None and self.prespin:
            i, h = stroke_plan(context, self.J, i_limit=self.i_ff_max)  # the feed-forward cut to its share
            u_lim = float(self.margin) * rig.u_max - rig.R * float(self.feedback_reserve) * context.i_max
            self.omega_start = fit_prespin(*prespin_bounds(i, h, rig.R, context.k_t, u_lim), self.omega_start)
            self.plan_peak_v = float(np.max(np.abs(rig.R * i + context.k_t * (self.omega_start + h))))

    def feedforward_current(self, obs: dict[str, float]) -> float:
        """:meth:`FeedforwardPD.feedforward_current` cut to ``(1 - feedback_reserve) i_max`` (module doc)."""
        return float(np.clip(super().feedforward_current(obs), -self.i_ff_max, self.i_ff_max))

    def flywheel_now(self, obs: dict[str, float]) -> float:
        """The flywheel's rate now, rad/s: the reported (``n`` samples old) plus the commands' impulse since."""
        if self.delay == 0 or not self.sent:
            return obs["flywheel_rate"]
        recent = self.sent[-self.delay:]
        return obs["flywheel_rate"] + self.ctx.k_t * self.ctx.dt * float(sum(recent)) / self.ctx.rig.J_flywheel

    def hold_current(self, obs: dict[str, float]) -> float:
        """The pre-spin's current on the predicted flywheel rate (0 without pre-spin)."""
        if not self.prespin:
            return 0.0
        J_f = self.ctx.rig.J_flywheel
        return J_f * (self.omega_start - self.flywheel_now(obs)) / (self.spinup_time_s * self.ctx.k_t)

    def track_state(self, obs: dict[str, float]) -> tuple[float, float]:
        """Tracking errors ``(phi_ref - phi, rate_ref - w)`` on the hull predicted ``n`` samples ahead."""
        if not self.started:
            x = self.predictor.start(obs["phi"])
            self.started = True
        else:
            x = self.predictor.update(self.i_prev, self.d_expected_prev, obs["phi"])
        self.d_expected_prev = self.expected_damping(obs)
        return obs["phi_ref"] - float(x[0]), obs["rate_ref"] - float(x[1])

    def stroke_current(self, obs: dict[str, float]) -> float:
        """Feed-forward + PD on the predicted hull, clamped to the supply's reach on the predicted flywheel rate."""
        i = super().stroke_current(obs)
        rig = self.ctx.rig
        if rig.u_max is not None and rig.R:
            emf = self.ctx.k_t * self.flywheel_now(obs)
            i = min(max(i, (-rig.u_max - emf) / rig.R), (rig.u_max - emf) / rig.R)
        return i

    def current(self, obs: dict[str, float]) -> float:
        """Hold: the pre-spin; reverse stroke: :meth:`stroke_current`; every command sent is kept for the predictor."""
        i = super().current(obs)
        self.sent.append(i)
        return i
