"""Run one reverse-symmetric experiment with a controller: the loop every caller shares."""

from __future__ import annotations

from typing import Any

from addedinertia_env.records.record import RunRecord
from addedinertia_env.rig.interface import Rig
from addedinertia_env.experiment.task import ControllerContext, ReverseStrokeTask
from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.protocol import Experiment, ExperimentPlan
from addedinertia_env.experiment.two_rate import stated_round_trip  # noqa: F401  (re-exported: its older home)


def controller_context(exp: Experiment):
    """What a controller may know once the free stroke is recorded."""
    every = command_every(exp.rig)
    slow = {"policy_rate_hz": 1.0 / (exp.rig.dt * every), "sample_dt": exp.rig.dt} if every > 1 else {}
    return ControllerContext(rig=exp.known, layout=ReverseStrokeTask.layout, reference=exp.reference,
                             inertia_prior=exp.inertia_prior, dt=exp.rig.dt * every, hold_s=exp.plan.hold_s,
                             link_round_trip_s=stated_round_trip(exp.rig), **slow)


def needs_stated_link(controller: Controller) -> bool:
    """Whether ``controller``, or the classical base under a residual policy (its ``base``), refuses a context
    without the link's round trip (``needs_stated_link``: smith-pd and policies on it)."""
    return bool(getattr(controller, "needs_stated_link", False)
                or getattr(getattr(controller, "base", None), "needs_stated_link", False))


def command_every(rig: Any) -> int:
    """Rig samples per controller call: 1, or the drive's set-point period of a
    :class:`~addedinertia_env.loop.control_loop.LoopRig` (a 100 Hz drive on a 1 kHz rig: 10)."""
    return max(1, int(getattr(rig, "command_every", 1)))


def run_experiment(rig: Rig, controller: Controller, plan: ExperimentPlan | None = None,
                   run_id: str = "run", policy_rate_hz: float | None = None,
                   board_mode: str | None = None) -> RunRecord:
    """Twist, release, hold and reverse under ``controller``; returns the run record.

    ``controller``: a :class:`~.controller.Controller` (``reset(context)``, called once the free
    stroke has been recorded, then ``predict(obs) -> (action, state)``).
    ``policy_rate_hz``: the controller acts at this rate through the two-rate board's
    inner loop (``loop/board_loop.py``, mode ``board_mode``, default ``zoh``), as on a
    two-rate bench (``deploy --host-rate-hz``); None: at every sample.
    """
    if policy_rate_hz is not None:
        from addedinertia_env.loop.board_loop import TwoRateSimRig  # noqa: PLC0415
        from addedinertia_env.experiment.two_rate import drive_two_rate  # noqa: PLC0415

        exp = Experiment(TwoRateSimRig(rig, policy_rate_hz), plan)
        exp.start()
        drive_two_rate(exp, controller, policy_rate_hz, board_mode)
        return exp.record(run_id)
    exp = Experiment(rig, plan)
    exp.start()
    drive(exp, controller)
    return exp.record(run_id)


def drive(exp: Experiment, controller: Controller) -> None:
    """The controlled part of a started experiment: hold and reverse stroke under ``controller``.

    The simulator (:func:`run_experiment`), the environment's classical baselines and the
    bench (``hw_adapter.deploy``) all run this one loop.
    """
    task = ReverseStrokeTask.for_rig(exp.known)
    if hasattr(controller, "reset"):
        controller.reset(controller_context(exp))
    every, k = command_every(exp.rig), 0
    while exp.needs_control:
        if k % every == 0:  # the controller runs at the drive's set-point rate
            action, _ = controller.predict(task.observe(exp), deterministic=True)
            cmd = task.command(action)
        exp.step(cmd)
        k += 1
