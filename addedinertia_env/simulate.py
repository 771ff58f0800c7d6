"""Simulate experiments on a named rig and write run records: what ``addedinertia simulate`` does."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

import numpy as np

from agents.registry import DEFAULT_CONTROLLER

from .experiment.protocol import ExperimentPlan
from .experiment.runner import run_experiment
from .record import RunRecord, write_record
from .rig.effects import Effects, draw_effect
from .rig.mujoco_rig import MujocoRig
from .rig.params import RigParams

# Experiment kinds besides the reverse-symmetric one: "module:function(rig, plan=, run_id=) -> RunRecord".
OTHER_KINDS = {
    "free-decay": "addedinertia_env.experiment.free_decay:run_free_decay",
    "forced-oscillation": "addedinertia_env.experiment.forced:run_forced",
}


def simulate_run(rig_params: RigParams, controller: Any = DEFAULT_CONTROLLER, plan: ExperimentPlan | None = None,
                 seed: int | np.random.SeedSequence = 0, kind: str = "reverse-symmetric",
                 run_id: str = "run") -> RunRecord:
    """One simulated experiment of ``kind`` on a fresh MuJoCo rig."""
    rig = MujocoRig(rig_params, seed=seed)
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


def simulate_to_dir(rig_params: RigParams, out: str | Path, controller: str = DEFAULT_CONTROLLER,
                    plan: ExperimentPlan | None = None, seed: int = 0, cycles: int = 1,
                    kind: str = "reverse-symmetric") -> list[Path]:
    """``cycles`` records (independent sensor noise each) written as ``run-NNNN.csv/.json``."""
    paths = []
    for k, ss in enumerate(np.random.SeedSequence(seed).spawn(cycles)):
        rec = simulate_run(rig_params, controller, plan, seed=ss, kind=kind, run_id=f"run-{k:04d}")
        rec.meta["experiment"]["seed"] = seed
        rec.meta["experiment"]["cycle"] = k
        paths.append(write_record(rec, Path(out) / f"run-{k:04d}.csv"))
    return paths


def effects_from_name(name: str | None, seed: int = 0) -> Effects:
    """``None``/``none`` -> no effect; an effect name -> that effect at a seeded realistic size."""
    if not name or name == "none":
        return Effects()
    return draw_effect(name, np.random.default_rng(np.random.SeedSequence([seed, 7919])))
