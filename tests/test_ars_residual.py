"""The learned residual controller for hard-v0 (issue 13, Build 5): the trainer scores episodes as
the benchmark does, and an exported policy is what its card says (100 Hz, zoh, residual on its base)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from addedinertia_env.bench.runner import run_episode
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.learning.ars_residual import LinearPolicy, base_factory, base_params, export_onnx
from addedinertia_env.learning.paired_batch import run_batch
from addedinertia_env.experiment.task import OBSERVATION_FIELDS


def test_the_trainer_scores_an_episode_as_the_benchmark_does():
    """The batched trainer's oracle and base episodes of a hard-v0 scenario give the benchmark's
    ranked error (MuJoCo, with the passive tail) to within the engines' difference."""
    suite = load_suite("hard-v0")
    params = base_params(suite, "pid")
    batch = run_batch(suite, [0, 0], base_factory("pid", params), split="tuning", oracle=[True, False])
    seed = suite.split_seed("tuning", 0)
    for j, name in enumerate(("oracle", "pid")):
        row = run_episode(suite.task(suite.scenario(seed), name))
        assert row["failure"] is None
        assert batch.rel_error[j] == pytest.approx(row["rel_error"], abs=2e-5), name
    with pytest.raises(ValueError, match="held out"):
        run_batch(suite, [0], base_factory("pid", params), split="test")


def test_a_zero_correction_is_the_base_and_the_oracle_is_paired_on_the_same_scenario():
    suite = load_suite("hard-v0")
    make = base_factory("pid", base_params(suite, "pid"))
    plain = run_batch(suite, [3], make)
    zero = run_batch(suite, [3], make, policy=lambda obs, slots: np.zeros(len(slots), np.float32), residual_scale=0.1)
    assert zero.rel_error[0] == plain.rel_error[0]
    pushed = run_batch(suite, [3], make, policy=lambda obs, slots: np.ones(len(slots), np.float32),
                       residual_scale=0.1)
    assert pushed.rel_error[0] != plain.rel_error[0]  # the correction reaches the rig


def _fake_run(tmp_path, theta):
    n = len(OBSERVATION_FIELDS)
    rng = np.random.default_rng(0)
    np.savez(tmp_path / "policy.npz", mean=rng.normal(size=n), std=rng.uniform(0.5, 2.0, n), theta=theta)
    card = {"algo": "ars", "suite": "hard-v0", "split": "train", "base": "pid", "base_params":
            {"feedforward": False, "prespin": True, "spinup_time_s": 0.4, "observer": True,
             "observer_bandwidth": 20.0, "omega_c": 15.0, "zeta": 1.0, "integral_ratio": 0.3},
            "seed": 0, "scale": 0.1, "action_repeat": 10, "cost": {"env_steps": 1000, "cpu_minutes": 0.5}}
    (tmp_path / "training_card.json").write_text(json.dumps(card))


def test_an_exported_policy_runs_at_100_hz_on_its_base_and_matches_its_card(tmp_path):
    from agents.onnx_policy import OnnxPolicy

    theta = np.random.default_rng(1).normal(scale=0.5, size=len(OBSERVATION_FIELDS) + 1)
    _fake_run(tmp_path, theta)
    card = export_onnx(tmp_path, tmp_path / "p.onnx")
    assert card["size_bytes"] < 1_000_000 and card["parity_max_abs_diff"] < 1e-5
    assert card["policy_rate_hz"] == 100.0 and card["board_mode"] == "zoh" and card["action_repeat"] == 10
    policy = OnnxPolicy(tmp_path / "p.onnx")
    assert policy.policy_rate_hz == 100.0 and policy.board_mode == "zoh"
    assert policy.residual_base == "pid" and policy.residual_scale == 0.1
    # trained with pid deciding once per 100 Hz action, so it must run that way everywhere
    assert policy.residual_base_rate == "policy" and card["residual"]["base_rate"] == "policy"
    assert policy.train_cpu_minutes == 0.5 and policy.base is not None
    linear = LinearPolicy(**{k: np.array(v) for k, v in card["linear_policy"].items()})
    obs = np.random.default_rng(2).normal(size=(50, len(OBSERVATION_FIELDS))).astype(np.float32)
    np.testing.assert_allclose(policy.network(obs).reshape(-1), linear(obs), atol=1e-5)
    assert np.any(np.abs(linear(obs)) > 0.01)  # a real correction, not a constant


def test_the_trainers_share_their_run_arguments_and_export_only_when_asked(tmp_path, capsys):
    """add_run_arguments / export_and_report (ars_residual, score_ars): --out is required, --onnx optional;
    the export runs and is reported only when --onnx is given."""
    import argparse  # noqa: PLC0415

    from addedinertia_env.learning.ars_residual import add_run_arguments, export_and_report  # noqa: PLC0415

    parser = argparse.ArgumentParser()
    add_run_arguments(parser)
    args = parser.parse_args(["--out", str(tmp_path)])
    assert args.out == tmp_path and args.onnx is None
    with pytest.raises(SystemExit):
        parser.parse_args([])
    calls = []

    def export(run, onnx):
        calls.append((run, onnx))
        return {"size_bytes": 12, "parity_max_abs_diff": 3e-8}

    export_and_report(export, args.out, args.onnx)
    assert calls == [] and capsys.readouterr().out == ""
    export_and_report(export, args.out, tmp_path / "p.onnx")
    assert calls == [(tmp_path, tmp_path / "p.onnx")]
    assert capsys.readouterr().out == f"wrote {tmp_path / 'p.onnx'} (12 bytes, parity 3.00e-08)\n"
