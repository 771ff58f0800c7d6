"""Failures that say so (issue 31): `bench run` exits non-zero when episodes fail, says how
many and why on stderr, and a rerun retries the failed episodes; `deploy` that ran to its
end without identifying lambda66 says "complete, not identified: REASON" and exits 1."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from addedinertia_env.cli import main

BROKEN = '''
import numpy as np

class Broken:
    def reset(self, context):
        self.i_max = context.rig["i_max"]  # the rig is a KnownRig dataclass: TypeError

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        return np.zeros(1, dtype=np.float32), state

def make():
    return Broken()
'''

FIXED = '''
import numpy as np

class Fixed:
    def reset(self, context):
        self.ctx = context
        self.J = context.inertia_prior

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        obs = self.ctx.layout.decode(np.asarray(observation, dtype=float))
        if obs["is_reverse"] < 0.5:
            return np.zeros(1, dtype=np.float32), state
        torque = self.J * (100.0 * obs["tracking_error"] + 20.0 * obs["rate_error"])
        amps = -torque / self.ctx.rig.k_t
        return np.array([np.clip(amps / self.ctx.rig.i_max, -1.0, 1.0)], dtype=np.float32), state

def make():
    return Fixed()
'''


def _rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _install(folder: Path, name: str, text: str) -> None:
    (folder / f"{name}.py").write_text(text)
    sys.modules.pop(name, None)


def test_failed_episodes_exit_non_zero_with_the_reason_and_are_retried(tmp_path, monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(tmp_path))
    _install(tmp_path, "fh_ctrl", BROKEN)
    out = tmp_path / "rows.jsonl"
    argv = ["bench", "run", "--suite", "smoke", "--controller", "fh_ctrl:make", "--seeds", "2", "--jobs", "1",
            "--no-progress", "--out", str(out)]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "2 of 2 episode(s) failed" in err
    assert "TypeError" in err and "not subscriptable" in err  # the first reason, on stderr
    rows = _rows(out)
    assert len(rows) == 2 and all(r["rel_error"] is None and "TypeError" in r["failure"] for r in rows)

    # --allow-failures does not hide a controller that fails every episode
    assert main([*argv, "--allow-failures"]) == 1
    capsys.readouterr()

    _install(tmp_path, "fh_ctrl", FIXED)  # the user fixes the controller and runs the same command again
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "2 episode(s)" in err and "running them again" in err
    rows = _rows(out)
    assert [r["scenario"] for r in rows] == sorted(r["scenario"] for r in rows) and len(rows) == 2
    assert all(r["rel_error"] is not None and r["failure"] is None for r in rows)

    assert main(argv) == 0  # a third run: nothing failed, nothing to do
    assert "already there, running the other 0" in capsys.readouterr().err
    assert len(_rows(out)) == 2


class BangBang:
    """Full current against the tracking error on the reverse stroke: the drive sits at its
    limit, so the energy method rejects every boundary angle (current at its limit)."""

    def reset(self, context):
        self.ctx = context

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        obs = self.ctx.layout.decode(np.asarray(observation, dtype=float))
        if obs["is_reverse"] < 0.5:
            return np.zeros(1, dtype=np.float32), state
        return np.array([-np.sign(obs["tracking_error"]) or 1.0], dtype=np.float32), state


def make_bang_bang():
    return BangBang()


def test_deploy_that_did_not_identify_says_so_and_exits_1(tmp_path, capsys):
    from hw_adapter.loopback import spawn_bench_server  # noqa: PLC0415

    proc, url = spawn_bench_server("--fast", "--rig", "wigley-2m", "--seed", "4", "--once")
    try:
        status = main(["deploy", "--bench", url, "--controller", "test_failures_say_so:make_bang_bang",
                       "--lab", "wigley-2m", "--hold", "0.3", "--out", str(tmp_path)])
    finally:
        proc.wait(timeout=30)
    captured = capsys.readouterr()
    assert status == 1, captured
    assert "complete, not identified: " in captured.err
    assert "current at its limit" in captured.err  # the reason, not just the word
    assert "status complete, not identified" in captured.out
