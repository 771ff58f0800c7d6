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

from addedinertia_env.foundation.atomic import save_figure
from addedinertia_env.foundation.machine import cpu_model

import datetime as _dt
import os
import platform
import time
import tracemalloc
from typing import Any, Callable

import numpy as np

from addedinertia_env.sim.batched import CURRENT, BatchedRig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams

DEFAULT_SIZES = tuple(4**k for k in range(8))  # 1, 4, ..., 16384


def machine() -> dict[str, Any]:
    """CPU model (``/proc/cpuinfo``), ``nproc``, load average, library versions."""
    model = cpu_model()
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


def plot_time_vs_n(result: dict[str, Any], path: str) -> None:
    """Figure: time per batched step and per environment-step against the batch size."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    n = np.array([r["n_envs"] for r in result["sweep"]])
    t = np.array([r["time_per_step_us"] for r in result["sweep"]])
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.loglog(n, t, "o-", label="batched: time per step of the whole batch")
    ax.loglog(n, t / n, "s--", label="batched: time per environment-step")
    single = 1e6 / result["single_env_steps_per_s"]
    ax.axhline(single, color="k", lw=1, ls=":", label=f"MujocoRig.step ({single:.0f} us)")
    ax.set_xlabel("environments in the batch, n")
    ax.set_ylabel("wall time, us")
    ax.set_title(f"{result['machine']['cpu']}, nproc {result['machine']['nproc']}", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def _time_shares(shares: list[dict[str, float]]) -> str:
    """``sample 25 / 21 %, identify 34 / 32 %, ...``: each activity's share of the wall time in every
    process (shard 0 first), largest first."""
    names = sorted({k for sh in shares for k in sh}, key=lambda k: -sum(sh.get(k, 0.0) for sh in shares))
    return ", ".join(f"{k} " + " / ".join(f"{100 * sh.get(k, 0.0):.0f}" for sh in shares) + " %" for k in names)


KEPT = "<!-- kept below: written by hand, not by `addedinertia perf`, which keeps it when it rewrites the page -->"


def with_kept_part(text: str, old: str | None) -> str:
    """``text`` (a fresh report) followed by what ``old`` (the page it replaces, None if none) holds from the
    marker :data:`KEPT` on: the measured figures other commands made, with their commands."""
    if not old or KEPT not in old:
        return text
    return text.rstrip("\n") + "\n\n" + old[old.index(KEPT):]


def render_markdown(result: dict[str, Any], command: str, figure: str | None) -> str:
    """docs/PERFORMANCE.md from a :func:`run_perf` result: the machine and what a step is, the headline
    figures, how time grows with n (``figure``: the plot's path, or None), the whole task when it was
    measured, and what the batched rig is."""
    lines = _intro(result, command) + _headline(result) + _sweep(result, figure)
    if result.get("vector_task"):
        lines += _whole_task(result)
    return "\n".join(lines + _BATCHED_RIG)


def _intro(result: dict[str, Any], command: str) -> list[str]:
    """The page's title, the command and date, the machine and what one step is."""
    m = result["machine"]
    return [
        "# Performance of the simulation",
        "",
        f"Measured by `{command}` on {result['date']}. Every number below comes from that one run;",
        "re-run the command to refresh this page (it overwrites it).",
        "",
        f"**Machine**: {m['cpu']}, `nproc` = {m['nproc']} (CPU only), Python {m['python']}, numpy {m['numpy']},",
        f"MuJoCo {m['mujoco']}. Load average (1/5/15 min) at the start {m['load_avg_1_5_15']}, at the end",
        f"{m['load_avg_at_end']}: the machine is shared, so each figure is the best of {result['repeats']} repeats of",
        f"about {result['seconds_per_measurement']} s (the least disturbed one).",
        "",
        "**GPU**: no GPU machine was available for this work, so there are no GPU figures; the",
        "batched rig is numpy and numba-compiled loops on the CPU.",
        "",
        "**Step**: one sample period (1 ms at 1 kHz) of one environment = `physics_substeps` (2) RK4",
        "physics steps with the motor current update, for both engines. `MujocoRig.step` is one",
        "step; `BatchedRig.physics_step` on n environments is n steps. Drive in current mode",
        "(a different current per environment), hull free, default rig, float64 unless stated.",
        "",
    ]


def _headline(result: dict[str, Any]) -> list[str]:
    """The headline table: the single and batched rigs, memory, and the whole task when measured."""
    lines = [
        "## Headline",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| single MuJoCo environment (`MujocoRig.step`) | {result['single_env_steps_per_s']:,.0f} steps/s |",
        f"| batched physics, n = {result['n_envs']}, float64 | {result['batched_physics_steps_per_s']:,.0f} steps/s |",
        f"| ratio batched / single (same run) | {result['ratio_batched_to_single']:,.0f} x |",
        f"| batched physics, n = {result['n_envs']}, float32 | {result['float32']['steps_per_s']:,.0f} steps/s |",
        f"| batched physics + sensor readings, n = {result['n_envs']}, float64 | "
        f"{result['with_sensors']['steps_per_s']:,.0f} steps/s |",
        f"| memory per environment (state, work and parameter arrays) | "
        f"{result['memory']['bytes_per_env_arrays']:.0f} bytes |",
        f"| memory per environment (tracemalloc peak, build + 3 steps) | "
        f"{result['memory']['bytes_per_env_tracemalloc_peak']:.0f} bytes |",
    ]
    if "vector_env_samples_per_s" in result:
        w = result.get("vector_workers", 1)
        runs = next((r.get("repeat_samples_per_s") for r in result["vector_task"]["rows"]
                     if r.get("repeat_samples_per_s")), None)
        median_of = f", median of {len(runs)} runs" if runs and len(runs) > 1 else ""
        lines += [
            f"| whole task, batched vector env, n = {result['vector_n_envs']}, {w} process{'es' if w > 1 else ''}"
            f"{median_of} | "
            f"{result['vector_env_samples_per_s']:,.0f} samples/s ({result['vector_env_agent_steps_per_s']:,.0f} agent "
            f"steps/s); {result['vector_env_samples_per_cpu_s']:,.0f} per CPU-s |",
            f"| whole task, `gym.make_vec` sync | {result['sync_vector_env_samples_per_s']:,.0f} samples/s; "
            f"{result['sync_vector_env_samples_per_cpu_s']:,.0f} per CPU-s |",
            f"| ratio batched / `make_vec` sync (same run) | {result['vector_ratio_to_sync']:,.0f} x wall, "
            f"{result['vector_ratio_to_sync_per_cpu_s']:,.0f} x per CPU-s |",
            f"| whole task, batched, 1 process | {result['vector_env_samples_per_s_one_process']:,.0f} samples/s; "
            f"{result['vector_env_samples_per_cpu_s_one_process']:,.0f} per CPU-s |",
            f"| whole task, batched, 1 process, identification off | "
            f"{result['vector_env_samples_per_s_identification_off']:,.0f} samples/s; "
            f"{result['vector_env_samples_per_cpu_s_identification_off']:,.0f} per CPU-s |",
        ]
    return lines


def _sweep(result: dict[str, Any], figure: str | None) -> list[str]:
    """How the time per step grows with the number of environments (table, comment, ``figure``)."""
    lines = [
        "",
        "The single-environment figure is the better of two measurements, before and after the",
        f"sweep ({result['single_env']['before_sweep']['steps_per_s']:,.0f} and "
        f"{result['single_env']['after_sweep']['steps_per_s']:,.0f} steps/s).",
        "",
        "## How time grows with the number of environments",
        "",
        "| n | steps/s | time per batch step (us) | time per env-step (ns) | bytes per env |",
        "|---:|---:|---:|---:|---:|",
    ]
    for r in result["sweep"]:
        lines.append(f"| {r['n_envs']} | {r['steps_per_s']:,.0f} | {r['time_per_step_us']:,.1f} | "
                     f"{r['time_per_env_step_ns']:,.1f} | {r['bytes_per_env']:.0f} |")
    lines += [
        "",
        "Up to a few hundred environments the time per batch step is flat "
        f"({result['sweep'][0]['time_per_step_us']:,.1f} us at n = {result['sweep'][0]['n_envs']}): it is the fixed cost",
        "of the Python and array calls of one step, whatever n. Beyond that it grows linearly with n, and the",
        "time per environment-step levels off at the cost of the per-environment arithmetic.",
        "",
    ]
    if figure:
        lines += [f"![time per step against n]({figure})", ""]
    return lines


def _whole_task(result: dict[str, Any]) -> list[str]:
    """The whole task: single env, ``gym.make_vec`` sync and the batched vector env, the identification's
    cost, where the time went and the figures against the targets."""
    vec = result["vector_task"]
    rows = vec["rows"]
    lines = ["## The whole task: single env, `gym.make_vec` and the batched vector env", "",
             "`AddedInertia/ReverseStroke-v0` with `action_repeat` = "
             f"{vec['action_repeat']} (the agent at 100 Hz on the 1 kHz rig), actions from a",
             "fixed random policy (uniform in [-0.3, 0.3]), domain randomisation on. A *sample* is one",
             "rig sample of one environment under the agent's command; settle, free strokes, resets and",
             "the end-of-episode identification (energy method, the accuracy reward) are in the time but",
             "not counted as samples. Single env and `make_vec` sync are timed from `reset`; the batched",
             "env after its first reset and a warm-up (the first episodes all start together), so",
             "the window holds autoresets and identifications at their steady rate.", "",
             "| engine | n envs | samples/s (wall) | agent steps/s (wall) | samples per CPU-s | episodes ended | wall s | CPU s |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        lines.append(f"| {row['kind']} | {row['n_envs']} | {row['samples_per_s']:,.0f} | "
                     f"{row['agent_steps_per_s']:,.0f} | {row['samples_per_cpu_s']:,.0f} | {row['episodes_ended']} | "
                     f"{row['wall_s']:.1f} | {row['cpu_s']:.1f} |")
    head, b, e = rows[2], rows[-2], rows[-1]  # headline, one process, one process without identification
    per_episode = b["samples"] / max(b["episodes_ended"], 1)
    ident_ms = (b["cpu_s"] / b["samples"] - e["cpu_s"] / e["samples"]) * per_episode * 1e3
    lines += _identification_cost(b, e, per_episode, ident_ms)
    lines += _run_notes(result, head)
    return lines + _against_the_targets(result, head, b, e, per_episode, ident_ms)


def _identification_cost(b: dict[str, Any], e: dict[str, Any], per_episode: float, ident_ms: float) -> list[str]:
    """What the end-of-episode identification costs: the one-process rows with it (``b``) and without (``e``)."""
    return ["", "Per CPU-second (`time.process_time`, summed over the worker processes) the figures do not depend",
            "on what else the machine runs; the wall figures do (load average above).", "",
            f"The end-of-episode identification (the energy method on each finished record, for the accuracy",
            f"reward and the episode's score, plus the episode's record and metrics) costs about {ident_ms:,.1f} CPU-ms",
            "per episode here (the difference of the two one-process rows, per episode); with it off",
            f"(`score_episodes=False`, accuracy weight 0) the rest of the task runs at {e['samples_per_cpu_s']:,.0f}",
            f"samples per CPU-second. An episode has about {per_episode:,.0f} controlled samples."]


def _run_notes(result: dict[str, Any], head: dict[str, Any]) -> list[str]:
    """The headline row (``head``): the ratio to ``make_vec`` sync, where its time went, its repeats, the error."""
    lines = ["", f"Batched / `make_vec` sync = **{result['vector_ratio_to_sync']:,.0f} x** wall "
             f"({result['vector_ratio_to_sync_per_cpu_s']:,.0f} x per CPU-second; same run). The headline row's",
             f"first reset ({head['n_envs']} free strokes at once) took {head['reset_s']:.1f} s; its timed window used "
             f"{head['cpu_s']:.1f} CPU-s in {head['wall_s']:.1f} s of wall time; {head['episodes_per_s']:.0f} episodes "
             "ended per second."]
    if head.get("time_shares"):
        lines += ["", "Where the headline row's wall time went, per process (" + _time_shares(head["time_shares"])
                  + "; `StepClock` in `vector/shards.py`). *wait* is a process blocked until another answers: "
                  "the step waits for the slower shard; *spares* and *fits* are the spare episodes' starts and "
                  "stroke fits, done while a process would otherwise wait."]
    if head.get("repeat_samples_per_s") and len(head["repeat_samples_per_s"]) > 1:
        lines += [f"The headline row is the median of {len(head['repeat_samples_per_s'])} runs, each from a fresh "
                  "env: " + ", ".join(f"{v:,.0f}" for v in head["repeat_samples_per_s"])
                  + " samples/s (the run-to-run spread on this machine)."]
    median = head.get("median_abs_rel_error")
    if isinstance(median, float) and np.isfinite(median):
        lines += [f"Median |rel_error| under the random policy: {100 * median:.2f} %."]
    return lines


def _against_the_targets(result: dict[str, Any], head: dict[str, Any], b: dict[str, Any], e: dict[str, Any],
                         per_episode: float, ident_ms: float) -> list[str]:
    """The whole task against its targets (1 M samples/s, 100 x ``make_vec`` sync), and why the processes wait."""
    speed_met = result["vector_env_samples_per_s"] >= 1e6
    ratio_met = result["vector_ratio_to_sync"] >= 100
    return ["", "**Against the targets** (whole task with identification, n = 1024, same run): 1 M samples/s "
            f"**{'met' if speed_met else 'not met'}** ({result['vector_env_samples_per_s']:,.0f} samples/s wall); "
            f"100 x `make_vec` sync **{'met' if ratio_met else 'not met'}** "
            f"({result['vector_ratio_to_sync']:,.0f} x; the sync figure itself moves by about 10 % between runs on "
            f"this machine). In {head.get('workers', 1)} process(es) the wall figure is at most "
            f"{head.get('workers', 1)} x the per-CPU-second one ({head['samples_per_cpu_s']:,.0f}); here the processes "
            f"kept {head['cpu_s'] / head['wall_s']:.1f} cores busy: every step waits for the slower shard. The shards "
            "share the identification of the episodes that ended in a step (records move to the shard with less "
            "to do), but a record is identified in one piece, so in a step where an odd number of episodes "
            "ended (" + (f"{100 * head['odd_end_steps_frac']:.0f} % of the timed steps" if "odd_end_steps_frac" in head
                         else "about half the steps") + ") one process waits for the other's last record; the "
            "shards' sampling halves also differ from step to step (the records of the ended episodes; the "
            "spare starts and the stroke fits at the free strokes' stops run while a process waits, as far as "
            "it waits), "
            "and other jobs on the machine take turns (load average above). "
            + (f"Per sample the {head.get('workers', 1)} processes used "
               f"{abs(100 * (b['samples_per_cpu_s'] / head['samples_per_cpu_s'] - 1)):.0f} % "
               f"{'more' if b['samples_per_cpu_s'] > head['samples_per_cpu_s'] else 'less'} CPU than one: each "
               "shard pays the fixed cost of the Python and array calls of every rig sample, whatever its number "
               "of slots, and the parent process, which steps shard 0 itself (2.5 % fewer environments than "
               "the others), also relays the other shards' actions, results and moved records. "
               if head.get("workers", 1) > 1 else "")
            + "Per episode "
            f"the identification ({ident_ms:,.1f} CPU-ms) costs "
            f"{'more' if ident_ms > per_episode / e['samples_per_cpu_s'] * 1e3 else 'less'} than stepping its "
            f"{per_episode:,.0f} samples ({per_episode / e['samples_per_cpu_s'] * 1e3:,.1f} CPU-ms): per sample, "
            f"{1e6 / e['samples_per_cpu_s']:.2f} CPU-us of stepping (settle, free strokes, resets included) and "
            f"{ident_ms * 1e3 / per_episode:.2f} CPU-us of end-of-episode work; 1 M samples/s on "
            f"{head.get('workers', 1)} cores needs at most {head.get('workers', 1):g} CPU-us per sample all in with "
            f"every core busy all the time, {head['cpu_s'] / head['wall_s']:.1f} CPU-us at the "
            f"{head['cpu_s'] / head['wall_s']:.1f} cores kept busy here, against "
            f"{1e6 / head['samples_per_cpu_s']:.2f} CPU-us measured in the headline row.", "",
            "`gym.make_vec(\"AddedInertia/ReverseStroke-v0\", num_envs=N)` gives the batched env (its",
            "`vector_entry_point`; `workers=W` runs it in W processes: shard 0 in the calling one, the others in",
            "workers); `vectorization_mode=\"sync\"` gives N single",
            "envs.", "",
            "**GPU / torch backend**: none. No GPU machine was available to this work, and a torch backend that",
            "was never run on a GPU would be an untested claim, so there is none; the batched env is numpy and",
            "numba-compiled loops on the CPU.", ""]


_BATCHED_RIG = [  # the page's last section: what the batched rig is and how it is tested
    "## What the batched rig is",
    "",
    "`addedinertia_env/sim/batched.py`: the same forces (`sim/forces.py`) and motor update",
    "(`sim/motor.py`) as the MuJoCo rig, integrated by the same RK4 scheme with the spring",
    "and the mass matrix inside the stages. With the extra torques held over a physics step",
    "that step is linear in the state, so it is applied as one matrix per kind of step,",
    "found by running the plain step (`reference_substep`) on unit vectors. Tests",
    "(`tests/test_batched.py`) hold it to the MuJoCo rig: state trajectories agree within",
    "1e-9 rad (float64) for passive, current-mode and voltage-mode inputs with every hidden",
    "effect on, and within 1e-4 rad in float32. A brake set while the hull moves at rate w0",
    "differs by up to w0 x physics_dt in phi (MuJoCo's brake is a stiff spring-damper",
    "constraint; the batched brake holds exactly).",
    "",
]
