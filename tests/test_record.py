"""Run records (../shared/spec/run-record.md): every bad-input case, round trip, atomic writes.

Each bad-input test spoils one thing in a valid record on disk and checks that the
reader refuses it with a message naming the file, the line or column (or the JSON key),
and what was expected.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.records import record as record_module
from addedinertia_env.cli import main
from addedinertia_env.records.record import (
    FORMAT,
    POSITIVE_RIG_KEYS,
    REQUIRED_COLUMNS,
    REQUIRED_RIG_KEYS,
    RecordError,
    RunRecord,
    read_record,
    write_record,
)
from addedinertia_env.sim.params import RigParams

N_ROWS = 40
PHASE_ROWS = ["idle"] * 5 + ["free"] * 15 + ["hold"] * 5 + ["reverse"] * 12 + ["idle"] * 3
NUMERIC_REQUIRED = [c for c in REQUIRED_COLUMNS if c != "phase"]


def small_record() -> RunRecord:
    """A valid 40-sample record at 1 kHz (the numbers need only be plausible)."""
    t = np.arange(N_ROWS) * 1e-3
    samples = {"t": t, "phase": np.array(PHASE_ROWS), "phi": -0.1 * np.cos(2 * np.pi * t / 4.0),
               "psi": 0.3 * t, "u": 0.1 + 0.01 * np.sin(t), "i": 0.002 * np.cos(t),
               "i_cmd": np.zeros(N_ROWS), "brake": np.array([1.0] * 5 + [0.0] * 15 + [1.0] * 5 + [0.0] * 15)}
    meta = {"format": FORMAT, "run_id": "small", "source": "sim", "rig": RigParams().known().to_block(),
            "experiment": {"kind": "reverse-symmetric", "alpha": 0.1, "hold_s": 0.005}}
    return RunRecord(samples=samples, meta=meta)


@pytest.fixture
def record_path(tmp_path) -> Path:
    return write_record(small_record(), tmp_path / "run-0001.csv")


def read_rows(path: Path) -> list[list[str]]:
    return list(csv.reader(io.StringIO(path.read_text())))


def write_rows(path: Path, rows: list[list[str]]) -> None:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    path.write_text(buf.getvalue())


def set_cell(path: Path, row: int, column: str, value: str) -> int:
    """Set the cell of sample ``row`` (0-based) in ``column``; returns its 1-based file line."""
    rows = read_rows(path)
    rows[row + 1][rows[0].index(column)] = value
    write_rows(path, rows)
    return row + 2


def edit_meta(path: Path, change) -> Path:
    json_path = path.with_suffix(".json")
    meta = json.loads(json_path.read_text())
    change(meta)
    json_path.write_text(json.dumps(meta))
    return json_path


def refused(path: Path, *fragments: str) -> str:
    """Read ``path``, expect a RecordError naming a file and ``fragments``; return the message."""
    with pytest.raises(RecordError) as info:
        read_record(path)
    message = str(info.value)
    assert "\n" not in message
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    return message


def test_the_valid_record_reads(record_path):
    rec = read_record(record_path)
    assert len(rec) == N_ROWS and rec.gaps == [] and list(rec.phase) == PHASE_ROWS
    assert read_record(record_path.with_suffix(".json")).samples.keys() == rec.samples.keys()


# --- samples -------------------------------------------------------------------------

@pytest.mark.parametrize("column", REQUIRED_COLUMNS)
def test_missing_required_column(record_path, column):
    rows = read_rows(record_path)
    k = rows[0].index(column)
    write_rows(record_path, [r[:k] + r[k + 1:] for r in rows])
    refused(record_path, str(record_path), "line 1", f"'{column}'", "expected")


@pytest.mark.parametrize("column", NUMERIC_REQUIRED + ["i_cmd", "brake"])
@pytest.mark.parametrize("value", ["abc", "", "1,5", "nan", "NaN", "inf", "-inf"])
def test_non_numeric_or_non_finite_value(record_path, column, value):
    line = set_cell(record_path, 17, column, value)
    refused(record_path, str(record_path), f"line {line}", f"column '{column}'", repr(value),
            "expected a finite number")


@pytest.mark.parametrize("delta", [0.0, -5e-4, -1.0])
def test_non_increasing_t(record_path, delta):
    line = set_cell(record_path, 20, "t", repr(0.019 + delta))  # sample 19 is at t = 0.019 s
    refused(record_path, str(record_path), f"line {line}", "column 't'", "expected strictly increasing")


@pytest.mark.parametrize("value", ["coast", "FREE", "", "reverse2"])
def test_unknown_phase(record_path, value):
    line = set_cell(record_path, 8, "phase", value)
    refused(record_path, str(record_path), f"line {line}", "column 'phase'", repr(value), "expected one of")


@pytest.mark.parametrize("value", ["7.0", "-6.3", "360"])
def test_phi_out_of_range_is_refused_as_wrong_units(record_path, value):
    line = set_cell(record_path, 3, "phi", value)
    refused(record_path, str(record_path), f"line {line}", "column 'phi'", "expected |phi| <= 2 pi")


def test_brake_column_must_be_0_or_1(record_path):
    line = set_cell(record_path, 4, "brake", "2")
    refused(record_path, str(record_path), f"line {line}", "column 'brake'", "expected 0 or 1")


@pytest.mark.parametrize("change", ["short", "long"])
def test_ragged_rows(record_path, change):
    rows = read_rows(record_path)
    rows[11] = rows[11][:-2] if change == "short" else rows[11] + ["0.0"]
    write_rows(record_path, rows)
    width = len(rows[0])
    refused(record_path, str(record_path), "line 12", f"expected {width}")


def test_header_only_and_empty_files(record_path):
    rows = read_rows(record_path)
    write_rows(record_path, rows[:1])
    refused(record_path, str(record_path), "expected at least one sample row")
    record_path.write_text("")
    refused(record_path, str(record_path), "empty file", "expected a header row")


def test_duplicate_column(record_path):
    rows = read_rows(record_path)
    write_rows(record_path, [r + [r[rows[0].index("phi")]] for r in rows])
    refused(record_path, str(record_path), "line 1", "duplicate column(s) ['phi']", "expected each column once")


def test_gaps_are_reported_not_refused(record_path):
    rows = read_rows(record_path)
    del rows[10:17]  # samples 9..15 (t = 9..15 ms) gone: a 7-period gap after t = 8 ms
    write_rows(record_path, rows)
    rec = read_record(record_path)
    assert len(rec) == N_ROWS - 7
    assert len(rec.gaps) == 1
    t_before, gap = rec.gaps[0]
    assert t_before == pytest.approx(0.008) and gap == pytest.approx(0.008)
    # Exactly five periods is not a gap (spec: larger than five nominal sample periods).
    rows = read_rows(write_record(small_record(), record_path.parent / "five.csv"))
    del rows[10:14]  # 4 samples gone: 5 periods from the one before to the one after
    write_rows(record_path.parent / "five.csv", rows)
    assert read_record(record_path.parent / "five.csv").gaps == []


# --- metadata ------------------------------------------------------------------------

@pytest.mark.parametrize("key", ["format", "rig", "experiment"])
def test_missing_top_level_key(record_path, key):
    json_path = edit_meta(record_path, lambda m: m.pop(key))
    refused(record_path, str(json_path), f"missing key '{key}'", "expected")


@pytest.mark.parametrize("key", REQUIRED_RIG_KEYS)
def test_missing_rig_key(record_path, key):
    json_path = edit_meta(record_path, lambda m: m["rig"].pop(key))
    refused(record_path, str(json_path), f"missing key 'rig.{key}'", "expected a number")


def test_missing_experiment_kind(record_path):
    json_path = edit_meta(record_path, lambda m: m["experiment"].pop("kind"))
    refused(record_path, str(json_path), "missing key 'experiment.kind'", "expected one of")


def test_unknown_experiment_kind(record_path):
    json_path = edit_meta(record_path, lambda m: m["experiment"].update(kind="tow-test"))
    refused(record_path, str(json_path), "key 'experiment.kind'", "'tow-test'", "expected one of")


@pytest.mark.parametrize("fmt", ["addedinertia-run/2", "", None, 1])
def test_unknown_format(record_path, fmt):
    json_path = edit_meta(record_path, lambda m: m.update(format=fmt))
    refused(record_path, str(json_path), "key 'format'", repr(fmt), FORMAT)


@pytest.mark.parametrize("key", POSITIVE_RIG_KEYS)
@pytest.mark.parametrize("value", [0.0, -1.0])
def test_non_positive_rig_constant(record_path, key, value):
    json_path = edit_meta(record_path, lambda m: m["rig"].update({key: value}))
    refused(record_path, str(json_path), f"key 'rig.{key}'", repr(value), "expected a number > 0")


@pytest.mark.parametrize("value", ["43.4", None, True, float("nan"), float("inf")])
def test_non_numeric_rig_constant(record_path, value):
    json_path = edit_meta(record_path, lambda m: m["rig"].update(c_torsion=value))
    refused(record_path, str(json_path), "key 'rig.c_torsion'", "expected a finite number")


def test_phi_neutral_out_of_range(record_path):
    json_path = edit_meta(record_path, lambda m: m["rig"].update(phi_neutral=90.0))
    refused(record_path, str(json_path), "key 'rig.phi_neutral'", "expected |value| <= 2 pi")


def test_bad_motor_friction_and_phi1(record_path):
    json_path = edit_meta(record_path, lambda m: m["rig"]["motor_friction"].update(coulomb=-0.1))
    refused(record_path, str(json_path), "key 'rig.motor_friction.coulomb'", "expected a finite number >= 0")
    json_path = edit_meta(record_path, lambda m: m["rig"].update(motor_friction={"coulomb": 0.002}))
    read_record(record_path)  # a partial friction block is fine (absent terms are zero)
    json_path = edit_meta(record_path, lambda m: m["experiment"].update(phi1=[0.02, 45.0]))
    refused(record_path, str(json_path), "key 'experiment.phi1'", "expected a list of angles in rad")


def test_bad_source_and_non_object_blocks(record_path):
    json_path = edit_meta(record_path, lambda m: m.update(source="lab"))
    refused(record_path, str(json_path), "key 'source'", "'lab'", "expected one of")
    json_path = edit_meta(record_path, lambda m: m.update(source="sim", experiment="reverse-symmetric"))
    refused(record_path, str(json_path), "key 'experiment' must be an object")
    json_path = edit_meta(record_path, lambda m: m.update(experiment={"kind": "free-decay"}, rig=[1, 2]))
    refused(record_path, str(json_path), "key 'rig' must be an object")


def test_invalid_json(record_path):
    json_path = record_path.with_suffix(".json")
    json_path.write_text('{\n  "format": "addedinertia-run/1",\n  "rig": {,}\n}\n')
    refused(record_path, str(json_path), "line 3 column", "not valid JSON")
    json_path.write_text("[1, 2]")
    refused(record_path, str(json_path), "expected a JSON object")


# --- file pairing --------------------------------------------------------------------

def test_csv_without_json(record_path):
    json_path = record_path.with_suffix(".json")
    json_path.unlink()
    refused(record_path, str(record_path), json_path.name, "expected a CSV and a JSON file with the same stem")
    refused(json_path, str(record_path), json_path.name)  # named by its JSON path: same answer


def test_json_without_csv(record_path):
    json_path = record_path.with_suffix(".json")
    record_path.unlink()
    refused(json_path, str(json_path), record_path.name, "expected a CSV and a JSON file with the same stem")
    refused(record_path, str(json_path), record_path.name)


def test_neither_file_and_wrong_suffix(tmp_path):
    refused(tmp_path / "none.csv", str(tmp_path / "none.csv"), "no such file", "expected")
    (tmp_path / "run.txt").write_text("t\n")
    refused(tmp_path / "run.txt", str(tmp_path / "run.txt"), "expected a run record's .csv")


# --- round trip ----------------------------------------------------------------------

def test_round_trip_keeps_unknown_keys_columns_and_every_row(tmp_path):
    rec = small_record()
    rec.samples["tank_temperature"] = np.linspace(18.0, 18.5, N_ROWS)  # unknown numeric column
    rec.samples["operator_note"] = np.array(["ok"] * (N_ROWS - 1) + ["bubble, seen"])  # unknown text column
    rec.meta["lab"] = {"name": "tank 3", "depth_m": [1.0, 1.2]}
    rec.meta["rig"]["rod_serial"] = "R-17"
    rec.meta["experiment"]["operator"] = "A. N."
    path = write_record(rec, tmp_path / "rt.csv")
    back = read_record(path)
    assert back.meta["lab"] == {"name": "tank 3", "depth_m": [1.0, 1.2]}
    assert back.meta["rig"]["rod_serial"] == "R-17" and back.meta["experiment"]["operator"] == "A. N."
    assert list(back.samples) == list(rec.samples)  # every column, in order
    for name, values in rec.samples.items():
        assert len(back[name]) == N_ROWS
        if values.dtype.kind in "US":
            assert list(back[name]) == list(values), name
        else:
            np.testing.assert_array_equal(back[name], values, err_msg=name)  # bit-exact (repr floats)
    # Writing what was read gives the same files again.
    again = write_record(back, tmp_path / "rt2.csv")
    assert again.read_text() == path.read_text()
    assert again.with_suffix(".json").read_text() == path.with_suffix(".json").read_text()


def test_round_trip_of_a_simulated_record(realistic_record, clone, tmp_path):
    rec, _ = realistic_record
    path = write_record(clone(rec), tmp_path / "sim.csv")
    back = read_record(path)
    assert len(back) == len(rec) and back.gaps == []
    for name in rec.samples:
        if name == "phase":
            assert np.array_equal(back[name], rec[name])
        else:
            np.testing.assert_array_equal(back[name], rec[name], err_msg=name)
    assert back.meta == json.loads(json.dumps(rec.meta))


# --- atomic writes -------------------------------------------------------------------

def _old_record(tmp_path) -> tuple[Path, str, str]:
    path = write_record(small_record(), tmp_path / "run-0001.csv")
    return path, path.read_text(), path.with_suffix(".json").read_text()


def _newer_record() -> RunRecord:
    rec = small_record()
    rec.samples["phi"] = rec.samples["phi"] * 0.5
    rec.meta["experiment"]["alpha"] = 0.05
    return rec


def _assert_old_intact(tmp_path, path: Path, old_csv: str, old_json: str) -> None:
    assert path.read_text() == old_csv
    assert path.with_suffix(".json").read_text() == old_json
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run-0001.csv", "run-0001.json"]  # no temporaries left
    read_record(path)


@pytest.mark.parametrize("crash_on_call", [1, 2])
def test_crash_while_writing_leaves_the_older_record_intact(tmp_path, monkeypatch, crash_on_call):
    """A crash while the JSON (call 1) or the CSV (call 2) is being written."""
    path, old_csv, old_json = _old_record(tmp_path)
    calls = {"n": 0}
    real_fsync = os.fsync

    def failing_fsync(fd):
        calls["n"] += 1
        if calls["n"] == crash_on_call:
            raise OSError(28, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(record_module.os, "fsync", failing_fsync)
    with pytest.raises(OSError, match="No space left"):
        write_record(_newer_record(), path)
    _assert_old_intact(tmp_path, path, old_csv, old_json)


def test_crash_in_the_middle_of_the_data_leaves_no_half_file(tmp_path, monkeypatch):
    """The process dies after writing part of the CSV text."""
    path, old_csv, old_json = _old_record(tmp_path)
    real_fdopen = os.fdopen

    class HalfWriter:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()
            return False

        def write(self, text):
            if text.startswith("t,"):  # the CSV: write half of it, then die
                self.f.write(text[: len(text) // 2])
                raise KeyboardInterrupt
            return self.f.write(text)

        def __getattr__(self, name):
            return getattr(self.f, name)

    monkeypatch.setattr(record_module.os, "fdopen", lambda *a, **k: HalfWriter(real_fdopen(*a, **k)))
    with pytest.raises(KeyboardInterrupt):
        write_record(_newer_record(), path)
    _assert_old_intact(tmp_path, path, old_csv, old_json)


def test_crash_at_the_rename_leaves_the_older_record_intact(tmp_path, monkeypatch):
    path, old_csv, old_json = _old_record(tmp_path)

    def failing_replace(src, dst):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(record_module.os, "replace", failing_replace)
    with pytest.raises(OSError):
        write_record(_newer_record(), path)
    _assert_old_intact(tmp_path, path, old_csv, old_json)


def test_crash_on_a_first_write_leaves_no_record(tmp_path, monkeypatch):
    monkeypatch.setattr(record_module.os, "fsync", lambda fd: (_ for _ in ()).throw(OSError(28, "disk full")))
    with pytest.raises(OSError):
        write_record(small_record(), tmp_path / "new.csv")
    assert list(tmp_path.iterdir()) == []


# --- the identify command shows gaps ---------------------------------------------------

def test_identify_warns_about_gaps(realistic_record_path, tmp_path, capsys):
    rows = read_rows(realistic_record_path)
    phase = rows[0].index("phase")
    hold = [k for k, r in enumerate(rows) if k and r[phase] == "hold"]
    start = hold[len(hold) // 2]
    t_before = float(rows[start - 1][0])
    del rows[start:start + 20]  # 20 samples of the brake hold lost: a 21 ms gap
    path = tmp_path / "gappy.csv"
    write_rows(path, rows)
    path.with_suffix(".json").write_text(realistic_record_path.with_suffix(".json").read_text())
    assert main(["identify", str(path), "--json"]) == 0
    out, err = capsys.readouterr()
    result = json.loads(out)  # exactly one JSON object on stdout
    assert math.isfinite(result["lambda66"])
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert len(warnings) == 1
    assert str(path) in warnings[0] and "gap of 0.0210 s" in warnings[0] and f"t = {t_before:.4f} s" in warnings[0]
