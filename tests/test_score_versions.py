"""Score versions (bench/versions.py): every bench row carries the score's version, and the
leaderboard and a resumed run refuse to mix versions (issue 26 item 6)."""

from __future__ import annotations

import json

import pytest

from addedinertia_env.bench.leaderboard import RowsError, load_rows
from addedinertia_env.bench.resume import RowsFileError, prepare_output
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.bench.score import MEMORY_SCORE_VERSION
from addedinertia_env.bench.versions import (FIELD, LEGACY, SCORE_VERSION, ScoreVersionError, check_versions,
                                              row_version)
from addedinertia_env.cli import main


def _rows(controller: str, version: str | None, n: int = 6, suite: str = "synthetic") -> list[dict]:
    rows = []
    for k in range(n):
        row = {"controller": controller, "suite": suite, "split": "test", "scenario": f"s{k}", "seed": k,
               "lambda66_true": 1.0, "lambda66_est": 1.0 + 0.001 * k, "rel_error": 0.001 * k, "energy_J": 1.0,
               "tracking_rms_rad": 1e-4, "saturated_frac": 0.0, "wall_s": 1.0, "version": "0.1.0", "commit": "abc"}
        if version is not None:
            row[FIELD] = version
        rows.append(row)
    return rows


def _write(path, rows) -> str:
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(path)


def test_one_version_is_ranked_and_rows_without_one_are_v0():
    assert row_version({}) == LEGACY and row_version({FIELD: SCORE_VERSION}) == SCORE_VERSION
    assert check_versions({"a": _rows("pd", SCORE_VERSION), "b": _rows("lqr", SCORE_VERSION)}) == SCORE_VERSION
    assert check_versions({"a": _rows("pd", None)}) == LEGACY  # an old board alone is ranked as before


@pytest.mark.parametrize("versions", [(SCORE_VERSION, None), (SCORE_VERSION, "capped-mean-v7")])
def test_the_leaderboard_refuses_to_mix_versions_naming_files_and_versions(tmp_path, capsys, versions):
    a = _write(tmp_path / "new.jsonl", _rows("pd", versions[0]))
    b = _write(tmp_path / "old.jsonl", _rows("lqr", versions[1]))
    shown = versions[1] or LEGACY
    with pytest.raises(RowsError, match=rf"new\.jsonl: {SCORE_VERSION}; .*old\.jsonl: {shown}"):
        load_rows([a, b])
    assert main(["bench", "leaderboard", a, b]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "different score versions" in err and "old.jsonl" in err and shown in err
    # one file mixing versions is refused the same way
    c = _write(tmp_path / "both.jsonl", _rows("pd", versions[0]) + _rows("lqr", versions[1]))
    with pytest.raises(RowsError, match=rf"both\.jsonl: .*{shown}"):
        load_rows([c])


def test_a_version_this_code_does_not_write_is_refused_alone(tmp_path):
    path = _write(tmp_path / "future.jsonl", _rows("pd", "capped-mean-v9"))
    with pytest.raises(ScoreVersionError, match=r"'capped-mean-v9' .*future\.jsonl.* is not one this code ranks"):
        check_versions({path: _rows("pd", "capped-mean-v9")})
    with pytest.raises(RowsError, match="not one this code ranks"):
        load_rows([path])


def test_leaderboard_json_states_the_version(tmp_path, capsys):
    a = _write(tmp_path / "a.jsonl", _rows("pd", SCORE_VERSION) + _rows("lqr", SCORE_VERSION))
    assert main(["bench", "leaderboard", a, "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["score_version"] == SCORE_VERSION


def test_a_resumed_run_never_appends_to_rows_of_another_version(tmp_path):
    key = {"controller": "pd", "suite": "synthetic", "split": "test"}
    path = tmp_path / "rows.jsonl"
    _write(path, _rows("pd", None))
    with pytest.raises(RowsFileError, match=rf"score version\(s\) \['{LEGACY}'\]; this run writes '{SCORE_VERSION}'"):
        prepare_output(path, key)
    _write(path, _rows("pd", SCORE_VERSION))
    kept, _ = prepare_output(path, key)
    assert len(kept) == 6


def test_memory_suite_rows_carry_the_version_and_the_a66_zero_truth(tmp_path, capsys):
    """memory-v1: the memory presets, scored against A66(0) (not A66 at the swing frequency);
    its row says so by its version. The oracle tracks the truth, so its error is the method's
    own memory bias, percent-sized, not the few 0.01 % of memory-free water."""
    suite = load_suite("memory-v1")
    assert set(suite.presets) == {"wigley-2m-memory", "spheroid-7-memory"}
    for sc in suite.scenarios("test")[:2] + suite.scenarios("tuning")[:2]:
        assert sc.rig.hydrodynamics is not None  # the water remembers in every scenario
    out = tmp_path / "rows.jsonl"
    assert main(["bench", "run", "--suite", "memory-v1", "--controller", "oracle", "--seeds", "1", "--jobs", "1",
                 "--out", str(out), "--no-progress"]) == 0
    row = json.loads(out.read_text().splitlines()[0])
    sc = suite.scenarios("test")[0]
    from addedinertia_env.hydro.radiation import truth_block

    block = truth_block(sc.rig.hull.J_hull, sc.rig.hull.lambda66, sc.rig.spring.c, sc.rig.hydrodynamics)
    # memory-v1 ranks the memory-corrected estimate (its suite says so), a score of its own version
    assert suite.ranked == "memory-corrected" and row["ranked_score"] == "memory-corrected"
    assert row[FIELD] == MEMORY_SCORE_VERSION != SCORE_VERSION and row["suite"] == "memory-v1"
    assert row["lambda66_true"] == pytest.approx(sc.rig.hull.lambda66, rel=1e-12) == block["lambda66"]
    assert abs(row["lambda66_true"] / block["A66_swing"] - 1.0) > 5e-3  # not the swing frequency's A66
    assert row["rel_error"] == pytest.approx(row["lambda66_est"] / row["lambda66_true"] - 1.0)
    assert abs(row["rel_error"]) < 3e-3  # the memory corrected for: not the method's percent-sized memory bias
    # resumed under its own version; a board refuses to rank it beside as-written rows
    assert main(["bench", "run", "--suite", "memory-v1", "--controller", "oracle", "--seeds", "1", "--jobs", "1",
                 "--out", str(out), "--no-progress"]) == 0
    with pytest.raises(ScoreVersionError, match="different score versions"):
        check_versions({"memory": [row], "as-written": _rows("pd", SCORE_VERSION)})


def test_a_suite_names_the_estimate_it_ranks(tmp_path):
    from addedinertia_env.sim.presets import ConfigError

    assert load_suite("standard-v0").ranked == "as-written"  # the default: the method as written
    text = (load_suite("memory-v1").source and open(load_suite("memory-v1").source).read())
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("ranked: memory-corrected", "ranked: truth"))
    with pytest.raises(ConfigError, match=r"bad\.yaml: ranked = 'truth'; expected one of as-written, memory-corrected"):
        load_suite(str(bad))


def test_an_env_on_a_suite_rewards_the_estimate_the_suite_ranks():
    from addedinertia_env.vector.env import ReverseStrokeVectorEnv

    assert ReverseStrokeVectorEnv(2, suite="memory-v1", suite_split="tuning").score_method == "memory-corrected"
    assert ReverseStrokeVectorEnv(2, suite="standard-v0", suite_split="tuning").score_method == "as-written"
