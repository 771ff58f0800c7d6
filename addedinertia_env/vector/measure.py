"""Throughput of the whole task: the batched vector env against ``gym.make_vec`` and one env.

A *sample* is one rig sample (1 ms at 1 kHz) of one environment under the agent's
command (hold or reverse stroke); an *agent step* is ``action_repeat`` samples. The
settle, free strokes, resets and end-of-episode identification are not counted as
samples but their time is in the wall time (and CPU time, :func:`time.process_time`, given
beside it: on a shared machine the wall time also holds other jobs' turns). Same task options and the same random
policy (uniform actions in [-0.3, 0.3]) for every engine.

For the batched env, the clock starts after ``reset`` and a warm-up of ``warmup_steps``
agent steps (long enough for the first episodes, which all start together, to spread
out; its episodes are not identified, to save time); the measured window then holds
autoresets and identifications at their steady rate. ``gym.make_vec`` (sync) and the single env are timed from ``reset`` on, for
``seconds`` of wall time each (their resets are part of every episode).
"""

from __future__ import annotations

import os
import time
from typing import Any, Callable

import gymnasium as gym
import numpy as np

ENV_ID = "AddedInertia/ReverseStroke-v0"


def _policy(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(-0.3, 0.3, size=(n, 1)).astype(np.float32)


def measure_batched(num_envs: int = 1024, steps: int = 300, warmup_steps: int = 400, action_repeat: int = 10,
                    seed: int = 0, score_episodes: bool = True, workers: int = 1, **env_kwargs: Any) -> dict[str, Any]:
    """Samples and agent steps per second of ``gym.make_vec`` (the batched vector env, in ``workers``
    processes); with ``score_episodes=False`` (and the accuracy reward off) without the end-of-episode
    identification. CPU time is this process's plus the workers'."""
    if not score_episodes:
        env_kwargs = {**env_kwargs, "score_episodes": False, "reward_weights": {"accuracy": 0.0}}
    env = gym.make_vec(ENV_ID, num_envs=num_envs, action_repeat=action_repeat, workers=workers, **env_kwargs)
    workers_cpu = getattr(env.unwrapped, "worker_cpu_s", lambda: 0.0)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    env.reset(seed=seed)
    reset_s = time.perf_counter() - t0
    scored = env.unwrapped.score_episodes
    env.unwrapped.score_episodes = False  # the warm-up only spreads the episodes out: no identification
    for _ in range(warmup_steps):
        env.step(_policy(rng, num_envs))
    env.unwrapped.score_episodes = scored
    ended = odd = 0
    rel = []
    step_clock = getattr(env.unwrapped, "step_clock", None)  # the sharded env: where each process's time goes
    if step_clock is not None:
        step_clock(True)
    t0 = time.perf_counter()
    cpu0 = time.process_time() + workers_cpu()
    for _ in range(steps):
        _, _, term, trunc, info = env.step(_policy(rng, num_envs))
        odd += int(term.sum()) % 2  # steps whose ended episodes cannot be split evenly between 2 processes
        if term.any():
            ended += int(term.sum())
            if "rel_error" in info:  # scored episodes only
                rel.extend(np.abs(info["rel_error"][term]).tolist())
    wall = time.perf_counter() - t0
    cpu = time.process_time() + workers_cpu() - cpu0
    shares = clocked = None
    if step_clock is not None:  # fractions of each process's clocked time (about the wall time), shard 0 first
        counted = step_clock(False)
        clocked = [sum(seconds.values()) for seconds in counted]
        shares = [{k: v / total for k, v in sorted(seconds.items())} for seconds, total in zip(counted, clocked)]
    env.close()
    agent_steps = num_envs * steps
    kind = (f"batched (gym.make_vec), {workers} process" + ("es" if workers > 1 else "")
            + ("" if score_episodes else ", identification off"))
    return {"kind": kind, "n_envs": num_envs, "action_repeat": action_repeat, "workers": workers,
            "agent_steps": agent_steps, "samples": agent_steps * action_repeat, "wall_s": wall, "cpu_s": cpu,
            "samples_per_s": agent_steps * action_repeat / wall, "agent_steps_per_s": agent_steps / wall,
            "samples_per_cpu_s": agent_steps * action_repeat / cpu,
            "episodes_ended": ended, "episodes_per_s": ended / wall, "reset_s": reset_s,
            "odd_end_steps_frac": odd / steps, "time_shares": shares, "clocked_s": clocked,
            "warmup_steps": warmup_steps,
            "median_abs_rel_error": float(np.nanmedian(rel)) if rel and np.isfinite(rel).any() else float("nan"),
            "failed_estimates": int(np.sum(~np.isfinite(rel))) if rel else 0}


def measure_loop(make: Callable[[], Any], n: int, kind: str, seconds: float, action_repeat: int,
                 seed: int = 0) -> dict[str, Any]:
    """Samples per second of a Gymnasium env (n = 1) or vector env stepped for ``seconds`` from reset."""
    env = make()
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    env.reset(seed=seed)
    steps = ended = 0
    while steps < 3 or time.perf_counter() - t0 < seconds:  # at least a few steps after the reset
        a = _policy(rng, n)
        _, _, term, trunc, _ = env.step(a if n > 1 else a[0])
        steps += 1
        done = np.atleast_1d(term) | np.atleast_1d(trunc)
        ended += int(done.sum())
        if n == 1 and done[0]:
            env.reset()
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    env.close()
    return {"kind": kind, "n_envs": n, "action_repeat": action_repeat, "agent_steps": steps * n,
            "samples": steps * n * action_repeat, "wall_s": wall, "cpu_s": cpu,
            "samples_per_s": steps * n * action_repeat / wall, "samples_per_cpu_s": steps * n * action_repeat / cpu,
            "agent_steps_per_s": steps * n / wall, "episodes_ended": ended}


def default_workers() -> int:
    """Processes for the batched env in ``perf``: one per CPU core this process may use, at most 2
    (the machine the targets are stated for has 2 cores)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(2, cores))


def median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The run of ``runs`` (rows of :func:`measure_batched`) whose samples per second is the median
    (the lower middle one for an even count), with every run's figure in ``repeat_samples_per_s``."""
    ranked = sorted(runs, key=lambda r: r["samples_per_s"])
    row = dict(ranked[(len(ranked) - 1) // 2])
    row["repeat_samples_per_s"] = [r["samples_per_s"] for r in runs]
    return row


def measure_vector_task(num_envs: int = 1024, steps: int = 300, warmup_steps: int = 400, sync_envs: int = 8,
                        seconds: float = 20.0, action_repeat: int = 10, workers: int | None = None,
                        progress: Callable[[str], None] | None = None, repeats: int = 1) -> dict[str, Any]:
    """The engines on the same task in one run; the keys of ``addedinertia perf --json``.

    Rows: one env, ``gym.make_vec`` sync, the batched env in ``workers`` processes (the
    headline: the median of ``repeats`` runs, each from a fresh env), in one process, and in one
    process without the end-of-episode identification.
    """
    say = progress or (lambda _m: None)
    workers = default_workers() if workers is None else workers
    single = measure_loop(lambda: gym.make(ENV_ID, action_repeat=action_repeat), 1,
                          "single env (gym.make, MujocoRig)", seconds, action_repeat)
    say(f"single env: {single['samples_per_s']:,.0f} samples/s")
    sync = measure_loop(lambda: gym.make_vec(ENV_ID, num_envs=sync_envs, vectorization_mode="sync",
                                             action_repeat=action_repeat),
                        sync_envs, "gym.make_vec sync (MujocoRig)", seconds, action_repeat)
    say(f"gym.make_vec sync n={sync_envs}: {sync['samples_per_s']:,.0f} samples/s")
    rows = [single, sync]
    headline = None
    if workers > 1:
        runs = []
        for _ in range(repeats):
            runs.append(measure_batched(num_envs, steps, warmup_steps, action_repeat, workers=workers))
            say(f"batched n={num_envs}, {workers} processes: {runs[-1]['samples_per_s']:,.0f} samples/s, "
                f"{runs[-1]['samples_per_cpu_s']:,.0f} per CPU-s")
        headline = median_run(runs)
        rows.append(headline)
    one = measure_batched(num_envs, steps, warmup_steps, action_repeat)
    say(f"batched n={num_envs}, 1 process: {one['samples_per_s']:,.0f} samples/s, "
        f"{one['samples_per_cpu_s']:,.0f} per CPU-s, {one['episodes_per_s']:.0f} episodes/s")
    rows.append(one)
    engine = measure_batched(num_envs, steps, warmup_steps, action_repeat, score_episodes=False)
    say(f"batched n={num_envs}, 1 process, identification off: {engine['samples_per_s']:,.0f} samples/s, "
        f"{engine['samples_per_cpu_s']:,.0f} per CPU-s")
    rows.append(engine)
    best = headline if headline is not None else one  # the headline: all the machine's cores
    return {"vector_env_samples_per_s": best["samples_per_s"],
            "vector_env_samples_per_cpu_s": best["samples_per_cpu_s"],
            "vector_env_agent_steps_per_s": best["agent_steps_per_s"],
            "vector_workers": best["workers"],
            "vector_env_samples_per_s_one_process": one["samples_per_s"],
            "vector_env_samples_per_cpu_s_one_process": one["samples_per_cpu_s"],
            "vector_env_samples_per_s_identification_off": engine["samples_per_s"],
            "vector_env_samples_per_cpu_s_identification_off": engine["samples_per_cpu_s"],
            "sync_vector_env_samples_per_s": sync["samples_per_s"],
            "sync_vector_env_samples_per_cpu_s": sync["samples_per_cpu_s"],
            "vector_n_envs": num_envs,
            "vector_ratio_to_sync": best["samples_per_s"] / sync["samples_per_s"],
            "vector_ratio_to_sync_per_cpu_s": best["samples_per_cpu_s"] / sync["samples_per_cpu_s"],
            "vector_task": {"rows": rows, "action_repeat": action_repeat, "workers": workers}}
