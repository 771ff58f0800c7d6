"""Callbacks: evaluation on a fixed seed set, checkpoints that carry their training cost."""

from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback


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
        return self.offset_wall_s + time.perf_counter() - self.t0

    @property
    def cpu_s(self) -> float:
        return self.offset_cpu_s + self._own_cpu() - self.cpu0 + self._workers_cpu()

    def snapshot(self, env_steps: int) -> dict[str, Any]:
        return {"env_steps": int(env_steps), "wall_s": round(self.wall_s, 2), "cpu_s": round(self.cpu_s, 2)}


class SeededEvalCallback(EvalCallback):
    """:class:`EvalCallback` that re-seeds the evaluation env before every evaluation.

    Every evaluation then runs the same episodes (scenarios drawn from ``eval_seed``),
    so the curve compares policies, not scenario luck.
    """

    def __init__(self, eval_env, eval_seed: int, **kwargs: Any):
        super().__init__(eval_env, **kwargs)
        self.eval_seed = int(eval_seed)

    def _on_step(self) -> bool:
        if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0:
            self.eval_env.seed(self.eval_seed)
        return super()._on_step()


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
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(obj, indent=2, allow_nan=False) + "\n")
    os.replace(tmp, path)
