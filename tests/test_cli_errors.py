"""One error path for the command line: every command, every kind of broken input, exit 2 and
one line naming the file; an unexpected exception is a bug report pointing to a log file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.cli.common import EXIT_BUG

NOT_UTF8 = b"\xff\xfe\x00garbage \xc3\x28\n"


def _one_line_error(capsys, argv: list[str], name: str | Path, status: int = 2) -> str:
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    assert rc == status, (rc, out)
    lines = [x for x in out.err.strip().splitlines() if "warning:" not in x and not x.startswith("bench:")]
    assert len(lines) == 1, out.err
    assert str(name) in lines[0], lines[0]
    assert "Traceback" not in out.err
    return lines[0]


def _onnx_identity(path: Path, n_in: int, n_out: int) -> Path:
    """A valid ONNX model of the wrong shape: a matrix (n_in -> n_out)."""
    import onnx
    from onnx import TensorProto, helper

    w = helper.make_tensor("w", TensorProto.FLOAT, [n_in, n_out], np.zeros(n_in * n_out, np.float32).tolist())
    node = helper.make_node("MatMul", ["obs", "w"], ["action"])
    graph = helper.make_graph([node], "wrong", [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", n_in])],
                              [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", n_out])], [w])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


@pytest.fixture
def broken(tmp_path, realistic_record_path) -> dict[str, Path]:
    """One broken file of each kind."""
    from addedinertia_env.experiment.task import OBSERVATION_FIELDS

    files = {}
    files["record"] = tmp_path / "bad.csv"
    files["record"].write_bytes(NOT_UTF8)
    (tmp_path / "bad.json").write_text(realistic_record_path.with_suffix(".json").read_text())
    files["yaml_bytes"] = tmp_path / "notutf8.yaml"
    files["yaml_bytes"].write_bytes(NOT_UTF8)
    files["yaml_syntax"] = tmp_path / "syntax.yaml"
    files["yaml_syntax"].write_text("a: [1, 2\nb: }\n")
    files["onnx_garbage"] = tmp_path / "garbage.onnx"
    files["onnx_garbage"].write_bytes(b"\x08\x01garbage" * 10)
    files["onnx_input"] = _onnx_identity(tmp_path / "wrong_input.onnx", 5, 1)
    files["onnx_output"] = _onnx_identity(tmp_path / "wrong_output.onnx", len(OBSERVATION_FIELDS), 3)
    files["rows"] = tmp_path / "rows.jsonl"
    files["rows"].write_text('{"controller": "x"}\nnot json\n')
    files["amplitudes"] = tmp_path / "amps.csv"
    files["amplitudes"].write_bytes(NOT_UTF8)
    return files


@pytest.mark.parametrize("kind", ["record", "missing"])
@pytest.mark.parametrize("command", ["identify", "discover"])
def test_record_commands(capsys, broken, tmp_path, command, kind):
    path = broken["record"] if kind == "record" else tmp_path / "nowhere.csv"
    _one_line_error(capsys, [command, path, "--json"], path)


@pytest.mark.parametrize("kind", ["yaml_bytes", "yaml_syntax"])
def test_simulate_bad_rig(capsys, broken, tmp_path, kind):
    _one_line_error(capsys, ["simulate", "--rig", broken[kind], "--out", tmp_path / "o"], broken[kind])


@pytest.mark.parametrize("kind", ["onnx_garbage", "onnx_input", "onnx_output"])
def test_simulate_bad_policy(capsys, broken, tmp_path, kind):
    line = _one_line_error(capsys, ["simulate", "--controller", f"onnx:{broken[kind]}", "--out", tmp_path / "o"],
                           broken[kind])
    assert "expected" in line
    assert not (tmp_path / "o").exists() or not list((tmp_path / "o").iterdir())


@pytest.mark.parametrize("kind", ["yaml_bytes", "yaml_syntax"])
def test_bench_run_bad_suite(capsys, broken, tmp_path, kind):
    _one_line_error(capsys, ["bench", "run", "--suite", broken[kind], "--controller", "lqr",
                             "--out", tmp_path / "r.jsonl"], broken[kind])


@pytest.mark.parametrize("kind", ["onnx_garbage", "onnx_input", "onnx_output"])
def test_bench_run_bad_policy_refused_before_any_episode(capsys, broken, tmp_path, kind):
    out = tmp_path / "r.jsonl"
    _one_line_error(capsys, ["bench", "run", "--suite", "smoke", "--controller", f"onnx:{broken[kind]}",
                             "--out", out, "--no-progress"], broken[kind])
    assert not out.exists()


def test_bench_leaderboard_bad_rows(capsys, broken):
    _one_line_error(capsys, ["bench", "leaderboard", broken["rows"]], broken["rows"])


def test_decay_bad_amplitudes(capsys, broken):
    _one_line_error(capsys, ["decay", broken["amplitudes"], "--json"], broken["amplitudes"])


@pytest.mark.parametrize("kind", ["yaml_bytes", "yaml_syntax"])
def test_deploy_bad_lab(capsys, broken, tmp_path, kind):
    _one_line_error(capsys, ["deploy", "--bench", "loop://", "--controller", "lqr", "--lab", broken[kind],
                             "--out", tmp_path / "d"], broken[kind])


@pytest.mark.parametrize("kind", ["onnx_garbage", "onnx_input", "onnx_output"])
def test_deploy_bad_policy_refused_before_connecting(capsys, broken, tmp_path, kind):
    # The bench URL points nowhere: a policy check that came after connecting would fail there instead.
    _one_line_error(capsys, ["deploy", "--bench", "socket://127.0.0.1:9", "--policy", broken[kind],
                             "--out", tmp_path / "d"], broken[kind])
    assert not (tmp_path / "d").exists()


def test_unexpected_exception_is_a_bug_report_with_a_log(capsys, tmp_path, monkeypatch):
    import addedinertia_env.cli.identify as identify_cli

    def boom(args):
        raise RuntimeError("something nobody expected")

    monkeypatch.setattr(identify_cli, "run", boom)
    monkeypatch.setenv("ADDEDINERTIA_LOG_DIR", str(tmp_path / "logs"))
    rc = main(["identify", "x.csv"])
    err = capsys.readouterr().err
    assert rc == EXIT_BUG
    assert "internal error" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    logs = list((tmp_path / "logs").glob("crash-*.log"))
    assert len(logs) == 1 and str(logs[0]) in err
    assert "Traceback" in logs[0].read_text() and "something nobody expected" in logs[0].read_text()


def test_deploy_bad_bench_url(capsys, tmp_path):
    _one_line_error(capsys, ["deploy", "--bench", "nosuchproto://x", "--controller", "lqr", "--out", tmp_path / "d"],
                    "nosuchproto://x")


@pytest.mark.parametrize("block,key,value,limit", [
    ("sensors", "sample_rate", 1e7, "20000"),
    ("sensors", "sample_rate", 1e9, "20000"),
    ("experiment", "hold_s", 1e5, "600"),
])
def test_unbounded_work_refused_up_front_with_the_limit(capsys, tmp_path, block, key, value, limit):
    import yaml

    data = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs" / "rigs" / "wigley-2m.yaml").read_text())
    data[block][key] = value
    rig = tmp_path / "big.yaml"
    rig.write_text(yaml.safe_dump(data))
    rc = main(["simulate", "--rig", str(rig), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and str(rig) in err and limit in err and len(err.strip().splitlines()) == 1, err


def test_too_many_cycles_refused(capsys, tmp_path):
    rc = main(["simulate", "--cycles", "100000", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "1000" in err


def test_simulate_removes_temporary_files_of_killed_writers_only(capsys, tmp_path):
    import os
    import subprocess

    out = tmp_path / "sim"
    out.mkdir()
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = out / f".run-0000.csv.pid{dead.pid}.abc123.tmp"
    live = out / f".run-0000.csv.pid{os.getppid()}.xyz789.tmp"  # a live writer (our parent process)
    stale.write_text("half a record")
    live.write_text("being written")
    assert main(["simulate", "--out", str(out), "--hold", "0.2"]) == 0
    err = capsys.readouterr().err
    assert not stale.exists() and str(stale) in err
    assert live.exists()
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["run-0000.csv", "run-0000.json"]


def test_a_suites_bad_value_is_blamed_on_the_suite(capsys, tmp_path):
    import yaml

    data = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs" / "suites" / "smoke.yaml").read_text())
    data["fixed"]["hold_s"] = -1.0
    suite = tmp_path / "bad-suite.yaml"
    suite.write_text(yaml.safe_dump(data))
    line = _one_line_error(capsys, ["bench", "run", "--suite", suite, "--controller", "lqr",
                                    "--out", tmp_path / "r.jsonl"], suite)
    assert "hold_s" in line


def test_a_rig_file_without_its_motor_block_is_refused(capsys, tmp_path):
    import yaml

    data = yaml.safe_load((Path(__file__).resolve().parents[1] / "configs" / "rigs" / "wigley-2m.yaml").read_text())
    del data["motor"]
    rig = tmp_path / "nomotor.yaml"
    rig.write_text(yaml.safe_dump(data))
    line = _one_line_error(capsys, ["simulate", "--rig", rig, "--out", tmp_path / "o"], rig)
    assert "motor" in line


def test_simulate_resumes_its_own_records_and_refuses_others(capsys, tmp_path):
    out = tmp_path / "sim"
    argv = ["simulate", "--out", str(out), "--hold", "0.2", "--cycles", "2", "--seed", "5"]
    assert main(argv) == 0
    first = (out / "run-0001.csv").read_text()
    (out / "run-0001.csv").unlink()  # as if killed before the second record was renamed into place
    (out / "run-0001.json").unlink()
    capsys.readouterr()
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "kept 1 record" in err and (out / "run-0001.csv").read_text() == first  # same record again
    other = ["simulate", "--out", str(out), "--hold", "0.2", "--seed", "6"]
    _one_line_error(capsys, other, out / "run-0000.csv")
    assert main([*other, "--force"]) == 0
