"""Throughput of the simulation: what ``addedinertia perf`` measures and writes.

One *step* is one sample period of one environment (``physics_substeps`` RK4 physics
steps, 2 for the presets), for both engines: :meth:`MujocoRig.step` on one rig, and
:meth:`BatchedRig.physics_step` on ``n`` rigs at once, which counts as ``n`` steps. The
drive is in current mode with a different current per environment, the hull free, the
default rig (``wigley-2m`` values, :class:`RigParams`). All figures come from one run on
one machine, so their ratio is meaningful even on a shared machine; each figure is the
best of a few repeats (as :mod:`timeit` advises: the minimum is the least disturbed).
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import time
import tracemalloc
from typing import Any, Callable

import numpy as np

from .rig.batched import CURRENT, BatchedRig
from .rig.motor import MotorCommand
from .rig.mujoco_rig import MujocoRig
from .rig.params import RigParams

DEFAULT_SIZES = tuple(4**k for k in range(8))  # 1, 4, ..., 16384


def machine() -> dict[str, Any]:
    """CPU model (``/proc/cpuinfo``), ``nproc``, load average, library versions."""
    model = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import mujoco  # noqa: PLC0415

    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    return {"cpu": model, "nproc": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
            "load_avg_1_5_15": [round(x, 2) for x in load], "python": platform.python_version(),
            "numpy": np.__version__, "mujoco": mujoco.__version__, "gpu": None}


def best_time(fn: Callable[[], None], calls: int, repeats: int) -> float:
    """Least wall time of ``repeats`` runs of ``calls`` calls of ``fn``, per call, s."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def _calls_for(fn: Callable[[], None], seconds: float) -> int:
    """How many calls of ``fn`` take about ``seconds`` (after one warm-up call)."""
    fn()
    t0 = time.perf_counter()
    fn()
    one = max(time.perf_counter() - t0, 1e-7)
    return max(3, int(seconds / one))


def measure_single(params: RigParams | None = None, seconds: float = 0.3, repeats: int = 5) -> dict[str, float]:
    """Steps per second of one :class:`MujocoRig` (current mode, hull free)."""
    rig = MujocoRig(params or RigParams(), seed=0)
    rig.reset(phi0=-0.1, brake=False)
    cmd = MotorCommand("current", 1.0)
    fn = lambda: rig.step(cmd)  # noqa: E731
    per_step = best_time(fn, _calls_for(fn, seconds), repeats)
    return {"steps_per_s": 1.0 / per_step, "time_per_step_us": per_step * 1e6}


def measure_batched(n: int, params: RigParams | None = None, dtype=np.float64, seconds: float = 0.3,
                    repeats: int = 5, sensors: bool = False) -> dict[str, float]:
    """Steps per second of a :class:`BatchedRig` of ``n`` environments (``n`` steps per call)."""
    rig = BatchedRig(params or RigParams(), n_envs=n, seed=0, dtype=dtype)
    rig.reset(phi0=-0.1, brake=False)
    current = np.linspace(-2.0, 2.0, n).astype(dtype)  # A, one current per environment
    fn = (lambda: rig.step(CURRENT, current)) if sensors else (lambda: rig.physics_step(CURRENT, current))
    per_call = best_time(fn, _calls_for(fn, seconds), repeats)
    if not np.all(np.isfinite(rig.phi)):
        raise RuntimeError(f"batched rig of {n} environments diverged during the measurement")
    return {"n_envs": n, "steps_per_s": n / per_call, "time_per_step_us": per_call * 1e6,
            "time_per_env_step_ns": per_call / n * 1e9, "bytes_per_env": rig.nbytes_per_env()}


def traced_bytes_per_env(n: int, params: RigParams | None = None, dtype=np.float64) -> float:
    """Peak Python-heap bytes (``tracemalloc``) per environment to build and step a batch."""
    tracemalloc.start()
    try:
        rig = BatchedRig(params or RigParams(), n_envs=n, seed=0, dtype=dtype)
        rig.reset(phi0=-0.1, brake=False)
        for _ in range(3):
            rig.step(CURRENT, np.ones(n, dtype=dtype))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak / n


def run_perf(sizes: tuple[int, ...] = DEFAULT_SIZES, seconds: float = 0.3, repeats: int = 5,
             progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The whole measurement: the MuJoCo baseline and the batched sweep, in one run."""
    say = progress or (lambda _msg: None)
    sizes = tuple(sorted(set(int(s) for s in sizes)))
    start = _dt.datetime.now(_dt.timezone.utc)
    info = machine()
    say(f"machine: {info['cpu']}, nproc {info['nproc']}, load {info['load_avg_1_5_15']}")
    single = measure_single(seconds=seconds, repeats=repeats)
    say(f"MujocoRig.step: {single['steps_per_s']:.4g} steps/s")
    sweep = []
    for n in sizes:
        row = measure_batched(n, seconds=seconds, repeats=repeats)
        sweep.append(row)
        say(f"batched n={n}: {row['steps_per_s']:.4g} steps/s, {row['time_per_step_us']:.1f} us per step")
    n_max = sizes[-1]
    top = sweep[-1]
    f32 = measure_batched(n_max, dtype=np.float32, seconds=seconds, repeats=repeats)
    say(f"batched float32 n={n_max}: {f32['steps_per_s']:.4g} steps/s")
    with_sensors = measure_batched(n_max, seconds=seconds, repeats=repeats, sensors=True)
    say(f"batched with sensors n={n_max}: {with_sensors['steps_per_s']:.4g} steps/s")
    single_after = measure_single(seconds=seconds, repeats=repeats)  # the baseline again, after the sweep
    baseline = max(single["steps_per_s"], single_after["steps_per_s"])
    traced = traced_bytes_per_env(n_max)
    info_end = machine()
    return {
        "single_env_steps_per_s": baseline,
        "batched_physics_steps_per_s": top["steps_per_s"],
        "n_envs": n_max,
        "ratio_batched_to_single": top["steps_per_s"] / baseline,
        "step_definition": "one sample period of one environment (physics_substeps RK4 steps, current mode)",
        "single_env": {"before_sweep": single, "after_sweep": single_after},
        "sweep": sweep,
        "float32": f32,
        "with_sensors": with_sensors,
        "memory": {"bytes_per_env_arrays": top["bytes_per_env"], "bytes_per_env_tracemalloc_peak": traced},
        "machine": {**info, "load_avg_at_end": info_end["load_avg_1_5_15"]},
        "date": start.strftime("%Y-%m-%d %H:%M UTC"),
        "seconds_per_measurement": seconds, "repeats": repeats,
    }
