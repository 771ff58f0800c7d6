"""Callbacks: evaluation on a fixed seed set, checkpoints that carry their training cost."""

from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback

from addedinertia_env.foundation.atomic import atomic_write_text

METRICS = ("rel_error", "energy_J", "tracking_rms_rad", "saturated_frac")  # the benchmark numbers of an episode


class TrainingClock:
    """Wall and CPU seconds spent on training, across resumes.

    CPU time is this process's (all threads, :func:`time.process_time`) plus its
    finished children (``RUSAGE_CHILDREN``) plus live ``SubprocVecEnv`` workers (read
    from ``/proc``), each counted from this clock's start; ``offset_*`` carry a resumed
    run's earlier cost.
    """

    def __init__(self, offset_wall_s: float = 0.0, offset_cpu_s: float = 0.0):
        self.offset_wall_s, self.offset_cpu_s = float(offset_wall_s), float(offset_cpu_s)
        self.t0 = time.perf_counter()
        self.cpu0 = self._own_cpu()
        self.workers: list[int] = []

    @staticmethod
    def _own_cpu() -> float:
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + children.ru_utime + children.ru_stime

    def _workers_cpu(self) -> float:
        total = 0.0
        tick = os.sysconf("SC_CLK_TCK")
        for pid in self.workers:
            try:
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue  # finished: already in RUSAGE_CHILDREN
            total += (int(fields[11]) + int(fields[12])) / tick  # utime, stime
        return total

    def watch(self, venv: Any) -> None:
        """Count the worker processes of a ``SubprocVecEnv`` while they run."""
        self.workers += [p.pid for p in getattr(venv, "processes", [])]

    @property
    def wall_s(self) -> float:
        """Wall seconds of training so far, resumed runs' earlier time included."""
        return self.offset_wall_s + time.perf_counter() - self.t0

    @property
    def cpu_s(self) -> float:
        """CPU seconds of training so far (this process, finished children, live workers), resumed runs' included."""
        return self.offset_cpu_s + self._own_cpu() - self.cpu0 + self._workers_cpu()

    def snapshot(self, env_steps: int) -> dict[str, Any]:
        """The cost so far as a JSON-ready dict: ``env_steps``, ``wall_s`` and ``cpu_s`` (s)."""
        return {"env_steps": int(env_steps), "wall_s": round(self.wall_s, 2), "cpu_s": round(self.cpu_s, 2)}


def episode_metrics(infos: list[dict[str, Any]], dones) -> list[dict[str, float]]:
    """The benchmark numbers of the episodes that ended in one vectorised step."""
    out = []
    for done, info in zip(dones, infos):
        if done and "rel_error" in info:
            row = {k: float(info[k]) for k in METRICS if k in info}
            row.update({f"reward_{k}": float(v) for k, v in (info.get("episode_reward_terms") or {}).items()})
            out.append(row)
    return out


# What each TensorBoard scalar of the project covers; written once to TensorBoard's text tab
# (``about/scalars``). |rel_error| is a fraction: 0.01 = 1 % of the true lambda66.
SCALARS_NOTE = (
    "episode/*: the TRAINING episodes that ended since the previous log line (one per rollout for PPO), "
    "means over them. episode/failure_rate: the fraction of those episodes whose lambda66 estimate failed "
    "(identification refused the record). episode/abs_rel_error and episode/rel_error: over the episodes "
    "WITH an estimate only (failures excluded: read them with failure_rate); |lambda66 estimate / truth - 1|, "
    "a fraction (0.01 = 1 %). episode/reward_<term>: every ended episode, failures included (a failure costs "
    "the accuracy term's maximum). eval/*: the deterministic EVALUATION episodes (eval.n_episodes on the "
    "fixed eval.seed) of each evaluation; eval/median_abs_rel_error over those with an estimate, "
    "eval/failure_rate the fraction without one."
)


def is_failure(row: dict[str, float]) -> bool:
    """Whether an ended episode's lambda66 estimate failed (no finite ``rel_error``)."""
    return not np.isfinite(row.get("rel_error", np.nan))


class EpisodeMetricsCallback(BaseCallback):
    """Training episodes' benchmark numbers to TensorBoard (``episode/abs_rel_error`` and
    ``episode/rel_error``, ``episode/energy_J``, ``episode/tracking_rms_rad``,
    ``episode/saturated_frac``, ``episode/reward_<term>``, ``episode/failure_rate``: means
    over the episodes that ended since the last log; :data:`SCALARS_NOTE` says which
    episodes each covers, and goes to TensorBoard's text tab as ``about/scalars``)."""

    def _on_training_start(self) -> None:
        self.logger.record("about/scalars", SCALARS_NOTE, exclude=("stdout", "log", "json", "csv"))

    def _on_step(self) -> bool:
        for row in episode_metrics(self.locals.get("infos", []), self.locals.get("dones", [])):
            self.logger.record_mean("episode/failure_rate", float(is_failure(row)))
            if not is_failure(row):
                self.logger.record_mean("episode/abs_rel_error", abs(row["rel_error"]))
            for key, value in row.items():
                if np.isfinite(value):
                    self.logger.record_mean(f"episode/{key}", value)
        return True


class SeededEvalCallback(EvalCallback):
    """:class:`EvalCallback` that re-seeds the evaluation env before every evaluation, and
    records the benchmark numbers of the evaluation episodes.

    Every evaluation then runs the same episodes (scenarios drawn from ``eval_seed``),
    so the curve compares policies, not scenario luck. Each evaluation appends one line
    to ``<log_path>/curve.jsonl``: agent steps, wall and CPU seconds so far (``clock``),
    mean reward, the median and mean ``|rel_error|`` (the benchmark metric, a fraction:
    0.01 = 1 %) over the episodes with an estimate, the failed ones (``failed``,
    ``failure_rate``), mean energy and tracking RMS of its episodes; the same go to
    TensorBoard under ``eval/``.
    """

    def __init__(self, eval_env, eval_seed: int, clock: "TrainingClock | None" = None, **kwargs: Any):
        super().__init__(eval_env, **kwargs)
        self.eval_seed = int(eval_seed)
        self.clock = clock
        self._episodes: list[dict[str, float]] = []

    def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        super()._log_success_callback(locals_, globals_)
        self._episodes += episode_metrics([locals_["info"]], [locals_["done"]])

    def _on_step(self) -> bool:
        evaluating = self.eval_freq > 0 and self.n_calls % self.eval_freq == 0
        if evaluating:
            self.eval_env.seed(self.eval_seed)
            self._episodes = []
        result = super()._on_step()
        if evaluating:
            self._record_curve()
        return result

    def _record_curve(self) -> None:
        rel = np.array([abs(e["rel_error"]) for e in self._episodes if "rel_error" in e])
        row: dict[str, Any] = {"timesteps": int(self.num_timesteps), "mean_reward": float(self.last_mean_reward),
                               "n_episodes": len(self._episodes)}
        if self.clock is not None:
            row.update(wall_s=round(self.clock.wall_s, 2), cpu_s=round(self.clock.cpu_s, 2))
        finite = rel[np.isfinite(rel)]
        row["failed"] = int(len(rel) - len(finite))
        row["failure_rate"] = row["failed"] / len(rel) if len(rel) else None
        if len(rel):
            self.logger.record("eval/failure_rate", row["failure_rate"])
        if len(finite):
            row["median_abs_rel_error"] = float(np.median(finite))
            row["mean_abs_rel_error"] = float(np.mean(finite))
            self.logger.record("eval/median_abs_rel_error", row["median_abs_rel_error"])
        for key in ("energy_J", "tracking_rms_rad", "saturated_frac"):
            values = [e[key] for e in self._episodes if np.isfinite(e.get(key, np.nan))]
            if values:
                row[f"mean_{key}"] = float(np.mean(values))
                self.logger.record(f"eval/mean_{key}", row[f"mean_{key}"])
        if self.log_path is not None:
            path = Path(self.log_path).parent / "curve.jsonl" if str(self.log_path).endswith("evaluations") \
                else Path(self.log_path) / "curve.jsonl"
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(path, "a") as fh:
                fh.write(json.dumps(row) + "\n")


class CostCheckpointCallback(CheckpointCallback):
    """:class:`CheckpointCallback` (model, VecNormalize, replay buffer) + ``cost_<N>_steps.json``.

    The JSON beside each checkpoint holds the cumulative environment steps, wall and CPU
    seconds, so ``--resume`` continues the training card's cost where it stopped.
    """

    def __init__(self, clock: TrainingClock, **kwargs: Any):
        super().__init__(**kwargs)
        self.clock = clock

    def _on_step(self) -> bool:
        result = super()._on_step()
        if self.n_calls % self.save_freq == 0:
            path = Path(self._checkpoint_path("cost_", extension="json"))
            write_json_atomic(path, self.clock.snapshot(self.num_timesteps))
        return result


def write_json_atomic(path: Path, obj: dict[str, Any]) -> None:
    """Write ``obj`` as indented strict JSON (no NaN) to ``path`` atomically, making its folder."""
    atomic_write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")
