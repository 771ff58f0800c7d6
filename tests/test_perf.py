"""``addedinertia perf``: the command runs and reports the contract's fields (no speed asserted:
speed is measured by the command and recorded in docs/PERFORMANCE.md)."""

from __future__ import annotations

import json

import pytest

from addedinertia_env.cli import main
from addedinertia_env.reports.perf import KEPT, measure_batched, render_markdown, with_kept_part


def test_perf_json_has_the_contract_fields(capsys, tmp_path):
    out = tmp_path / "PERF.md"
    out.write_text("an old report, replaced\n\n" + KEPT + "\n\n## A figure measured by hand (kept)\n")
    assert main(["perf", "--max-envs", "16", "--seconds", "0.01", "--repeats", "1", "--vector-envs", "4",
                 "--vector-steps", "120", "--vector-warmup", "2", "--vector-seconds", "0.2", "--vector-repeats", "2", "--json",
                 "--out", str(out)]) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("single_env_steps_per_s", "batched_physics_steps_per_s", "n_envs", "vector_env_samples_per_s",
                "vector_env_agent_steps_per_s", "sync_vector_env_samples_per_s", "vector_n_envs",
                "vector_env_samples_per_cpu_s", "vector_env_samples_per_s_identification_off",
                "vector_env_samples_per_cpu_s_identification_off", "vector_env_samples_per_s_one_process"):
        assert key in result
    kinds = [row["kind"] for row in result["vector_task"]["rows"]]
    assert kinds[0].startswith("single env") and kinds[1].startswith("gym.make_vec sync") and len(kinds) >= 4
    assert all(row["samples_per_cpu_s"] > 0 for row in result["vector_task"]["rows"])
    assert result["vector_n_envs"] == 4 and result["vector_env_samples_per_s"] > 0
    assert result["vector_env_samples_per_s"] == pytest.approx(10 * result["vector_env_agent_steps_per_s"])  # repeat 10
    assert result["n_envs"] == 16
    assert [r["n_envs"] for r in result["sweep"]] == [1, 4, 16]
    assert all(r["steps_per_s"] > 0 and r["time_per_step_us"] > 0 for r in result["sweep"])
    assert result["single_env_steps_per_s"] > 0
    assert result["ratio_batched_to_single"] == result["batched_physics_steps_per_s"] / result["single_env_steps_per_s"]
    assert result["memory"]["bytes_per_env_arrays"] > 0
    assert result["machine"]["nproc"] >= 1 and result["machine"]["cpu"]
    text = out.read_text()
    assert "an old report" not in text and text.endswith(KEPT + "\n\n## A figure measured by hand (kept)\n")
    assert "addedinertia perf" in text and result["machine"]["cpu"] in text and "GPU" in text
    if result["vector_workers"] > 1:  # the headline row (2 processes on a 2-core machine): the median of 2 runs
        head = result["vector_task"]["rows"][2]
        assert len(head["repeat_samples_per_s"]) == 2 and "median of 2 runs" in text and "--vector-repeats 2" in text
        assert len(head["time_shares"]) == 2 and "Where the headline row's wall time went" in text
        for shares, clocked in zip(head["time_shares"], head["clocked_s"]):  # each process's time, counted once
            assert shares["sample"] > 0 and min(shares.values()) >= 0 and sum(shares.values()) == pytest.approx(1.0)
            # the clock ran over the window, counted once: each worker's clock also holds the latency of the
            # on/off messages (a few ms, tens under load), so the window is 120 steps (about 0.1 s) and 40 ms are allowed;
            # time counted twice would read about twice the wall time
            assert abs(clocked - head["wall_s"]) < 0.25 * head["wall_s"] + 0.04
    assert (tmp_path / "figures" / "perf_time_vs_n.png").stat().st_size > 1000


def test_perf_refuses_bad_input(capsys):
    assert main(["perf", "--seconds", "-1"]) == 2
    assert "--seconds" in capsys.readouterr().err


def test_batched_measurement_counts_n_steps_per_call():
    row = measure_batched(8, seconds=0.01, repeats=1)
    assert row["n_envs"] == 8
    assert abs(row["steps_per_s"] * row["time_per_step_us"] * 1e-6 - 8) < 1e-9
    assert "GPU" in render_markdown({**_fake(row)}, "addedinertia perf", None)


def _fake(row):
    machine = {"cpu": "x", "nproc": 2, "python": "3", "numpy": "2", "mujoco": "3", "load_avg_1_5_15": [0, 0, 0],
               "load_avg_at_end": [0, 0, 0]}
    single = {"steps_per_s": 1.0, "time_per_step_us": 1.0}
    return {"machine": machine, "date": "d", "repeats": 1, "seconds_per_measurement": 0.01,
            "single_env_steps_per_s": 1.0, "batched_physics_steps_per_s": row["steps_per_s"], "n_envs": 8,
            "ratio_batched_to_single": row["steps_per_s"], "float32": row, "with_sensors": row,
            "memory": {"bytes_per_env_arrays": 1.0, "bytes_per_env_tracemalloc_peak": 1.0},
            "single_env": {"before_sweep": single, "after_sweep": single}, "sweep": [row]}


def test_whole_task_measurement_counts_ended_episodes_with_and_without_identification():
    from addedinertia_env.vector.measure import measure_batched as measure_task

    short = dict(hold_s=0.5, fixed={"period_s": 3.0})
    scored = measure_task(2, steps=250, warmup_steps=0, **short)
    plain = measure_task(2, steps=250, warmup_steps=0, score_episodes=False, **short)
    for row in (scored, plain):
        assert row["episodes_ended"] >= 2 and row["samples"] == 2 * 250 * 10
        assert row["samples_per_s"] > 0 and row["samples_per_cpu_s"] > 0
        # a step with an odd number of ended episodes exists (2 envs, at least 2 episodes, and they
        # do not all end in pairs in these runs), and at most every step is one
        assert 0 < row["odd_end_steps_frac"] * 250 <= row["episodes_ended"]
    assert scored["median_abs_rel_error"] < 1.0  # identified
    assert plain["median_abs_rel_error"] != plain["median_abs_rel_error"]  # nan: nothing identified


def test_the_headline_is_the_median_run_and_keeps_every_run():
    from addedinertia_env.vector.measure import median_run

    runs = [{"samples_per_s": v, "tag": k} for k, v in enumerate([7.0, 9.0, 8.0])]
    row = median_run(runs)
    assert row["tag"] == 2 and row["repeat_samples_per_s"] == [7.0, 9.0, 8.0]
    assert median_run(runs[:2])["tag"] == 0  # even count: the lower middle run, never the best
    assert "repeat_samples_per_s" not in runs[2]  # the runs themselves are left as they were


def test_the_kept_part_follows_the_fresh_report_and_nothing_else_of_the_old_page():
    assert with_kept_part("new\n", None) == "new\n"
    assert with_kept_part("new\n", "old page without the marker\n") == "new\n"
    assert with_kept_part("new\n\n", "old\n" + KEPT + "\nkept 1\nkept 2\n") == "new\n\n" + KEPT + "\nkept 1\nkept 2\n"
