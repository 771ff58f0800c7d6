"""Feed-forward + PD with a pre-spin planned on the supply over the whole stroke (issue 28, drive-v2).

On a fixed supply ``u_max`` the driver can hold the current only while the terminal voltage the
stroke asks for stays within it (sim/motor.py)::

    u(t) = R i(t) + k_t Omega(t),      Omega(t) = Omega_0 + (1 / J_f) integral_0^t k_t i ds

(``k_t`` the torque constant at the flywheel, the gear ratio included; ``R`` the winding;
``J_f`` the flywheel). With the feed-forward current of the mirrored stroke ``i_ff(t)`` (the
recorded law and the known rig only, :func:`~agents.base.stroke_feedforward_current`) each
sample of the stroke bounds the pre-spin ``Omega_0`` to an interval::

    (-m u_max - R i(t)) / k_t - h(t)  <=  Omega_0  <=  (m u_max - R i(t)) / k_t - h(t)

(``h(t)`` the flywheel's change of rate the plan implies, ``m`` = :attr:`margin` the share of
the supply the plan may use; the rest is the feedback's). The entry takes the pre-spin of
:class:`~agents.feedforward_pd.FeedforwardPD` scaled by ``prespin_fraction`` (1: the symmetric
one) where it lies in the intersection of these intervals; where it does not, the pre-spin that
minimises the plan's peak ``|u|`` (the middle of the two binding bounds: the middle of the
intersection where there is one, so the most room on both sides for what the plan does not predict;
where the stroke's swing needs more than the supply's room, the least excess), which is never worse
than no pre-spin.
:class:`~agents.drive_aware.DriveAwarePD` cuts instead on ``R i_max`` throughout and breaks when
the swing exceeds the room (docs/DRIVE.md, drive-v2).

In the stroke the command is clamped to what the supply can drive now,
``[(-u_max - k_t Omega) / R, (u_max - k_t Omega) / R]`` (``Omega`` the reported flywheel rate), so
the observer is fed the current that flows rather than one the driver cannot reach (the loop has
no integrator to wind up). Its loop gains are feedforward-pd's tuned ones (``tuned_as``): tuned on
the suite's tuning split, where the link's delay is (a 25 rad/s crossover, docs/DRIVE.md). Known
constants only (``ctx.rig``: ``u_max``, ``R``, ``k_t``, ``J_flywheel``); never the truth.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from agents.base import ControllerContext, stroke_feedforward_current
from agents.feedforward_pd import FeedforwardPD


def stroke_plan(context: ControllerContext, J: float, n: int = 400,
                i_limit: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The feed-forward current ``i(t)`` (A, cut to ``i_limit``, default ``context.i_max``, and to the rig's
    current limit) over the reverse stroke, in the stroke's order, and the flywheel's change of rate ``h(t)``
    (rad/s, from 0 at the stroke's start) that it implies. The reverse stroke retraces the free stroke's law
    backwards in time (:class:`~addedinertia_env.experiment.reference.MirroredReference`: from its stop to its start)."""
    rig, law = context.rig, context.reference.law
    s = np.linspace(law.t_stop, law.t_start, n)  # the law's time, in the reverse stroke's order
    cut = context.i_max if i_limit is None else i_limit
    i_lim = min(cut, rig.current_limit) if rig.current_limit is not None else cut
    i = np.clip(stroke_feedforward_current(context, law.phi(s) - rig.phi_neutral, law.accel(s), J), -i_lim, i_lim)
    dt = -np.diff(s)  # s, positive: the stroke's own time steps
    h = np.concatenate([[0.0], np.cumsum(0.5 * (i[1:] + i[:-1]) * dt)]) * context.k_t / rig.J_flywheel
    return i, h


def prespin_bounds(i: np.ndarray, h: np.ndarray, R: float, k_t: float, u_limit: float) -> tuple[float, float]:
    """The pre-spins ``Omega_0`` (rad/s) that keep ``|R i + k_t (Omega_0 + h)| <= u_limit`` at every sample of
    the plan (the rest before the stroke included, ``i = h = 0``): ``(lo, hi)``, empty where ``lo > hi``."""
    i = np.concatenate([[0.0], np.asarray(i, float)])
    h = np.concatenate([[0.0], np.asarray(h, float)])
    return float(np.max((-u_limit - R * i) / k_t - h)), float(np.min((u_limit - R * i) / k_t - h))


def plan_prespin(i: np.ndarray, h: np.ndarray, R: float, k_t: float, u_limit: float, target: float) -> float:
    """``target`` (rad/s) where it lies within :func:`prespin_bounds`; else the pre-spin that minimises the
    plan's peak ``|u|`` (the middle of the interval of pre-spins that fit, where there is one)."""
    lo, hi = prespin_bounds(i, h, R, k_t, u_limit)
    if lo <= target <= hi:
        return float(target)
    # the plan's excess over u_limit, k_t max(Omega_0 - hi, lo - Omega_0), is least at the middle, which also
    # leaves the most room on both sides where the fit is feasible (the plan predicts the current, not the loop's)
    return 0.5 * (lo + hi)


class SupplyAwarePD(FeedforwardPD):
    """:class:`~agents.feedforward_pd.FeedforwardPD` with the pre-spin planned on the supply (module doc)."""

    name = "supply-aware"
    tuned_as = "feedforward-pd"  # the same loop: feedforward-pd's tuned gains where the suite has no own entry
    DEFAULTS: dict[str, Any] = {**FeedforwardPD.DEFAULTS, "prespin_fraction": 1.0, "margin": 0.85}
    KNOBS = dict(FeedforwardPD.KNOBS)

    def __init__(self, tuned: bool = True, **overrides: Any):
        super().__init__(tuned=tuned, **overrides)
        m, f = self.params["margin"], self.params["prespin_fraction"]
        if not (isinstance(m, (int, float)) and math.isfinite(m) and 0.0 < m <= 1.0):
            raise ValueError(f"supply-aware: margin = {m!r}; expected the share of the supply the plan may use, "
                             "a number in (0, 1]")
        if not (isinstance(f, (int, float)) and math.isfinite(f) and 0.0 <= f <= 1.5):
            raise ValueError(f"supply-aware: prespin_fraction = {f!r}; expected a number in [0, 1.5] "
                             "(1: the symmetric pre-spin, 0: none)")

    def reset(self, context: ControllerContext) -> None:
        """As :class:`FeedforwardPD`, then the pre-spin planned on the supply over the stroke."""
        super().reset(context)
        rig = context.rig
        target = float(self.prespin_fraction) * self.omega_start
        self.plan_peak_v = None
        if rig.u_max is not None:
            i, h = stroke_plan(context, self.J)
            target = plan_prespin(i, h, rig.R, context.k_t, float(self.margin) * rig.u_max, target)
            self.plan_peak_v = float(np.max(np.abs(rig.R * i + context.k_t * (target + h))))
        self.omega_start = target
        self.prespin = True

    def current(self, obs: dict[str, float]) -> float:
        """:meth:`FeedforwardPD.current`, clamped in the stroke to what the supply can drive at the reported rate."""
        i = super().current(obs)
        rig = self.ctx.rig
        if obs["is_reverse"] > 0.5 and rig.u_max is not None and rig.R:
            emf = self.ctx.k_t * obs["flywheel_rate"]
            i = float(min(max(i, (-rig.u_max - emf) / rig.R), (rig.u_max - emf) / rig.R))
            self.i_prev = i
        return i
