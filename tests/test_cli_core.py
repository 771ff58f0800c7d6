"""The core commands: ``addedinertia demo``, ``simulate`` and ``identify``.

Contract (../shared/spec/interfaces.md): with ``--json`` exactly one JSON object on
stdout and human text on stderr; bad input exits with status 2 and one line on stderr
that names the file. Commands run in-process through ``main([...])``; one runs as a real
subprocess to check the installed entry point.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from addedinertia_env.cli import main
from addedinertia_env.identify import identify
from addedinertia_env.records.record import read_record
from addedinertia_env.sim.presets import load_preset, load_rig


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_json_object(out: str) -> dict:
    """stdout must be exactly one JSON object (one line, nothing else)."""
    assert out.endswith("\n") and out.count("\n") == 1, out
    obj = json.loads(out)
    assert isinstance(obj, dict)
    return obj


def one_error_line(err: str, *fragments: str) -> str:
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1, err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def test_demo_json(tmp_path, capsys):
    out_dir = tmp_path / "demo"
    code, out, err = run_cli(capsys, "demo", "--out", out_dir, "--json")
    assert code == 0, err
    summary = one_json_object(out)
    truth = load_rig("wigley-2m").hull.lambda66
    assert summary["lambda66_true"] == truth
    # The default controller with realistic sensors: within a few percent (physics.md s4).
    assert abs(summary["lambda66_est"] / truth - 1.0) < 0.03, summary
    lo, hi = summary["ci95"]
    assert lo < summary["lambda66_est"] < hi
    record = Path(summary["record"])
    assert record.parent == out_dir and record.exists() and record.with_suffix(".json").exists()
    assert read_record(record).truth_lambda66() == truth
    figure = Path(summary["figure"])
    assert figure.exists() and figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in out_dir.iterdir()) == ["demo.csv", "demo.json", "demo.png"]  # no temporaries


def test_simulate_then_identify_round_trip(tmp_path, capsys):
    out_dir = tmp_path / "sim"
    code, out, err = run_cli(capsys, "simulate", "--rig", "spheroid-7", "--seed", "4", "--hold", "1.5",
                             "--out", out_dir, "--json")
    assert code == 0, err
    sim = one_json_object(out)
    assert sim["rig"] == "spheroid-7" and len(sim["records"]) == 1
    record_path = Path(sim["records"][0])
    assert "wrote" in err and str(record_path) in err  # human text on stderr
    record = read_record(record_path)
    assert record.experiment["hold_s"] == 1.5 and record.experiment["seed"] == 4

    code, out, err = run_cli(capsys, "identify", record_path, "--json")
    assert code == 0, err
    result = one_json_object(out)
    assert set(result) >= {"method", "lambda66", "ci95", "n_intervals"}
    assert result["method"] == "energy" and result["n_intervals"] >= 1
    # The command reports what the Python entry point computes from the same files.
    assert result["lambda66"] == identify([record], "energy").lambda66
    truth = load_rig("spheroid-7").hull.lambda66
    assert abs(result["lambda66"] / truth - 1.0) < 0.03
    lo, hi = result["ci95"]
    assert lo < result["lambda66"] < hi

    code, out, err = run_cli(capsys, "identify", record_path)  # human form: one line on stdout
    assert code == 0 and "lambda66 =" in out


@pytest.fixture
def bad_record(tmp_path, realistic_record_path) -> Path:
    """A copy of the realistic record whose JSON has a negative torsion stiffness."""
    path = tmp_path / "bad.csv"
    path.write_text(realistic_record_path.read_text())
    meta = json.loads(realistic_record_path.with_suffix(".json").read_text())
    meta["rig"]["c_torsion"] = -43.4
    path.with_suffix(".json").write_text(json.dumps(meta))
    return path


def test_identify_bad_record_exits_2_with_one_line(bad_record, capsys):
    code, out, err = run_cli(capsys, "identify", bad_record, "--json")
    assert code == 2 and out == ""
    one_error_line(err, str(bad_record.with_suffix(".json")), "rig.c_torsion", "expected")


def test_identify_missing_file_exits_2_with_one_line(tmp_path, capsys):
    missing = tmp_path / "nowhere.csv"
    code, out, err = run_cli(capsys, "identify", missing, "--json")
    assert code == 2 and out == ""
    one_error_line(err, str(missing), "no such file")


def test_identify_csv_without_json_exits_2(tmp_path, realistic_record_path, capsys):
    lonely = tmp_path / "lonely.csv"
    lonely.write_text(realistic_record_path.read_text())
    code, out, err = run_cli(capsys, "identify", lonely)
    assert code == 2 and out == ""
    one_error_line(err, str(lonely), "lonely.json")


def test_simulate_bad_preset_file_exits_2(tmp_path, capsys):
    data = load_preset("wigley-2m")
    data.pop("_path")
    data["motor"]["k_t"] = -0.25
    preset = tmp_path / "broken.yaml"
    preset.write_text(yaml.safe_dump(data))
    code, out, err = run_cli(capsys, "simulate", "--rig", preset, "--out", tmp_path / "x", "--json")
    assert code == 2 and out == ""
    one_error_line(err, str(preset), "k_t", "expected")
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("argv, fragments", [
    (["simulate", "--rig", "no-such-rig"], ["unknown rig 'no-such-rig'", "wigley-2m"]),
    (["simulate", "--controller", "nosuch"], ["--controller", "nosuch"]),
    (["simulate", "--controller", "smith-pd"], ["--controller 'smith-pd'", "link_round_trip_s"]),
    (["simulate", "--hold", "-1"], ["--hold", "expected"]),
    (["simulate", "--seed", "-1"], ["--seed", "expected an integer >= 0"]),
    (["demo", "--rig", "no-such-rig"], ["unknown rig 'no-such-rig'"]),
    (["identify", "--method", "nosuch", "x.csv"], ["--method", "nosuch"]),
    (["identify"], ["RUN.csv"]),
    (["no-such-command"], ["no-such-command"]),
])
def test_usage_errors_exit_2_with_one_line(argv, fragments, tmp_path, capsys):
    out_dir = ["--out", tmp_path / "out"] if argv[0] in ("simulate", "demo") else []
    code, out, err = run_cli(capsys, *argv, *out_dir)
    assert code == 2 and out == ""
    one_error_line(err, *fragments)
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_bad_input_through_a_real_process(bad_record):
    """The installed entry point, as a user runs it: exit status 2, one line on stderr."""
    script = Path(sys.executable).parent / "addedinertia"  # the console script pip installed
    command = [str(script)] if script.exists() else [
        sys.executable, "-c", "import sys; from addedinertia_env.cli import main; sys.exit(main())"]
    proc = subprocess.run([*command, "identify", str(bad_record), "--json"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and proc.stdout == ""
    line = one_error_line(proc.stderr, str(bad_record.with_suffix(".json")), "rig.c_torsion")
    assert line.startswith("addedinertia: error:")
