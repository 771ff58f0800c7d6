"""`bench run` survives a kill: rows appended as they land, resumed with the same command,
never mixed with another run's rows, nothing left behind (addedinertia_env/bench/resume.py)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from addedinertia_env.cli import main

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["bench", "run", "--suite", "smoke", "--controller", "pd", "--no-progress"]
CLI = "import sys; from addedinertia_env.cli import main; sys.exit(main())"


def _rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _comparable(rows: list[dict]) -> list[dict]:
    """Rows without their wall-clock time (the only field a rerun may change)."""
    return [{k: v for k, v in r.items() if k not in ("wall_s", "command")} for r in rows]


def _start(out: Path, jobs: int) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-c", CLI, *ARGS, "--jobs", str(jobs), "--out", str(out)],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_rows(proc: subprocess.Popen, out: Path, n: int, timeout_s: float = 240.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if out.exists() and len(_rows(out)) >= n:
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"no {n} row(s) in {out} after {timeout_s} s")


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> list[dict]:
    out = tmp_path_factory.mktemp("whole") / "rows.jsonl"
    assert main([*ARGS, "--jobs", "1", "--out", str(out)]) == 0
    rows = _rows(out)
    assert len(rows) == 3
    return rows


def test_killed_run_resumes_to_the_same_rows(tmp_path, uninterrupted, capsys):
    out = tmp_path / "rows.jsonl"
    proc = _start(out, jobs=2)
    _wait_for_rows(proc, out, 1)
    proc.send_signal(signal.SIGKILL)  # the hardest kill: no handler runs
    proc.wait(timeout=30)
    kept = _rows(out)
    assert 1 <= len(kept) < 3 or len(kept) == 3
    with open(out, "a") as f:  # as if the kill had cut a line in half
        f.write('{"controller": "pd", "suite": "sm')
    assert main([*ARGS, "--jobs", "1", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "unfinished last line" in err
    if len(kept) < 3:
        assert "resuming" in err
    rows = _rows(out)
    assert [r["scenario"] for r in rows] == [r["scenario"] for r in uninterrupted]  # no duplicates, same order
    assert _comparable(rows) == _comparable(uninterrupted)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rows.jsonl"]  # nothing left behind


def test_sigterm_ends_a_parallel_run_quietly_and_keeps_its_rows(tmp_path, uninterrupted):
    out = tmp_path / "rows.jsonl"
    proc = _start(out, jobs=2)
    _wait_for_rows(proc, out, 1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (0, 130), err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    if proc.returncode == 130:
        assert "run the same command to resume" in err
    rows = _rows(out)
    n = len(rows)
    assert _comparable(rows) == _comparable(uninterrupted[:n])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rows.jsonl"]


def test_other_runs_rows_are_not_overwritten_unless_forced(tmp_path, uninterrupted, capsys):
    out = tmp_path / "rows.jsonl"
    out.write_text("".join(json.dumps(r) + "\n" for r in uninterrupted))
    argv = ["bench", "run", "--suite", "smoke", "--controller", "lqr", "--seeds", "1", "--jobs", "1",
            "--no-progress", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert str(out) in err and "--force" in err and "controller pd" in err
    assert _rows(out) == uninterrupted  # untouched
    assert main([*argv, "--force"]) == 0
    rows = _rows(out)
    assert len(rows) == 1 and rows[0]["controller"] == "lqr"


def test_a_finished_run_resumes_to_nothing(tmp_path, uninterrupted, capsys):
    out = tmp_path / "rows.jsonl"
    out.write_text("".join(json.dumps(r) + "\n" for r in uninterrupted))
    assert main([*ARGS, "--jobs", "1", "--out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    assert "3 of 3 episode(s) already there" in captured.err
    assert json.loads(captured.out)["rows"] == 3
    assert _rows(out) == uninterrupted
