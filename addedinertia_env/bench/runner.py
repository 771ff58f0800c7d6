"""Run benchmark episodes: ``EpisodeTask -> row`` (one JSON line), locally in processes.

A row holds at least: controller, suite, scenario, seed, lambda66_true, lambda66_est,
rel_error ((estimate - truth) / truth, a fraction: 0.01 is 1 %), energy_J, tracking_rms_rad,
saturated_frac, wall_s, version (and commit), and the score's version ``score_version``
(:mod:`.versions`: truth lambda66 = A66(0)).
Every number of the episode comes from the one scoring, :func:`addedinertia_env.evaluation.scoring.score_episode`
(``lambda66_true``: the records' truth block, scoring only). A run or identification that
fails gives a row with ``rel_error: null`` and the reason in ``failure``.

The ranked ``rel_error`` is the patent's energy method as written
(``asymmetry_correction=False``); ``rel_error_corrected`` is the project's default
(corrected) estimate, reported beside it. A suite with ``cycles: N`` runs N
reverse-symmetric cycles per episode (each with fresh sensor noise, the same noise for
every controller) and identifies them jointly. Controllers that learn across cycles
(``BENCH_CYCLES`` > 1, e.g. ILC) first run ``BENCH_CYCLES - 1`` unscored learning cycles
(with other noise), keeping their state. The references ``oracle`` (truth-based tracking,
:mod:`..experiment.oracle`) and ``zero`` (0 A) run like any controller.
"""

from __future__ import annotations

import functools
import math
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from agents import make_controller

from addedinertia_env import __version__
from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.experiment.scenarios import build_rig
from addedinertia_env.evaluation.scoring import AS_WRITTEN, CORRECTED, MEMORY_CORRECTED, score_episode
from addedinertia_env.bench.suites import EpisodeTask
from addedinertia_env.bench.versions import row_fields as score_version_fields
from addedinertia_env.bench.score import row_fields as score_fields
from addedinertia_env.bench.wear import episode_wear

# The ranked score: the patent's energy method as written (no model-based correction of the
# strokes' dissipation mismatch), so that what the controller fails to retrace shows. The
# corrected estimate (the project's default identification) is reported beside it.
SCORE_METHOD = "energy, asymmetry_correction=False"
RANKED_METHODS = {AS_WRITTEN: SCORE_METHOD, MEMORY_CORRECTED: "energy, asymmetry_correction=False, memory=auto"}

REQUIRED_FIELDS = ("controller", "suite", "scenario", "seed", "lambda66_true", "lambda66_est", "rel_error",
                   "energy_J", "tracking_rms_rad", "saturated_frac", "wall_s", "version")


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """Short commit of the working tree, or ``unknown``."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).resolve().parent,
                             capture_output=True, text=True, timeout=10)
        return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def cycle_seed(scenario, k: int) -> np.random.SeedSequence:
    """Sensor-noise seed of cycle ``k`` of a scenario (a child of the scenario's sensor seed).

    Scored cycles are ``k = 0 .. cycles - 1`` for every controller, so that all entries and
    the references meet the same sensor noise (paired scoring); learning cycles of a
    controller that adapts across cycles (ILC) use ``k = 1000, 1001, ...``."""
    ss = scenario.sensor_seed
    return np.random.SeedSequence(entropy=ss.entropy, spawn_key=(*ss.spawn_key, k))


REFERENCES = ("oracle", "zero")  # reference rows: truth-based tracking (the floor), motor passive
WARMUP_SEED_BASE = 1000


def episode_controller(name: str, kwargs: dict[str, Any], rig: Any) -> Controller:
    """The controller of an episode: a reference (``oracle`` needs the simulated ``rig``) or a
    registry name (agents/registry.py)."""
    if name == "oracle":
        from addedinertia_env.experiment.oracle import OracleController  # noqa: PLC0415

        return OracleController(rig)
    if name == "zero":
        from agents.zero import ZeroCurrent  # noqa: PLC0415

        return ZeroCurrent()
    return make_controller(name, **kwargs)


def entry_kind(name: str, controller: Controller | None = None) -> str:
    """``reference``, ``learned`` (a training cost is known) or ``classical``; see also ``task.entry``."""
    if name in REFERENCES:
        return "reference"
    if name.startswith("onnx:") or getattr(controller, "train_env_steps", None) is not None:
        return "learned"
    return "classical"


def run_episode(task: EpisodeTask) -> dict[str, Any]:
    """One benchmark row (see module doc)."""
    t0 = time.perf_counter()
    sc = task.scenario
    from addedinertia_env.sim.forces import gear_ratio, true_lambda66  # noqa: PLC0415

    truth = true_lambda66(sc.rig)  # describes the scenario; the score's own (the records' truth block) replaces it
    row: dict[str, Any] = {
        "controller": task.controller, "suite": task.suite, "split": task.split, "scenario": sc.name,
        "seed": sc.seed, "preset": task.preset, "sensor_quality": sc.sensor_quality,
        "hold_s": sc.plan.hold_s, "alpha": sc.plan.alpha, "lambda_ratio": truth / sc.rig.hull.J_hull,
        "lambda66_true": truth, "lambda66_est": None, "ci95": None, "rel_error": None, "abs_rel_error": None,
        "lambda66_est_corrected": None, "rel_error_corrected": None, "score_method": SCORE_METHOD,
        "energy_J": None, "tracking_rms_rad": None, "saturated_frac": None, "cycles": task.cycles,
        "learning_cycles": 0, "effects": sorted(sc.rig.effects.active),
        "control_loop": sc.loop.to_dict() if sc.loop is not None else None, "i_max": sc.rig.motor.i_max,
        "failure": None, "controller_kwargs": task.controller_kwargs, "version": __version__,
        "commit": git_commit(), "entry_kind": None, **score_version_fields(geared=gear_ratio(sc.rig) > 1.0, ranked=task.ranked),
    }
    if task.ranked != AS_WRITTEN:  # the suite ranks another estimate (bench/suites.py ``ranked``)
        row.update(ranked_score=task.ranked, score_method=RANKED_METHODS[task.ranked])
    try:
        rig = build_rig(sc, seed=cycle_seed(sc, 0))
        controller = episode_controller(task.controller, task.controller_kwargs, rig)
        for key in ("train_env_steps", "train_cpu_minutes"):  # learned policies: training cost (OnnxPolicy)
            if getattr(controller, key, None) is not None:
                row[key] = getattr(controller, key)
        row["entry_kind"] = entry_kind(task.controller, controller)
        row.update(task.entry)  # what an outside submission declares (bench run --entry-kind, card)
        learning = max(1, int(getattr(controller, "BENCH_CYCLES", 1))) - 1
        row["learning_cycles"] = learning
        records = []
        schedule = [WARMUP_SEED_BASE + j for j in range(learning)] + list(range(task.cycles))
        for n, k in enumerate(schedule):
            if n > 0:
                rig = build_rig(sc, seed=cycle_seed(sc, k))
                if task.controller == "oracle":
                    controller.rig = rig
            rec = run_experiment(rig, controller, sc.plan, run_id=f"{sc.name}/cycle-{k}")
            if n >= learning:
                records.append(rec)
        # the one scoring (addedinertia_env/evaluation/scoring.py): ranked as written, the corrected score beside it
        ranked = score_episode(records, task.ranked)
        row.update(episode_wear(records, sc.rig.motor.i_max))  # current sign changes, chatter (bench/wear.py)
        row.update(lambda66_true=ranked.lambda66_true, energy_J=ranked.energy_J, saturated_frac=ranked.saturated_frac,
                   tracking_rms_rad=ranked.tracking_rms_rad if math.isfinite(ranked.tracking_rms_rad) else None)
        corrected = score_episode(records, CORRECTED, metrics=False)
        if corrected.failed:  # reported beside the ranked score, never instead of it
            row["failure_corrected"] = f"{corrected.failure_type}: {corrected.failure}"
        else:
            row.update(lambda66_est_corrected=corrected.lambda66_est, rel_error_corrected=corrected.rel_error)
        if ranked.failed:
            row["failure"] = f"{ranked.failure_type}: {ranked.failure}"
        else:
            row.update(lambda66_est=ranked.lambda66_est, ci95=list(ranked.ci95), rel_error=ranked.rel_error,
                       abs_rel_error=abs(ranked.rel_error))
    except Exception as e:  # noqa: BLE001 - any failure of one episode is that episode's result
        row["failure"] = f"{type(e).__name__}: {e}"
    row.update(score_fields(row))  # the ranked score's version and this episode's score (bench/score.py)
    row["wall_s"] = time.perf_counter() - t0
    return row


def _init_worker() -> None:
    """A worker ends quietly: Ctrl-C is the parent's to handle, SIGTERM (the parent's
    ``terminate``) just ends it, and on Linux it ends when the parent dies (no orphan
    left computing, no BrokenPipe traceback from writing to a parent that is gone)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        try:
            import ctypes  # noqa: PLC0415

            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def run_tasks(tasks: list[EpisodeTask], jobs: int = 1, progress: bool = True, desc: str = "bench",
              on_row: Callable[[dict], None] | None = None) -> list[dict]:
    """Rows of ``tasks`` in task order; ``jobs`` > 1 uses that many processes.

    ``on_row(row)`` is called for each row as it lands (in task order), e.g. to append it
    to a file at once so that a killed run keeps what it finished.
    """
    from tqdm import tqdm  # noqa: PLC0415

    bar = tqdm(total=len(tasks), desc=desc, file=sys.stderr, disable=not progress, unit="ep")
    rows: list[dict] = []

    def land(row: dict) -> None:
        rows.append(row)
        if on_row is not None:
            on_row(row)
        bar.update()

    try:
        if jobs <= 1 or len(tasks) <= 1:
            for task in tasks:
                land(run_episode(task))
        else:
            ctx = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
            with ctx.Pool(min(jobs, len(tasks)), initializer=_init_worker) as pool:  # exit: terminate()
                for row in pool.imap(run_episode, tasks, chunksize=1):
                    land(row)
    finally:
        bar.close()
    return rows
