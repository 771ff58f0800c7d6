"""The controlled part of an experiment at the policy's rate: the host half of the two-rate bench.

The board runs its inner loop (:mod:`addedinertia_env.loop.board_loop`) every sample; the
host acts once per host period (``1 / host_rate_hz``) and sends a *segment*. The same
loop runs against the simulator (:class:`~addedinertia_env.loop.board_loop.TwoRateSimRig`)
and against a bench (``hw_adapter.bench_rig.BenchRig`` with ``host_rate_hz``), so a
policy trained or a controller benchmarked in simulation sees the board it will drive.

Board modes (the task's ``board_mode``):

* ``zoh``: the controller's ``predict`` runs at the host rate; its current is held by
  the board (one knot) until the next segment. Any controller, learned or classical.
* ``pd``: for controllers with ``board_pd`` (the classical stroke controllers): the host
  sends the stroke's feed-forward current and reference angle as piecewise-linear knots
  over three host periods, with PD gains; the board closes the fast loop on its own
  encoder every sample. The brake release at the end of the hold is scheduled on the
  board's clock, so it lands on its sample whatever the host's latency.

Every segment starts at the newest sample the host has (``t0``), is due within one host
period (``deadline = t0 + period``) and lasts three, so one or two late or lost segments
cost nothing; after that the board holds for its grace and then stops by itself.
"""

from __future__ import annotations

import math
from typing import Any

from addedinertia_env.loop.board_loop import BOARD_MODES, HORIZON_PERIODS, Segment, zoh_segment
from addedinertia_env.experiment.task import ControllerContext, ReverseStrokeTask
from addedinertia_env.experiment.feedforward import stroke_feedforward_current
from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.protocol import Experiment

KNOTS = 7  # knots per pd segment (6 pieces over HORIZON_PERIODS = 3 host periods)


def supports_board_pd(controller: Controller) -> bool:
    """True if ``controller`` can run in board mode ``pd`` (it has ``board_pd``)."""
    return callable(getattr(controller, "board_pd", None))


def default_board_mode(controller: Controller) -> str:
    """The controller's own board mode if it declares one (an exported policy's card), else
    ``zoh``. (``pd`` with the classical controllers' gains is available but not the default:
    with the board's alpha-beta rate estimate on a 17-bit encoder the LQR's rate gain
    turns quantisation noise into current at the limit; docs/BENCH.md.)"""
    return getattr(controller, "board_mode", None) or "zoh"


def two_rate_context(exp: Experiment, host_rate_hz: float, board_mode: str):
    """The controller context at the host's rate (with the link's round trip the rig states, if any)."""
    return ControllerContext(rig=exp.known, layout=ReverseStrokeTask.layout, reference=exp.reference,
                             inertia_prior=exp.inertia_prior, dt=1.0 / host_rate_hz, hold_s=exp.plan.hold_s,
                             policy_rate_hz=host_rate_hz, board_mode=board_mode, sample_dt=exp.rig.dt,
                             link_round_trip_s=stated_round_trip(exp.rig))


MAX_STATED_ROUND_TRIP_S = 1.0  # s: the longest watchdog; a lab's round trip beyond it stops every run


def stated_round_trip(rig: Any) -> float | None:
    """The link's round trip stated to the controllers (s) by a rig that states one (a
    :class:`~addedinertia_env.loop.control_loop.LoopRig` whose loop states it, a ``TwoRateSimRig`` around one,
    a bench whose lab stated it: ``deploy --link-round-trip-ms``); None otherwise (never the loop's true delay).
    Single-rate and two-rate contexts both read it here."""
    value = getattr(rig, "stated_round_trip_s", None)
    return float(value) if value is not None else None


class SegmentPlanner:
    """Turns the controller's decision at one host tick into a :class:`Segment`."""

    def __init__(self, exp: Experiment, controller: Controller, task: ReverseStrokeTask, board_mode: str,
                 host_rate_hz: float):
        if board_mode not in BOARD_MODES:
            raise ValueError(f"board mode {board_mode!r}: expected one of {BOARD_MODES}")
        if board_mode == "pd" and not supports_board_pd(controller):
            raise ValueError(f"board mode 'pd' needs a controller with board_pd (the classical stroke "
                             f"controllers); {type(controller).__name__} has none: use board mode 'zoh'")
        self.exp, self.controller, self.task = exp, controller, task
        self.board_mode = board_mode
        self.period_s = 1.0 / host_rate_hz
        self.period_us = int(round(1e6 * self.period_s))

    def plan(self, rig: Any) -> Segment:
        """The segment the board plays from the newest sample on: the controller's held command
        (board mode ``zoh``) or its PD law for the board (``pd``), with the switch time (board
        microseconds) when the reverse stroke begins within the horizon.
        """
        exp = self.exp
        t_last = exp.last.t
        t0 = rig.board_time_us(t_last)
        obs = self.task.observe(exp)
        ref = exp.reference
        in_hold = exp.phase == "hold"
        switch = rig.board_time_us(ref.t_begin) if in_hold and ref.t_begin < t_last + HORIZON_PERIODS * self.period_s else None
        if self.board_mode == "zoh":
            action, _ = self.controller.predict(obs, deterministic=True)
            return zoh_segment(rig.next_seg_id(), self.task.command(action), in_hold, t0, self.period_us, switch)
        return self._pd_segment(rig, obs, t_last, t0, switch)

    def _pd_segment(self, rig: Any, obs, t_last: float, t0: int, switch: int | None) -> Segment:
        exp, ctl = self.exp, self.controller
        ref = exp.reference
        decoded = ctl.ctx.layout.decode(obs)
        kp, kd, correction = ctl.board_pd(decoded)
        hold_i = ctl.hold_current(decoded) if exp.phase == "hold" else 0.0
        horizon = HORIZON_PERIODS * self.period_s
        knot_s = horizon / (KNOTS - 1)
        end_passive = False
        duration_s = horizon
        if ref.t_end < t_last + horizon:  # the stroke ends inside: then passive, as the experiment's tail
            duration_s = max(ref.t_end - t_last, exp.rig.dt)
            end_passive = True
        phi_n = exp.known.phi_neutral
        i_max = exp.known.current_limit
        currents, refs = [], []
        for k in range(KNOTS):
            t = t_last + k * knot_s
            if t < ref.t_begin:
                i = hold_i
            else:
                i = correction
                if getattr(ctl, "feedforward", True):
                    i += stroke_feedforward_current(ctl.ctx, float(ref.phi(t)) - phi_n, float(ref.accel(t)), ctl.J)
            currents.append(min(i_max, max(-i_max, float(i))))
            refs.append(float(ref.phi(t)))
        return Segment(rig.next_seg_id(), t0, int(round(duration_s * 1e6)), (t0 + self.period_us) % 2**32,
                       int(round(knot_s * 1e6)), tuple(currents), tuple(refs), float(kp), float(kd),
                       brake=exp.phase == "hold", brake_switch_us=switch, end_passive=end_passive)


def drive_two_rate(exp: Experiment, controller: Controller, host_rate_hz: float, board_mode: str | None = None) -> None:
    """The controlled part of a started experiment at ``host_rate_hz``.

    ``exp.rig`` is a two-rate rig (``send_segment``, ``poll``, ``board_time_us``,
    ``next_seg_id``; ``step(None)`` reads the next board sample). The host plans a
    segment once a host period of board time has passed *and* it has read every sample
    that arrived (it never plans on stale data); every sample still goes through the
    experiment (record, phases) in order.
    """
    if not (math.isfinite(host_rate_hz) and host_rate_hz > 0):
        raise ValueError(f"host rate {host_rate_hz!r} Hz: expected > 0")
    rig = exp.rig
    mode = board_mode or default_board_mode(controller)
    task = ReverseStrokeTask.for_rig(exp.known)
    if hasattr(controller, "reset"):
        controller.reset(two_rate_context(exp, host_rate_hz, mode))
    planner = SegmentPlanner(exp, controller, task, mode, host_rate_hz)
    period = 1.0 / host_rate_hz
    next_plan = -math.inf
    while exp.needs_control:
        if exp.last.t >= next_plan - 0.5 * rig.dt and rig.poll() == 0:
            rig.send_segment(planner.plan(rig))
            next_plan = exp.last.t + period
        exp.step(None)
