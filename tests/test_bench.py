"""The benchmark: suites, rows, leaderboard statistics, outside controllers, CLI errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.bench.leaderboard import iqm, summarise
from addedinertia_env.bench.statistics import median_ci as bootstrap_median_ci
from addedinertia_env.bench.runner import REQUIRED_FIELDS
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.cli import main
from addedinertia_env.sim.presets import ConfigError
from agents.base import Controller


class TinyController(Controller):
    """An outside controller: a weak P loop on the tracking error (no feedforward)."""

    name = "tiny"

    def current(self, obs):
        if obs["is_reverse"] < 0.5:
            return 0.0
        return -self.ctx.inertia_prior * 100.0 * obs["tracking_error"] / self.ctx.k_t


def make_tiny():
    return TinyController()


def test_standard_suite_has_disjoint_tuning_and_test_splits():
    s = load_suite("standard-v0")
    tuning, test = set(s.seeds("tuning")), set(s.seeds("test"))
    assert len(tuning) + len(test) >= 50 and not tuning & test
    scen = s.scenarios("test")
    assert {sc.sensor_quality for sc in scen} >= {"realistic", "ideal"}
    ratios = [sc.rig.hull.lambda66 / sc.rig.hull.J_hull for sc in scen]
    assert 0.5 <= min(ratios) and max(ratios) <= 2.5 and max(ratios) - min(ratios) > 1.0
    assert len({s.preset_for(sc.seed) for sc in scen}) == 2
    assert s.split_of(s.seeds("test")[0]) == "test"


def test_unknown_suite_is_a_config_error():
    with pytest.raises(ConfigError, match="unknown suite"):
        load_suite("no-such-suite")


@pytest.mark.parametrize("block, value, message", [
    ("fixed", "3", r"fixed = 3: expected a mapping with keys from \['J_flywheel'"),
    ("fixed", "{colour: red}", r"fixed: unknown key\(s\) \['colour'\]; allowed keys are"),
    ("ranges", "{colour: [1, 2]}", r"ranges: unknown key\(s\) \['colour'\]"),
])
def test_a_suite_block_that_is_no_mapping_or_has_unknown_keys_is_refused_by_name(tmp_path, block, value, message):
    """Every block of a suite file is checked the same way (config_io.check_keys): a value that
    is not a mapping was a TypeError (exit 70) before; now a ConfigError naming file and block."""
    text = (Path(__file__).resolve().parents[1] / "configs" / "suites" / "smoke.yaml").read_text()
    lines = [line for line in text.splitlines() if not line.startswith(("fixed:", "ranges:", "  hold_s:",
                                                                          "  sensor_quality:"))]
    path = tmp_path / "suite.yaml"
    path.write_text("\n".join(lines) + f"\n{block}: {value}\n")
    with pytest.raises(ConfigError, match=rf"{path}: {message}"):
        load_suite(str(path))


def test_bench_run_writes_rows_with_required_fields(tmp_path, capsys):
    out = tmp_path / "rows.jsonl"
    rc = main(["bench", "run", "--suite", "smoke", "--controller", "pd", "--seeds", "1", "--jobs", "1",
               "--out", str(out), "--no-progress", "--json"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rows"] == 1
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 1
    row = rows[0]
    for key in REQUIRED_FIELDS:
        assert key in row
    assert row["controller"] == "pd" and row["suite"] == "smoke" and row["seed"] == 1000
    assert row["lambda66_true"] > 0 and row["energy_J"] > 0 and 0 <= row["saturated_frac"] <= 1
    if row["rel_error"] is not None:
        assert row["rel_error"] == pytest.approx(row["lambda66_est"] / row["lambda66_true"] - 1.0)
        assert abs(row["rel_error"]) < 0.5


def test_outside_controller_through_module_factory(tmp_path):
    out = tmp_path / "tiny.jsonl"
    rc = main(["bench", "run", "--suite", "smoke", "--controller", "test_bench:make_tiny", "--seeds", "1",
               "--jobs", "1", "--out", str(out), "--no-progress"])
    assert rc == 0
    row = json.loads(out.read_text().splitlines()[0])
    assert row["controller"] == "test_bench:make_tiny"
    assert row["tracking_rms_rad"] is not None and row["tracking_rms_rad"] > 0


@pytest.mark.parametrize("argv", [
    ["bench", "run", "--suite", "no-such-suite", "--controller", "pd"],
    ["bench", "run", "--suite", "smoke", "--controller", "no-such-controller"],
    ["bench", "run", "--suite", "smoke", "--controller", "no_such_module_xyz:factory"],
    ["bench", "leaderboard", "/nonexistent/rows.jsonl"],
])
def test_bad_names_exit_2(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("addedinertia: error:") and err.count("\n") == 1


def _rows(controller, errors, energy=1.0):
    return [{"controller": controller, "suite": "synthetic", "split": "test", "scenario": f"s{k}", "seed": k,
             "lambda66_true": 1.0, "lambda66_est": None if e is None else 1.0 + e, "rel_error": e,
             "energy_J": energy, "tracking_rms_rad": 1e-4, "saturated_frac": 0.0, "wall_s": 1.0,
             "version": "0.1.0", "commit": "abc1234"} for k, e in enumerate(errors)]


def test_leaderboard_ranks_by_median_with_known_values():
    rng = np.random.default_rng(0)
    good = rng.uniform(-0.004, 0.004, 41)  # median |e| about 0.002
    good[0] = 0.0
    bad = np.concatenate([rng.uniform(0.01, 0.03, 40), [-0.02]])
    mixed = [0.001] * 20 + [None] * 21  # more than half failures: median is a failure
    rows = _rows("bad", bad) + _rows("good", good) + _rows("mixed", mixed)
    entries = summarise(rows, n_boot=500)
    assert [e["controller"] for e in entries] == ["good", "bad", "mixed"]
    g = entries[0]
    assert g["median_abs_error"] == pytest.approx(float(np.median(np.abs(good))))
    lo, hi = g["ci95_median"]
    assert lo <= g["median_abs_error"] <= hi and hi - lo < 0.003
    assert entries[2]["failure_rate"] == pytest.approx(21 / 41) and math.isinf(entries[2]["median_abs_error"])
    assert all(e["version"] == "0.1.0" and e["commit"] == "abc1234" for e in entries)


def test_iqm_and_bootstrap_on_known_data():
    assert iqm(np.arange(8.0)) == pytest.approx(np.mean([2, 3, 4, 5]))
    assert iqm(np.array([0.0, 1.0, 2.0, 100.0])) == pytest.approx(1.5)
    x = np.random.default_rng(5).normal(3.0, 1.0, 401)
    lo, hi = bootstrap_median_ci(x, n_boot=1000)
    assert lo < np.median(x) < hi and lo > 2.7 and hi < 3.3
    lo_i, hi_i = bootstrap_median_ci(np.array([1.0, math.inf, 2.0]), n_boot=200)
    assert lo_i >= 1.0 and math.isinf(hi_i)


def test_leaderboard_cli_formats(tmp_path, capsys):
    rows = _rows("a", [0.001, -0.002, 0.003]) + _rows("b", [0.02, 0.03, -0.01], energy=5.0)
    f = tmp_path / "rows.jsonl"
    f.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    assert main(["bench", "leaderboard", str(f), "--format", "json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert [e["controller"] for e in obj["entries"]] == ["a", "b"]
    md = tmp_path / "lb.md"
    assert main(["bench", "leaderboard", str(f), "--format", "md", "--out", str(md)]) == 0
    text = md.read_text()
    assert text.index("| 1 | a |") < text.index("| 2 | b |") and "abc1234" in text
    assert (tmp_path / "figures" / "lb-error-energy.png").stat().st_size > 1000
    html = tmp_path / "lb.html"
    assert main(["bench", "leaderboard", str(f), "--format", "html", "--out", str(html)]) == 0
    page = html.read_text()
    assert "<svg" in page and "<table id='leaderboard'" in page and 'src="http' not in page
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"controller": "x"}\n')
    assert main(["bench", "leaderboard", str(bad)]) == 2
