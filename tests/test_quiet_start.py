"""Quiet, quick start (issue 31): packaging without warnings, compiled kernels cached on disk
(a second interpreter loads them, with identical results), no tracebacks at interpreter exit
from an environment left open, and the ``plot`` render mode redrawing only what changed."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _python(code: str, env: dict | None = None, cwd: Path | None = None, timeout: float = 600):
    full = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
    return subprocess.run([sys.executable, "-c", code], cwd=cwd or ROOT, env=full, capture_output=True, text=True,
                          timeout=timeout)


def test_packaging_metadata_without_warnings(tmp_path):
    """What pip runs first on `pip install -e .` (make demo, make test): no deprecation warnings."""
    for name in ("pyproject.toml", "README.md"):
        (tmp_path / name).write_bytes((ROOT / name).read_bytes())
    for name in ("addedinertia_env", "agents", "hw_adapter"):
        (tmp_path / name).symlink_to(ROOT / name)
    (tmp_path / "meta").mkdir()
    proc = _python("import warnings; warnings.simplefilter('always')\n"
                   "from setuptools import build_meta\n"
                   "print(build_meta.prepare_metadata_for_build_wheel('meta'))", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Warning" not in proc.stderr, proc.stderr[-3000:]
    meta = next((tmp_path / "meta").glob("*.dist-info")) / "METADATA"
    assert "License-Expression: MIT" in meta.read_text()
    sources = next((tmp_path / "meta").glob("*.egg-info")) / "SOURCES.txt"
    assert "addedinertia_env/data/textbook/textbook_roll_decay.csv" in sources.read_text()  # the data ship


KERNEL_RUN = """
import json, numpy as np
from addedinertia_env.records import scan_kernels as s
x = np.repeat(np.arange(50.0), 3); x[7] = np.nan; x[8] = np.nan
out = s.value_change_starts(x)
stats = [s.value_change_starts.stats]
print(json.dumps({"result": out.tolist(), "hits": sum(sum(st.cache_hits.values()) for st in stats),
                  "misses": sum(sum(st.cache_misses.values()) for st in stats),
                  "path": s.value_change_starts._cache._cache_path}))
"""


def test_compiled_kernels_are_cached_and_give_identical_results(tmp_path):
    cache = tmp_path / "numba-cache"
    first = _python(KERNEL_RUN, env={"NUMBA_CACHE_DIR": str(cache)})
    second = _python(KERNEL_RUN, env={"NUMBA_CACHE_DIR": str(cache)})
    assert first.returncode == 0 and second.returncode == 0, (first.stderr[-2000:], second.stderr[-2000:])
    a, b = json.loads(first.stdout), json.loads(second.stdout)
    assert a["misses"] >= 1 and a["hits"] == 0  # compiled, written to the cache
    assert b["hits"] >= 1 and b["misses"] == 0  # loaded from it
    assert a["result"] == b["result"]
    assert list(cache.rglob("*.nbi")), "no cache index written"


def test_the_default_cache_folder_is_writable():
    """Numba writes beside the sources (__pycache__), else in a per-user folder; either must be writable."""
    proc = _python("from addedinertia_env.records import scan_kernels as s; print(s.value_change_starts._cache._cache_path)",
                   env={"NUMBA_CACHE_DIR": ""})
    path = Path(proc.stdout.strip())
    assert proc.returncode == 0 and path.is_dir() and os.access(path, os.W_OK), (path, proc.stderr[-1000:])


def test_an_env_left_open_exits_without_tracebacks():
    code = ("import gymnasium as gym, addedinertia_env\n"
            "env = gym.make('AddedInertia/ReverseStroke-v0', render_mode='rgb_array', action_repeat=10)\n"
            "env.reset(seed=0)\n"
            "try:\n"
            "    frame = env.render()\n"
            "except RuntimeError as e:\n"
            "    print('NO-GL', e)\n"
            "else:\n"
            "    print('FRAME', frame.shape)\n")  # the env is never closed
    proc = _python(code, env={"MUJOCO_GL": "egl", "EGL_PLATFORM": "surfaceless"})
    if "NO-GL" in proc.stdout:
        pytest.skip(f"no OpenGL backend here: {proc.stdout.strip()[:200]}")
    assert proc.returncode == 0 and "FRAME (360, 480, 3)" in proc.stdout, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr[-3000:]


def test_plot_mode_redraws_the_figure_only_when_the_axes_grow(monkeypatch):
    import gymnasium as gym

    import addedinertia_env  # noqa: F401
    from addedinertia_env.envs.render import PlotRenderer, plot_frame

    env = gym.make("AddedInertia/ReverseStroke-v0", render_mode="plot", action_repeat=50, hold_s=0.2,
                   fixed={"period_s": 3.0})
    env.reset(seed=0)
    frames, full_draws = [], []
    original = PlotRenderer._grow_limits

    def counting(self, t, series):
        changed = original(self, t, series)
        full_draws.append(changed)
        return changed

    monkeypatch.setattr(PlotRenderer, "_grow_limits", counting)
    while True:
        _, _, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
        frames.append(env.render())
        if terminated or truncated:
            break
    record = env.unwrapped.experiment.record()
    env.close()
    assert len(frames) >= 20
    assert sum(full_draws) <= len(frames) // 3, f"{sum(full_draws)} full redraws for {len(frames)} frames"
    last = frames[-1]
    assert last.shape == plot_frame(record).shape and last.dtype == np.uint8
    # the curves are drawn: the last frame holds far more black pixels than the first
    dark = [int((f.max(axis=2) < 60).sum()) for f in (frames[0], last)]
    assert dark[1] > dark[0] + 200, dark


@pytest.mark.slow
def test_a_second_start_of_the_vector_env_is_fast_and_identical(tmp_path):
    """gym.make_vec(num_envs=8) and its first reset in two fresh interpreters sharing one empty
    numba cache folder: the second loads the kernels the first compiled."""
    code = ("import time, json, numpy as np, gymnasium as gym, addedinertia_env\n"
            "c0 = time.process_time()\n"
            "envs = gym.make_vec('AddedInertia/ReverseStroke-v0', num_envs=8)\n"
            "obs, _ = envs.reset(seed=0)\n"
            "for _ in range(20):\n"
            "    obs, *_ = envs.step(np.zeros((8, 1), np.float32))\n"
            "print(json.dumps({'cpu_s': time.process_time() - c0, 'obs': obs.astype(float).tolist()}))\n"
            "envs.close()\n")
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    t0 = time.perf_counter()
    first = _python(code, env=env)
    t1 = time.perf_counter()
    second = _python(code, env=env)
    assert first.returncode == 0 and second.returncode == 0, (first.stderr[-2000:], second.stderr[-2000:])
    a, b = json.loads(first.stdout), json.loads(second.stdout)
    assert a["obs"] == b["obs"]  # bit for bit: the cached kernels are the compiled ones
    assert b["cpu_s"] < a["cpu_s"] / 3, (a["cpu_s"], b["cpu_s"], t1 - t0)
