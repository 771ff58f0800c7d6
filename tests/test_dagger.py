"""The oracle distilled by DAgger (issue 13, Build 5): the teacher's labels are the oracle's actions on
the states the student visits, the student learns them, and its ONNX export is the numpy student."""

from __future__ import annotations

import json

import numpy as np
import pytest

from addedinertia_env.bench.suites import load_suite
from addedinertia_env.learning.ars_residual import base_factory, base_params
from addedinertia_env.learning.dagger import MLPStudent, export_onnx, fit, load_student, train
from addedinertia_env.learning.paired_batch import run_batch
from addedinertia_env.experiment.task import OBSERVATION_FIELDS

N_OBS = len(OBSERVATION_FIELDS)


def test_a_rig_that_always_follows_the_teacher_runs_the_oracles_episode():
    """With ``teacher_mix=1`` every action the rig gets is the teacher's: the episode, its labels
    and its lambda66 are the oracle slot's on the same scenario and noise; the base's action is
    still recorded beside it."""
    suite = load_suite("hard-v0")
    make = base_factory("pid", base_params(suite, "pid"))
    oracle = run_batch(suite, [5], make, oracle=[True])
    taught = run_batch(suite, [5], make, teacher_labels=True, teacher_mix=1.0)
    assert taught.rel_error[0] == pytest.approx(oracle.rel_error[0], abs=1e-12)
    lab = taught.labels
    assert lab.followed_teacher.all() and len(lab.teacher_action) == taught.agent_steps
    hold = lab.observations[:, list(OBSERVATION_FIELDS).index("is_hold")] > 0.5
    assert np.all(lab.teacher_action[hold][:-1] == 0.0)  # the oracle commands nothing in the hold
    assert np.any(np.abs(lab.base_action[hold]) > 0.01)  # pid pre-spins there
    plain = run_batch(suite, [5], make, teacher_labels=True)  # no mixing: pid's own episode, labelled
    assert not plain.labels.followed_teacher.any()
    assert plain.rel_error[0] == run_batch(suite, [5], make).rel_error[0]
    with pytest.raises(ValueError, match="teacher_labels"):
        run_batch(suite, [5], make, teacher_mix=0.5)


def test_fit_learns_a_smooth_function_of_the_observation():
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(3000, N_OBS)).astype(np.float32)
    obs[:, list(OBSERVATION_FIELDS).index("is_reverse")] = 1.0
    target = np.clip(0.4 * np.tanh(obs[:, 0]) - 0.3 * obs[:, 3] * obs[:, 17] / 3.0, -1, 1)
    student = MLPStudent(obs.mean(axis=0), obs.std(axis=0) + 1e-3, hidden=16, seed=0)
    before = float(np.mean((student(obs) - target) ** 2))
    after = fit(student, obs, target, steps=800, seed=0)
    assert before > 0.02 and after < 0.1 * before
    assert float(np.mean((student(obs) - target) ** 2)) == pytest.approx(after, rel=1e-4)


def test_dagger_learns_the_teachers_hold_on_a_tiny_problem(tmp_path):
    """Two iterations on four training scenarios: the student's imitation loss on the fresh
    scenarios of iteration 1 is a fraction of the untrained student's on those of iteration 0."""
    card = train(tmp_path, base="pid", gate="hold", seed=7, iterations=2, scenarios=4, validate=2,
                 fit_steps=400, hidden=16, log=lambda m: None)
    rows = [json.loads(line) for line in (tmp_path / "curve.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [-1, 0, 1]
    assert rows[2]["onpolicy_loss"] < 0.3 * rows[1]["onpolicy_loss"]
    assert card["cost"]["episodes"] == 2 * 2 + 2 * 4 + 2 * 2 and card["gate"] == "hold"
    student = load_student(tmp_path / "policy.npz")
    assert student.gate_name == "hold" and student.n_parameters() == 16 * N_OBS + 16 + 16 * 16 + 16 + 16 + 1


def test_an_exported_student_is_the_numpy_student_and_says_how_to_run(tmp_path):
    from agents.onnx_policy import OnnxPolicy

    rng = np.random.default_rng(1)
    student = MLPStudent(rng.normal(size=N_OBS), rng.uniform(0.5, 2.0, N_OBS), hidden=24, seed=3, gate="hold")
    student.weights[4] = rng.normal(scale=0.5, size=(1, 24))  # a real output layer (zero when untrained)
    np.savez(tmp_path / "policy.npz", mean=student.mean, std=student.std, gate=student.gate_name, *student.weights)
    params = {"feedforward": False, "prespin": True, "spinup_time_s": 0.4, "observer": True,
              "observer_bandwidth": 20.0, "omega_c": 15.0, "zeta": 1.0, "integral_ratio": 0.3}
    (tmp_path / "training_card.json").write_text(json.dumps(
        {"algo": "dagger", "suite": "hard-v0", "split": "train", "base": "pid", "base_params": params, "seed": 0,
         "scale": 1.0, "gate": "hold", "action_repeat": 10, "cost": {"env_steps": 1000, "cpu_minutes": 0.5}}))
    card = export_onnx(tmp_path, tmp_path / "p.onnx")
    assert card["size_bytes"] < 1_000_000 and card["parity_max_abs_diff"] < 1e-5
    assert card["policy_rate_hz"] == 100.0 and card["board_mode"] == "zoh" and card["residual"]["gate"] == "hold"
    policy = OnnxPolicy(tmp_path / "p.onnx")
    assert policy.residual_base == "pid" and policy.residual_scale == 1.0 and policy.residual_base_rate == "policy"
    assert policy.policy_rate_hz == 100.0 and policy.train_cpu_minutes == 0.5
    obs = rng.normal(size=(64, N_OBS)).astype(np.float32)
    obs[:, list(OBSERVATION_FIELDS).index("is_hold")] = np.arange(64) % 2
    ours = load_student(tmp_path / "policy.npz")(obs)
    np.testing.assert_allclose(policy.network(obs).reshape(-1), ours, atol=1e-5)
    assert np.all(ours[::2] == 0.0) and np.any(np.abs(ours[1::2]) > 0.01)  # gated: acts in the hold only


def test_the_oracle_ablation_with_nothing_taken_away_is_the_oracle(monkeypatch):
    """``DegradedOracle`` with the true state, J and k_t acts as the benchmark's oracle; with the
    prior J it does not."""
    from addedinertia_env.learning import paired_batch
    from addedinertia_env.reports.oracle_ablation import DegradedOracle

    suite = load_suite("hard-v0")
    real = run_batch(suite, [2], None, oracle=[True]).rel_error[0]
    for knobs, same in (({}, True), ({"J": "prior"}, False)):
        monkeypatch.setattr(paired_batch, "OracleController",
                            lambda rig, omega_c=40.0, k=knobs: DegradedOracle(rig, omega_c, **k))
        e = run_batch(suite, [2], None, oracle=[True]).rel_error[0]
        assert (e == pytest.approx(real, abs=1e-12)) == same, knobs
