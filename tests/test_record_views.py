"""The run record owns its typed views (known rig, phase blocks, sampling, plausibility limits),
computed once; the ``rig`` block has one schema that the reader, ``KnownRig`` and the lab file share."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.records import plausibility
from addedinertia_env.identify import identify
from addedinertia_env.records.record import RecordError, measure_sampling, read_record, sampling, write_record
from addedinertia_env.rig.known import RIG_BLOCK, KnownRig, block_problems
from addedinertia_env.sim.presets import ConfigError
from hw_adapter.lab import LAB_RIG_KEYS, known_rig, lab_from_mapping
from hw_adapter.messages import Caps

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def count_checks(monkeypatch):
    """How often the plausibility check runs (the views call it through the module)."""
    calls = []
    original = plausibility.check_plausible

    def spy(rec):
        calls.append(rec.name)
        return original(rec)

    monkeypatch.setattr(plausibility, "check_plausible", spy)
    return calls


def test_views_are_computed_once_and_equal_what_the_record_gives(realistic_record, clone):
    rec = clone(realistic_record[0])
    views = rec.views
    assert rec.views is views and rec.known is views.known and sampling(rec) is views.sampling
    assert views.known == KnownRig.from_block(rec.rig)
    phase = rec.phase
    starts = np.concatenate([[0], np.nonzero(phase[1:] != phase[:-1])[0] + 1])
    blocks = views.phase_blocks
    assert blocks.starts.tolist() == starts.tolist() and blocks.labels == tuple(str(p) for p in phase[starts])
    a = int(np.argmax(phase == "free"))
    assert blocks.first("free") == slice(a, a + int(np.argmax(phase[a:] != "free")))
    assert blocks.first("nonsense") is None
    assert views.sampling == measure_sampling(rec)
    assert views.limits == plausibility.check_plausible(rec)


def test_the_reader_checks_once_and_identify_does_not_check_again(tmp_path, realistic_record, clone, count_checks):
    path = write_record(clone(realistic_record[0]), tmp_path / "run.csv")
    rec = read_record(path)
    assert count_checks == [str(path)]
    result = identify([rec], "energy")
    assert np.isfinite(result.lambda66) and count_checks == [str(path)]  # the reader's check, kept


def test_a_record_made_in_memory_is_checked_by_identify_once(realistic_record, clone, count_checks):
    rec = clone(realistic_record[0])
    identify([rec], "energy")
    identify([rec], "energy")
    assert len(count_checks) == 1


def test_without_truth_shares_the_views(realistic_record, clone):
    rec = clone(realistic_record[0])
    bare = rec.without_truth()
    assert "truth" not in bare.meta and bare.views is rec.views


def test_replaced_data_gets_new_views(realistic_record, clone):
    """A column replaced, or the rig block or the experiment's kind changed, is seen; the plausibility
    check then runs again on the new data."""
    rec = clone(realistic_record[0])
    before = rec.views
    rec.views.limits  # noqa: B018
    rec.meta["rig"]["c_torsion"] = 40.0
    assert rec.views is not before and rec.known.c_torsion == 40.0
    rec.samples["u"] = rec["u"] * 1e3  # logged in mV
    with pytest.raises(RecordError, match="column 'u'"):
        identify([rec], "energy")
    rec.samples["u"] = rec["u"] / 1e3
    rec.meta["experiment"]["kind"] = "free-decay"
    with pytest.raises(RecordError, match="free-decay"):  # the phases no longer fit the kind
        rec.views.limits  # noqa: B018


# --- one schema for the rig block ---------------------------------------------------------

BLOCK = {"J_hull": 5.8, "J_flywheel": 0.1, "c_torsion": 43.4, "phi_neutral": 0.0, "k_t": 0.25, "R": 0.5,
         "sample_rate": 1000.0}
LAB = {k: v for k, v in BLOCK.items() if k != "sample_rate"}
CAPS = Caps(firmware_version=1, flags=0, sample_period_us=1000, phi_counts=131072, psi_counts=16384, i_max=10.0,
            u_max=24.0, watchdog_ms=100, brake_response_ms=5, board_id="test")


@pytest.mark.parametrize("extra", [{}, {"L": 0.0}, {"L": 5e-4}, {"gear_ratio": 3.0}, {"gear_ratio": 1.0, "L": 0}])
def test_reader_known_rig_and_lab_agree_on_optional_keys(tmp_path, realistic_record, clone, extra):
    """``L`` may be 0 or absent and ``gear_ratio`` absent (= 1), in a record and in a lab file alike
    (spec/run-record.md); both give the same typed rig."""
    rec = clone(realistic_record[0])
    rec.meta["rig"].pop("L", None)
    rec.meta["rig"].update(extra)
    back = read_record(write_record(rec, tmp_path / "run.csv"))
    assert back.known.L == (None if "L" not in extra else extra["L"])
    assert back.known.gear_ratio == extra.get("gear_ratio", 1.0)
    from_lab = known_rig(lab_from_mapping({**LAB, **extra}, "lab.yaml"), CAPS)
    assert from_lab.L == back.known.L and from_lab.gear_ratio == back.known.gear_ratio


@pytest.mark.parametrize("key,value,expected", [("L", -1e-3, ">= 0"), ("gear_ratio", 0.0, "> 0"),
                                                ("J_hull", -1.0, "> 0"), ("motor_friction", {"viscous": -1}, ">= 0"),
                                                ("current_gain_uncertainty", "0.5%", ">= 0")])
def test_reader_and_lab_refuse_the_same_values(tmp_path, realistic_record, clone, key, value, expected):
    rec = clone(realistic_record[0])
    rec.meta["rig"][key] = value
    write_record(rec, tmp_path / "run.csv")
    with pytest.raises(RecordError, match=re.escape(expected)) as from_record:
        read_record(tmp_path / "run.csv")
    assert key in str(from_record.value) and "run.json" in str(from_record.value)
    with pytest.raises(ConfigError, match=re.escape(expected)) as from_lab:
        lab_from_mapping({**LAB, key: value}, "lab.yaml")
    assert key in str(from_lab.value) and "lab.yaml" in str(from_lab.value)


def test_the_lab_file_states_the_labs_keys_of_the_schema():
    assert set(LAB_RIG_KEYS) == {k.name for k in RIG_BLOCK if k.source == "lab"}
    assert {"J_hull", "L", "gear_ratio", "motor_friction"} <= set(LAB_RIG_KEYS)
    assert not {"sample_rate", "i_max", "encoder_counts"} & set(LAB_RIG_KEYS)  # the board states them
    with pytest.raises(ConfigError, match="missing key 'k_t'"):
        lab_from_mapping({k: v for k, v in LAB.items() if k != "k_t"}, "lab.yaml")


def test_block_problems_orders_required_keys_first():
    problems = list(block_problems({**BLOCK, "L": -1.0, "J_hull": "5.8"}))
    assert [p[0] for p in problems] == ["J_hull", "L"]
    assert list(block_problems({k: v for k, v in BLOCK.items() if k != "R"}))[0] == ("R", None, "missing")


def test_no_raw_rig_key_reads_outside_the_schema():
    """Constants are read through ``record.known`` (KnownRig, built from the schema), never by key."""
    raw = re.compile(r"""\.rig\[|\.rig\.get\(|\["rig"\]\[|\["rig"\]\.get\(""")
    allowed = {ROOT / "addedinertia_env" / "rig" / "known.py"}
    found = []
    for package in ("addedinertia_env", "agents", "hw_adapter"):
        for path in (ROOT / package).rglob("*.py"):
            if path in allowed:
                continue
            for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if raw.search(line.split("#")[0]):
                    found.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not found, "\n".join(found)
