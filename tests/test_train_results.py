"""Training shows its result (issue 31): the final evaluation's median |error| in percent, the
failure rate and where the curve is, on stderr; a run shorter than eval.freq still writes
eval/curve.jsonl (its final evaluation); TensorBoard logs the failure rate beside the error."""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("stable_baselines3")

from addedinertia_env.cli import main  # noqa: E402
from addedinertia_env.cli.train import final_eval_line  # noqa: E402
from addedinertia_env.learning.callbacks import SCALARS_NOTE, EpisodeMetricsCallback  # noqa: E402
from addedinertia_env.learning.toy import TOY_ENV_ID  # noqa: E402


def _curve(path):
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def test_a_run_shorter_than_eval_freq_still_has_its_curve_and_says_where(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--algo", "ppo", "--env", TOY_ENV_ID, "--timesteps", "512", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    rows = _curve(out / "eval" / "curve.jsonl")
    card = json.loads((out / "training_card.json").read_text())
    assert card["config"]["eval"]["freq"] > 512  # so no periodic evaluation ran: the row is the final one
    assert len(rows) == 1 and rows[0]["final"] and rows[0]["timesteps"] == card["cost"]["env_steps"]
    assert rows[0]["mean_reward"] == pytest.approx(card["final_eval"]["mean_reward"])
    assert "final evaluation, 5 deterministic episode(s)" in err
    assert f"curve: {out / 'eval' / 'curve.jsonl'}" in err and f"tensorboard --logdir {out}/tb" in err


def test_final_line_gives_percent_and_failures():
    line = final_eval_line({"n_episodes": 8, "mean_reward": -41.6, "failed_estimates": 1, "failure_rate": 0.125,
                            "median_abs_rel_error": 0.002634, "mean_abs_rel_error": 0.00277}, 10000)
    assert "median |lambda66 error| 0.263 %" in line and "1 of 8 failed" in line and "eval seed 10000" in line


class _Logger:
    def __init__(self):
        self.means: dict[str, list[float]] = {}
        self.records: dict[str, object] = {}

    def record_mean(self, key, value):
        self.means.setdefault(key, []).append(value)

    def record(self, key, value, exclude=None):
        self.records[key] = value


def test_tensorboard_failure_rate_beside_the_error_of_the_estimated_episodes():
    cb = EpisodeMetricsCallback()
    logger = _Logger()
    cb.__dict__["_logger"] = logger  # BaseCallback.logger reads the model's; give it ours
    type(cb).logger = property(lambda self: self.__dict__["_logger"])
    try:
        infos = [{"rel_error": 0.01, "energy_J": 1.0}, {"rel_error": math.nan, "energy_J": 2.0},
                 {"rel_error": -0.03, "energy_J": 3.0}, {"rel_error": 0.5}]
        cb.locals = {"infos": infos, "dones": [True, True, True, False]}  # the last did not end
        cb._on_training_start()
        cb._on_step()
    finally:
        del type(cb).logger
    assert logger.means["episode/failure_rate"] == [0.0, 1.0, 0.0]  # mean 1/3: every ended episode counts
    assert logger.means["episode/abs_rel_error"] == [0.01, 0.03]  # only the estimated ones
    assert logger.means["episode/energy_J"] == [1.0, 2.0, 3.0]
    assert logger.records["about/scalars"] == SCALARS_NOTE and "failure_rate" in SCALARS_NOTE


@pytest.mark.slow
def test_a_short_run_on_the_real_task_prints_its_error_in_percent(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--algo", "ppo", "--timesteps", "256", "--n-envs", "2", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    card = json.loads((out / "training_card.json").read_text())
    final = card["final_eval"]
    assert f"median |lambda66 error| {100 * final['median_abs_rel_error']:.3f} %" in err
    assert f"{final['failed_estimates']} of {final['n_episodes']} failed" in err
    assert _curve(out / "eval" / "curve.jsonl")[-1]["failure_rate"] == final["failure_rate"]
