"""capped-mean-v3 (bench/score.py, bench/versions.py): rows of a geared rig carry their own score version,
since the energy method books the gearhead's loss there (identify/energy_gear.py) and, from v3, the
motor's cogging (identify/energy_cogging.py); rows of an older estimate on a geared suite (v1, v2) are
never ranked beside them nor resumed by a new run."""

from __future__ import annotations

import pytest
from test_score_versions import _rows, _write

from addedinertia_env.bench import score
from addedinertia_env.bench.leaderboard import RowsError, load_rows
from addedinertia_env.bench.resume import RowsFileError, prepare_output
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.bench.versions import GEARED_SCORE_VERSION, RANKABLE, SCORE_VERSION, row_fields
from addedinertia_env.sim.forces import gear_ratio


def test_a_geared_rig_writes_the_geared_version_and_others_keep_theirs():
    assert row_fields(geared=True) == {"score_version": GEARED_SCORE_VERSION} != row_fields()
    assert all(gear_ratio(sc.rig) > 1.0 for sc in load_suite("drive-v1").scenarios("test"))
    assert all(gear_ratio(sc.rig) == 1.0 for sc in load_suite("standard-v0").scenarios("test"))
    row = {"rel_error": 0.02, **row_fields(geared=True)}
    assert score.row_fields(row) == {"score_version": GEARED_SCORE_VERSION, "score": 0.02}


def test_old_and_new_rows_of_a_geared_suite_are_not_ranked_together(tmp_path):
    a = _write(tmp_path / "old.jsonl", _rows("pd", SCORE_VERSION, suite="drive-v1"))
    b = _write(tmp_path / "new.jsonl", _rows("lqr", GEARED_SCORE_VERSION, suite="drive-v1"))
    with pytest.raises(RowsError, match="different score versions"):
        load_rows([a, b])
    assert load_rows([b])  # one version alone is ranked
    with pytest.raises(score.ScoreVersionError):
        score.check_versions(_rows("pd", SCORE_VERSION) + _rows("lqr", GEARED_SCORE_VERSION))


def test_a_geared_run_does_not_resume_rows_of_the_old_estimate(tmp_path):
    key = {"controller": "pd", "suite": "drive-v1", "split": "test"}
    path = tmp_path / "rows.jsonl"
    _write(path, _rows("pd", SCORE_VERSION, suite="drive-v1"))
    with pytest.raises(RowsFileError, match=rf"this run writes '{GEARED_SCORE_VERSION}'"):
        prepare_output(path, key, version=GEARED_SCORE_VERSION)
    _write(path, _rows("pd", GEARED_SCORE_VERSION, suite="drive-v1"))
    kept, _ = prepare_output(path, key, version=GEARED_SCORE_VERSION)
    assert len(kept) == 6


def test_the_three_versions_side_by_side():
    """What a row carries: the suite's ranked estimate first (memory-corrected), then the gearbox, else
    the plain version; a row's own known version is kept when its score is recomputed; one board
    never ranks two of them together."""
    from addedinertia_env.bench.versions import MEMORY_SCORE_VERSION  # noqa: PLC0415

    assert row_fields(geared=False)["score_version"] == SCORE_VERSION
    assert row_fields(geared=True)["score_version"] == GEARED_SCORE_VERSION
    assert row_fields(geared=False, ranked="memory-corrected")["score_version"] == MEMORY_SCORE_VERSION
    assert len({SCORE_VERSION, GEARED_SCORE_VERSION, MEMORY_SCORE_VERSION}) == 3
    geared_row = {"score_version": GEARED_SCORE_VERSION, "rel_error": 0.01}
    assert score.row_fields(geared_row)["score_version"] == GEARED_SCORE_VERSION
    memory_row = {"ranked_score": "memory-corrected", "rel_error": 0.01}
    assert score.row_fields(memory_row)["score_version"] == MEMORY_SCORE_VERSION
    assert score.row_fields({"rel_error": 0.01})["score_version"] == SCORE_VERSION
    for a, b in ((GEARED_SCORE_VERSION, MEMORY_SCORE_VERSION), (SCORE_VERSION, GEARED_SCORE_VERSION)):
        with pytest.raises(score.ScoreVersionError):
            score.check_versions([{"score_version": a, "rel_error": 0.0}, {"score_version": b, "rel_error": 0.0}])
    assert score.check_versions([{"score_version": MEMORY_SCORE_VERSION, "rel_error": 0.0}]) == MEMORY_SCORE_VERSION


V2 = "capped-mean-v2"  # the geared rows written before the cogging was booked (the loss alone)


def test_v2_rows_of_the_loss_alone_are_a_former_version_never_ranked_beside_v3(tmp_path):
    """The estimator changed on geared rigs (cogging booked): v3 is what is written, v2 rows keep their
    version when their score is recomputed, a board of v2 alone still ranks, v2 beside v3 is refused, and
    a new run does not resume v2 rows."""
    assert GEARED_SCORE_VERSION == "capped-mean-v3" and V2 in score.FORMER_VERSIONS and V2 not in score.VERSIONS
    assert V2 in RANKABLE and GEARED_SCORE_VERSION in RANKABLE
    assert score.row_fields({"score_version": V2, "rel_error": 0.01})["score_version"] == V2
    assert score.check_versions([{"score_version": V2, "rel_error": 0.0}]) == V2
    with pytest.raises(score.ScoreVersionError):
        score.check_versions([{"score_version": V2, "rel_error": 0.0}, {"score_version": GEARED_SCORE_VERSION,
                                                                       "rel_error": 0.0}])
    old = _write(tmp_path / "v2.jsonl", _rows("pd", V2, suite="drive-v1"))
    new = _write(tmp_path / "v3.jsonl", _rows("lqr", GEARED_SCORE_VERSION, suite="drive-v1"))
    assert load_rows([old]) and load_rows([new])
    with pytest.raises(RowsError, match="different score versions"):
        load_rows([old, new])
    with pytest.raises(RowsFileError, match=rf"this run writes '{GEARED_SCORE_VERSION}'"):
        prepare_output(old, {"controller": "pd", "suite": "drive-v1", "split": "test"}, version=GEARED_SCORE_VERSION)


@pytest.mark.parametrize("former", score.FORMER_VERSIONS)
def test_every_former_version_ranks_alone_and_is_never_mixed_or_resumed(tmp_path, former):
    """2026-11-28 the energy method changed on every rig (the rest after the release, the torque scale of a
    smooth current, the rotor's creep): each version this code wrote before is a former one, whatever the
    suite. A board of its rows alone ranks; beside what this code writes now it is refused; a new run
    refuses to resume it."""
    current = {"capped-mean-memory-corrected-v1": score.MEMORY_SCORE_VERSION,
               "capped-mean-v2": GEARED_SCORE_VERSION}.get(former, SCORE_VERSION)
    assert former not in score.VERSIONS and current in score.VERSIONS and former in RANKABLE
    old = _write(tmp_path / "old.jsonl", _rows("pd", former))
    new = _write(tmp_path / "new.jsonl", _rows("lqr", current))
    assert load_rows([old]) and load_rows([new])
    with pytest.raises(RowsError, match="different score versions"):
        load_rows([old, new])
    with pytest.raises(RowsFileError, match=rf"this run writes '{current}'"):
        prepare_output(old, {"controller": "pd", "suite": "synthetic", "split": "test"}, version=current)
