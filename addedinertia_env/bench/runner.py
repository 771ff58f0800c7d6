"""Run benchmark episodes: ``EpisodeTask -> row`` (one JSON line), locally in processes.

A row holds at least: controller, suite, scenario, seed, lambda66_true, lambda66_est,
rel_error, energy_J, tracking_rms_rad, saturated_frac, wall_s, version (and commit).
``lambda66_est`` comes from ``identify([record], "energy")``; ``lambda66_true`` from the
scenario's own parameters (scoring only). A run or identification that fails gives a
row with ``rel_error: null`` and the reason in ``failure``.

Controllers that learn across cycles (``BENCH_CYCLES`` > 1, e.g. ILC) run that many
episodes of the scenario, each with fresh sensor noise, keeping their state; only the
last cycle is scored. All others run one episode.
"""

from __future__ import annotations

import functools
import json
import math
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from .. import __version__
from ..experiment.runner import run_experiment
from ..identify import identify
from ..record import RunRecord
from ..rig.mujoco_rig import MujocoRig
from .suites import EpisodeTask

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


class _TrackingProbe:
    """Passes through to the controller; records the reverse stroke's tracking error (rad)."""

    def __init__(self, inner: Any):
        self.inner = inner
        self.errors: list[float] = []

    def reset(self, context: Any) -> None:
        self.layout = context.layout
        self.errors = []
        if hasattr(self.inner, "reset"):
            self.inner.reset(context)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(observation, dtype=float).reshape(-1)
        if self.layout.get(obs, "is_reverse") > 0.5:
            self.errors.append(self.layout.get(obs, "tracking_error"))
        return self.inner.predict(observation, state, episode_start, deterministic)


def electric_energy(rec: RunRecord) -> float:
    """Integral of ``|u i|`` over the hold and the reverse stroke, J (measured channels)."""
    t, u, i = rec.t, rec["u"], rec["i"]
    controlled = np.isin(rec.phase, ("hold", "reverse"))
    dt = np.diff(t, prepend=t[0])
    return float(np.sum(np.abs(u * i)[controlled] * dt[controlled]))


def saturated_fraction(rec: RunRecord) -> float:
    """Fraction of reverse-stroke samples whose current command is at the limit."""
    rev = rec.phase == "reverse"
    if not rev.any():
        return 0.0
    return float(np.mean(np.abs(rec["i_cmd"][rev]) >= 0.999 * rec.known.current_limit))


def cycle_seed(scenario, k: int) -> np.random.SeedSequence:
    """Sensor-noise seed of cycle ``k`` of a scenario (a child of the scenario's sensor seed)."""
    ss = scenario.sensor_seed
    return np.random.SeedSequence(entropy=ss.entropy, spawn_key=(*ss.spawn_key, k))


def run_episode(task: EpisodeTask) -> dict[str, Any]:
    """One benchmark row (see module doc)."""
    from agents import make_controller  # noqa: PLC0415 - agents depends on this package

    t0 = time.perf_counter()
    sc = task.scenario
    truth = sc.rig.hull.lambda66  # scoring only
    row: dict[str, Any] = {
        "controller": task.controller, "suite": task.suite, "split": task.split, "scenario": sc.name,
        "seed": sc.seed, "preset": task.preset, "sensor_quality": sc.sensor_quality,
        "hold_s": sc.plan.hold_s, "alpha": sc.plan.alpha, "lambda_ratio": truth / sc.rig.hull.J_hull,
        "lambda66_true": truth, "lambda66_est": None, "ci95": None, "rel_error": None, "abs_rel_error": None,
        "energy_J": None, "tracking_rms_rad": None, "saturated_frac": None, "cycles": 1, "failure": None,
        "controller_kwargs": task.controller_kwargs, "version": __version__, "commit": git_commit(),
    }
    try:
        controller = make_controller(task.controller, **task.controller_kwargs)
        for key in ("train_env_steps", "train_cpu_minutes"):  # learned policies: training cost (OnnxPolicy)
            if getattr(controller, key, None) is not None:
                row[key] = getattr(controller, key)
        cycles = max(1, int(getattr(controller, "BENCH_CYCLES", 1)))
        row["cycles"] = cycles
        probe = _TrackingProbe(controller)
        for k in range(cycles):
            rig = MujocoRig(sc.rig, seed=cycle_seed(sc, k))
            rec = run_experiment(rig, probe, sc.plan, run_id=f"{sc.name}/cycle-{k}")
        row["energy_J"] = electric_energy(rec)
        row["saturated_frac"] = saturated_fraction(rec)
        row["tracking_rms_rad"] = float(np.sqrt(np.mean(np.square(probe.errors)))) if probe.errors else None
        result = identify([rec], "energy")
        est = float(result.lambda66)
        if not math.isfinite(est):
            raise ValueError("identification returned a non-finite lambda66")
        row.update(lambda66_est=est, ci95=[float(x) for x in result.ci95], rel_error=est / truth - 1.0,
                   abs_rel_error=abs(est / truth - 1.0))
    except Exception as e:  # noqa: BLE001 - any failure of one episode is that episode's result
        row["failure"] = f"{type(e).__name__}: {e}"
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


def write_rows(rows: Iterable[dict], path: str | Path) -> Path:
    """JSON lines, written atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        for row in rows:
            f.write(json.dumps(_finite(row), allow_nan=False) + "\n")
    os.replace(tmp, path)
    return path


def _finite(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x
