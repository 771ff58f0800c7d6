"""Records their own rig could not have produced are refused (addedinertia_env/records/plausibility.py);
records that are only unusual in form are not; methods never return an impossible value."""

from __future__ import annotations

import json
import shutil
import tarfile
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.identify import IdentificationError, Result, identify
from addedinertia_env.identify.common import check_physical
from addedinertia_env.records.plausibility import check_plausible
from addedinertia_env.records.record import RecordError, RunRecord, read_record, write_record

# ../shared beside the project root (as CI lays it out), else this workplace's copy.
FOREIGN = next((p for p in (Path(__file__).resolve().parents[2] / "shared" / "data" / "foreign-lab.tar.xz",
                            Path("/work/shared/data/foreign-lab.tar.xz")) if p.exists()),
               Path("../shared/data/foreign-lab.tar.xz"))


def _written(tmp_path, rec: RunRecord, name: str = "run") -> Path:
    return write_record(rec, tmp_path / f"{name}.csv")


def _refusal(capsys, path: Path) -> str:
    """Run ``identify`` on ``path``: exit 2, one line on stderr naming the file."""
    rc = main(["identify", str(path), "--json"])
    out = capsys.readouterr()
    assert rc == 2, out
    assert out.out == ""
    lines = [x for x in out.err.strip().splitlines() if "warning:" not in x]  # gap warnings may come first
    assert len(lines) == 1 and str(path) in lines[0] and "error" in lines[0], lines
    return lines[0]


def test_plain_records_pass(realistic_record, oracle_record):
    for rec in (realistic_record[0], oracle_record("wigley-2m")[0]):
        limits = check_plausible(rec)
        assert np.max(np.abs(rec["i"])) <= limits.i_max and np.max(np.abs(rec["u"])) <= limits.u_max


# Each general rule, by scaling a whole channel (units) or one sample (a spike). The scale
# factors are SI prefixes a DAQ might use; the limit in the message is what the rig allows.
@pytest.mark.parametrize("column,factor,limit_word", [
    ("i", 1e3, "|i| <="), ("u", 1e3, "|u| <="), ("psi", 1e15, "|psi| <="),
])
def test_wrong_units_refused_naming_column_row_and_limit(tmp_path, capsys, realistic_record, clone, column, factor,
                                                         limit_word):
    rec = clone(realistic_record[0])
    rec.samples[column] = rec.samples[column] * factor + (1.0 if column == "psi" else 0.0)
    line = _refusal(capsys, _written(tmp_path, rec))
    assert f"column '{column}'" in line and "line " in line and limit_word in line


@pytest.mark.parametrize("column,value", [("i", 1e6), ("i", -40.0), ("u", 1e9), ("psi", 1e15), ("phi", 0.5),
                                          ("psi", 50.0)])
def test_single_impossible_sample_refused(tmp_path, capsys, realistic_record, clone, column, value):
    rec = clone(realistic_record[0])
    k = int(np.nonzero(rec.phase == "reverse")[0][100])
    rec.samples[column][k] += value
    line = _refusal(capsys, _written(tmp_path, rec))
    assert f"column '{column}'" in line and f"line {k + 2}" in line


def test_current_beyond_what_the_voltage_drives_is_refused_without_i_max(tmp_path, capsys, realistic_record, clone):
    """No ``i_max`` in the rig: the limit comes from ``u``, ``k_t`` and ``R`` alone."""
    rec = clone(realistic_record[0])
    for key in ("i_max", "u_max"):
        rec.meta["rig"].pop(key, None)
    rec.samples["i"] = rec["i"] * 1e3  # logged in mA
    line = _refusal(capsys, _written(tmp_path, rec))
    assert "the most the terminal voltage can drive" in line


def test_phases_out_of_order_refused(tmp_path, capsys, realistic_record, clone):
    rec = clone(realistic_record[0])
    ph = rec.samples["phase"]
    hold = ph == "hold"
    rec.samples["phase"] = np.where(ph == "free", "hold", np.where(hold, "free", ph))
    line = _refusal(capsys, _written(tmp_path, rec))
    assert "column 'phase'" in line and "idle -> free -> hold -> reverse -> idle" in line


def test_unusual_but_legitimate_forms_pass(tmp_path, realistic_record, clone):
    """Columns shuffled, clock jitter, single dropped samples, a reported gap in the hold,
    no i_max / u_max / encoder_counts, CRLF: all still plausible (the reader's business)."""
    rec = clone(realistic_record[0])
    rng = np.random.default_rng(0)
    n = len(rec)
    keep = np.ones(n, bool)
    keep[rng.choice(np.arange(10, n - 10), 20, replace=False)] = False
    hold = np.nonzero(rec.phase == "hold")[0]
    keep[hold[500:520]] = False  # a 20-sample gap while braked
    samples = {k: v[keep] for k, v in rec.samples.items()}
    t = samples["t"]
    t = t + rng.uniform(-0.2e-3, 0.2e-3, t.size) * 0.5  # jitter below half a period keeps t increasing
    samples["t"] = np.sort(t)
    samples = dict(reversed(list(samples.items())))
    for key in ("i_max", "u_max", "encoder_counts"):
        rec.meta["rig"].pop(key, None)
    path = _written(tmp_path, RunRecord(samples=samples, meta=rec.meta))
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    back = read_record(path)
    assert back.gaps and len(back) == int(keep.sum())


def test_foreign_lab_records_pass(tmp_path):
    """Another lab's simulator and habits (development set): every record is plausible."""
    if not FOREIGN.exists():
        pytest.skip("foreign-lab data not present")
    with tarfile.open(FOREIGN) as tar:
        tar.extractall(tmp_path, filter="data")
    paths = sorted(tmp_path.glob("foreign-lab/case-*/run-*.csv"))
    assert len(paths) >= 40
    for path in paths:
        meta_path = path.with_suffix(".json")
        meta = json.loads(meta_path.read_text())
        if not meta["rig"].get("L"):  # L = 0 is the reader's concern (issue 11), not plausibility's
            meta["rig"]["L"] = 1e-4
            meta_path.write_text(json.dumps(meta))
        check_plausible(read_record(path))


def test_gap_inside_a_stroke_drops_the_interval_and_says_so(tmp_path, capsys, realistic_record, clone):
    rec = clone(realistic_record[0])
    rev = np.nonzero(rec.phase == "reverse")[0]
    keep = np.ones(len(rec), bool)
    keep[rev[300:350]] = False  # 50 samples lost in the reverse stroke
    samples = {k: v[keep] for k, v in rec.samples.items()}
    path = _written(tmp_path, RunRecord(samples=samples, meta=rec.meta))
    line = _refusal(capsys, path)
    assert "gap of" in line and "inside the integrated stroke" in line


@pytest.mark.parametrize("lam,ci", [(-10.0, (-11.0, -9.0)), (float("nan"), (0.0, 1.0)), (1.0, (0.0, float("inf"))),
                                    (-0.5, (-0.6, -0.4))])
def test_physically_impossible_results_are_refused(realistic_record, lam, ci):
    rec = realistic_record[0]
    with pytest.raises(IdentificationError, match="energy method on"):
        check_physical(Result("energy", lam, ci, 1), [rec])


def test_a_small_negative_estimate_within_its_interval_is_kept(realistic_record):
    """An added inertia near zero may be estimated slightly below it; the interval reaches zero."""
    rec = realistic_record[0]
    assert check_physical(Result("energy", -0.01, (-0.05, 0.03), 1), [rec]).lambda66 == -0.01


def test_in_memory_records_are_checked_before_any_method(realistic_record, clone):
    rec = clone(realistic_record[0])
    rec.samples["u"] = rec.samples["u"] * 1e3
    with pytest.raises(RecordError, match="column 'u'"):
        identify([rec], "energy")


def test_every_method_refusal_names_the_record(tmp_path, capsys, realistic_record, clone):
    """A method's own refusal (too short, too few swings) still names the file."""
    rec = clone(realistic_record[0])
    rec.meta["experiment"]["kind"] = "free-decay"
    n = int(np.nonzero(rec.phase == "free")[0][40])
    samples = {k: v[:n] for k, v in rec.samples.items()}  # idle then a short free stretch
    path = _written(tmp_path, RunRecord(samples=samples, meta=rec.meta))
    rc = main(["identify", str(path), "--method", "free-decay", "--json"])
    err = capsys.readouterr().err
    assert rc == 2 and str(path) in err, err
