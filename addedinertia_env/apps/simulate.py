"""Simulate experiments on a named rig and write run records: what ``addedinertia simulate`` does."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

import numpy as np

from agents.registry import DEFAULT_CONTROLLER

from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.protocol import ExperimentPlan
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.loop.control_loop import ControlLoop, LoopRig
from addedinertia_env.records.record import RunRecord, write_record
from addedinertia_env.sim.effects import Effects, draw_effect
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams

# Experiment kinds besides the reverse-symmetric one: "module:function(rig, plan=, run_id=) -> RunRecord".
OTHER_KINDS = {
    "free-decay": "addedinertia_env.experiment.free_decay:run_free_decay",
    "forced-oscillation": "addedinertia_env.experiment.forced:run_forced",
}


def simulate_run(rig_params: RigParams, controller: Controller | str = DEFAULT_CONTROLLER, plan: ExperimentPlan | None = None,
                 seed: int | np.random.SeedSequence = 0, kind: str = "reverse-symmetric",
                 run_id: str = "run", loop: ControlLoop | None = None) -> RunRecord:
    """One simulated experiment of ``kind`` on a fresh MuJoCo rig (behind ``loop``, if given: e.g. a link
    whose round trip is simulated as the readings' delay and stated to the controllers)."""
    rig = MujocoRig(rig_params, seed=seed)
    if loop is not None:
        rig = LoopRig(rig, loop)
    if kind == "reverse-symmetric":
        if isinstance(controller, str):
            from agents import make_controller  # noqa: PLC0415

            controller = make_controller(controller)
        return run_experiment(rig, controller, plan, run_id=run_id)
    if kind not in OTHER_KINDS:
        raise ValueError(f"experiment kind {kind!r}: expected 'reverse-symmetric' or one of {', '.join(OTHER_KINDS)}")
    module, _, func = OTHER_KINDS[kind].partition(":")
    record = getattr(importlib.import_module(module), func)(rig, plan=plan, run_id=run_id)
    return record


class OutputInUse(ValueError):
    """The output folder holds records of another simulation; the message says how to proceed."""


def simulate_to_dir(rig_params: RigParams, out: str | Path, controller: str = DEFAULT_CONTROLLER,
                    plan: ExperimentPlan | None = None, seed: int = 0, cycles: int = 1,
                    kind: str = "reverse-symmetric", signature: dict[str, Any] | None = None,
                    force: bool = False, kept: list[Path] | None = None,
                    loop: ControlLoop | None = None) -> list[Path]:
    """``cycles`` records (independent sensor noise each) written as ``run-NNNN.csv/.json``.

    ``signature`` (what the simulation was asked for, e.g. the command's arguments) is
    stored in each record's ``experiment.simulate``; a record already in ``out`` with the
    same signature and cycle is kept, not simulated again (a killed run resumes; its
    paths are appended to ``kept``), and one with another signature is refused
    (:class:`OutputInUse`) unless ``force``. ``loop``: the control loop every run sits behind (None: ideal);
    a stated round trip is recorded as ``experiment.link_round_trip_s`` (s), as ``deploy`` records it.
    """
    paths = []
    for k, ss in enumerate(np.random.SeedSequence(seed).spawn(cycles)):
        target = Path(out) / f"run-{k:04d}.csv"
        if signature is not None and _already_there(target, signature, k, force):
            paths.append(target)
            if kept is not None:
                kept.append(target)
            continue
        rec = simulate_run(rig_params, controller, plan, seed=ss, kind=kind, run_id=f"run-{k:04d}", loop=loop)
        if loop is not None and loop.stated_round_trip_s is not None:
            rec.meta["experiment"].update(link_round_trip_s=loop.stated_round_trip_s, link_round_trip_from="stated")
        rec.meta["experiment"]["seed"] = seed
        rec.meta["experiment"]["cycle"] = k
        if signature is not None:
            rec.meta["experiment"]["simulate"] = dict(signature)
        paths.append(write_record(rec, target))
    return paths


def _already_there(target: Path, signature: dict[str, Any], cycle: int, force: bool) -> bool:
    """True if ``target`` is a whole record of this simulation; refuse another one's unless ``force``."""
    import json  # noqa: PLC0415

    meta_path = target.with_suffix(".json")
    if not (target.exists() or meta_path.exists()) or force:
        return False
    try:
        experiment = json.loads(meta_path.read_text()).get("experiment") or {}
    except (OSError, ValueError, AttributeError):
        experiment = {}
    theirs = experiment.get("simulate")
    if theirs == json.loads(json.dumps(signature)) and experiment.get("cycle") == cycle and target.exists():
        from addedinertia_env.records.record import RecordError, read_record  # noqa: PLC0415

        try:
            read_record(target)
            return True
        except RecordError:
            return False  # a damaged record of this simulation: simulated again
    raise OutputInUse(f"{target}: holds a record of another simulation ({theirs or 'not written by simulate'}); "
                      "refusing to overwrite it. Use another --out, or --force to replace it")


def effects_from_name(name: str | None, seed: int = 0) -> Effects:
    """``None``/``none`` -> no effect; an effect name -> that effect at a seeded realistic size."""
    if not name or name == "none":
        return Effects()
    return draw_effect(name, np.random.default_rng(np.random.SeedSequence([seed, 7919])))
