"""ONNX export: parity with model.predict, metadata, OnnxPolicy's hold and residual, the shipped policy."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("stable_baselines3")

from addedinertia_env.cli import main  # noqa: E402
from addedinertia_env.learning.export import export_onnx, load_trained, random_observations  # noqa: E402
from addedinertia_env.learning.toy import toy_config  # noqa: E402
from addedinertia_env.learning.train import train  # noqa: E402
from addedinertia_env.experiment.task import OBSERVATION_FIELDS  # noqa: E402
from agents.onnx_policy import OnnxPolicy, OnnxPolicyError  # noqa: E402

SHIPPED = Path(__file__).resolve().parents[1] / "agents" / "policies" / "reverse_stroke.onnx"


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    """A tiny PPO on the stand-in task with a 3-sample action repeat, exported."""
    out = tmp_path_factory.mktemp("ppo")
    cfg = toy_config("ppo", 512)
    cfg.env_kwargs = {"action_repeat": 3}
    train(cfg, seed=0, out=out)
    card = export_onnx(out, out / "policy.onnx")
    return out, card


def _independent_parity(run_dir: Path, onnx_path: Path) -> float:
    import onnxruntime as ort

    model, vecnorm, _ = load_trained(run_dir)
    obs = random_observations(1000, vecnorm, seed=7)
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    got = session.run(None, {"obs": obs})[0]
    want, _ = model.predict(vecnorm.normalize_obs(obs), deterministic=True)
    return float(np.max(np.abs(got - want)))


def test_ppo_export_matches_predict(ppo_run):
    out, card = ppo_run
    assert card["parity_max_abs_diff"] < 1e-5
    assert _independent_parity(out, out / "policy.onnx") < 1e-5
    assert card["metadata"]["obs_fields"] == json.dumps(list(OBSERVATION_FIELDS))
    assert card["latency_us"]["p50"] > 0 and card["latency_us"]["p99"] >= card["latency_us"]["p50"]


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_off_policy_export_matches_predict(tmp_path, algo):
    cfg = toy_config(algo, 300)
    cfg.hyperparams = {**cfg.hyperparams, "learning_starts": 100}
    train(cfg, seed=0, out=tmp_path)
    card = export_onnx(tmp_path, tmp_path / "p.onnx", n_parity=500)
    assert card["parity_max_abs_diff"] < 1e-5
    assert _independent_parity(tmp_path, tmp_path / "p.onnx") < 1e-5


def test_onnx_policy_holds_action_for_action_repeat_samples(ppo_run):
    out, _ = ppo_run
    policy = OnnxPolicy(out / "policy.onnx")
    assert policy.action_repeat == 3 and policy.residual_base is None and policy.train_env_steps == 512
    obs = random_observations(8, seed=1)
    policy.reset(None)
    actions = [policy.predict(o)[0][0] for o in obs[:7]]
    net = policy.network(obs).reshape(-1)
    assert actions[:3] == [net[0]] * 3 and actions[3:6] == [net[3]] * 3 and actions[6] == net[6]
    policy.reset(None)  # the counter restarts: a fresh evaluation at the first call
    assert policy.predict(obs[7])[0][0] == net[7]


def test_onnx_policy_refuses_other_observation_layout(ppo_run, tmp_path):
    import onnx

    out, _ = ppo_run
    graph = onnx.load(str(out / "policy.onnx"))
    for prop in graph.metadata_props:
        if prop.key == "addedinertia.obs_fields":
            prop.value = json.dumps(list(OBSERVATION_FIELDS)[:-1] + ["something_else"])
    onnx.save(graph, str(tmp_path / "other.onnx"))
    with pytest.raises(OnnxPolicyError, match="something_else"):
        OnnxPolicy(tmp_path / "other.onnx")


def test_cli_export_missing_model_exits_2(tmp_path, capsys):
    assert main(["export", str(tmp_path / "nothing"), "--onnx", str(tmp_path / "x.onnx")]) == 2
    assert "nothing" in capsys.readouterr().err


def test_shipped_policy_is_small_and_matches_its_card():
    data = SHIPPED.read_bytes()
    assert len(data) < 1_000_000
    card = json.loads(SHIPPED.with_suffix(".json").read_text())
    assert card["sha256"] == hashlib.sha256(data).hexdigest()
    assert card["parity_max_abs_diff"] < 1e-5
    policy = OnnxPolicy(SHIPPED)
    assert policy.train_env_steps == card["training"]["cost"]["env_steps"]


def test_shipped_policy_runs_an_experiment_within_the_current_limit():
    from addedinertia_env.experiment.runner import run_experiment
    from addedinertia_env.sim.mujoco_rig import MujocoRig
    from addedinertia_env.experiment.scenarios import make_scenario
    from agents import make_controller

    scenario = make_scenario(123)
    rig = MujocoRig(scenario.rig, seed=scenario.sensor_seed)
    record = run_experiment(rig, make_controller(f"onnx:{SHIPPED}"), scenario.plan)
    i_max = float(record.meta["rig"]["i_max"])
    controlled = np.isin(record.samples["phase"], ["hold", "reverse"])
    assert controlled.sum() > 1000
    assert np.all(np.abs(record.samples["i_cmd"][controlled]) <= i_max * (1 + 1e-9))
    assert np.all(np.abs(record.samples["i"]) <= 1.05 * i_max)


def test_shipped_policy_on_the_bench_loop_equals_the_training_loop():
    """OnnxPolicy at 1 kHz (as the benchmark runs it) == the training wrapper at its action repeat."""
    import gymnasium as gym

    from addedinertia_env.learning.envs import make_env

    policy = OnnxPolicy(SHIPPED)
    residual = ({"enabled": True, "base": policy.residual_base, "scale": policy.residual_scale}
                if policy.residual_base else None)
    wrapped = make_env("AddedInertia/ReverseStroke-v0", {"action_repeat": policy.action_repeat}, residual)
    obs, _ = wrapped.reset(seed=11)
    done = False
    while not done:
        obs, _, term, trunc, info_train = wrapped.step(policy.network(obs).reshape(1))
        done = term or trunc

    plain = gym.make("AddedInertia/ReverseStroke-v0", action_repeat=1)
    obs, _ = plain.reset(seed=11)
    policy.reset(plain.unwrapped.controller_context())
    done = False
    while not done:
        action, _ = policy.predict(obs)
        obs, _, term, trunc, info_bench = plain.step(action)
        done = term or trunc
    assert info_bench["lambda66_est"] == pytest.approx(info_train["lambda66_est"], rel=1e-6)
    assert info_bench["energy_J"] == pytest.approx(info_train["energy_J"], rel=1e-6)
