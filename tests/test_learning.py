"""Training: configs, determinism, resume, residual wrapper, and a short run that learns (slow).

Fast tests train on the stand-in task (addedinertia_env/learning/toy.py) for a few
hundred steps; the residual test runs the real environment for one episode.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from addedinertia_env.cli import main  # noqa: E402
from addedinertia_env.learning.config import ALGOS, DEFAULT_ENV_ID, load_config  # noqa: E402
from addedinertia_env.learning.toy import TOY_ENV_ID, toy_config  # noqa: E402
from addedinertia_env.learning.train import train  # noqa: E402
from addedinertia_env.sim.presets import ConfigError  # noqa: E402


def _params(model_dir):
    from stable_baselines3 import PPO

    model = PPO.load(str(model_dir / "model.zip"), device="cpu")
    return {k: v.detach().numpy().copy() for k, v in model.policy.state_dict().items()}


@pytest.mark.parametrize("algo", sorted(ALGOS))
@pytest.mark.parametrize("env_id", [DEFAULT_ENV_ID, TOY_ENV_ID])
def test_shipped_configs_load(algo, env_id):
    cfg = load_config(algo, env_id=env_id)
    assert cfg.n_timesteps > 0 and cfg.n_envs >= 1
    kwargs = cfg.model_kwargs()
    assert "seed" not in kwargs


@pytest.mark.parametrize("body, match", [
    ("n_timesteps: 100\n  hyperparams: {learning_rat: 0.001}", "learning_rat"),
    ("n_timestep: 100", "n_timestep"),
    ("residual: {scale: -1}", "residual.scale"),
    ("residual: {base_rate: host}", "residual.base_rate = 'host'"),
])
def test_config_refuses_unknown_keys_by_name(tmp_path, body, match):
    bad = tmp_path / "ppo.yaml"
    bad.write_text(f"{DEFAULT_ENV_ID}:\n  {body}\n")
    with pytest.raises(ConfigError, match=match):
        load_config("ppo", bad)


def test_the_100hz_residual_config_loads_with_its_base_at_the_policy_rate():
    from addedinertia_env.sim.presets import CONFIG_DIR

    cfg = load_config("ppo", CONFIG_DIR / "algos" / "ppo_residual_100hz.yaml")
    assert cfg.residual["enabled"] and cfg.residual["base_rate"] == "policy"
    assert cfg.env_kwargs["action_repeat"] == 10


def test_cli_train_bad_config_exits_2(tmp_path, capsys):
    assert main(["train", "--algo", "ppo", "--config", str(tmp_path / "missing.yaml")]) == 2
    err = capsys.readouterr().err
    assert "missing.yaml" in err and err.count("\n") == 1


def test_same_seed_same_parameters_other_seed_differs(tmp_path):
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        train(toy_config("ppo", 512), seed=seed, out=tmp_path / name)
    a, b, c = (_params(tmp_path / n) for n in "abc")
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert any(not np.array_equal(a[k], c[k]) for k in a)


def test_resume_continues_steps_and_cost(tmp_path):
    cfg = toy_config("ppo", 512, checkpoint_freq=256)
    train(cfg, seed=0, out=tmp_path / "first")
    ckpt = tmp_path / "first" / "checkpoints" / "model_256_steps.zip"
    before = json.loads((tmp_path / "first" / "checkpoints" / "model_cost_256_steps.json").read_text())
    assert before["env_steps"] == 256
    card = train(toy_config("ppo", 1024, checkpoint_freq=256), seed=0, out=tmp_path / "resumed", resume=ckpt)
    rollout = cfg.hyperparams["n_steps"] * cfg.n_envs  # PPO always finishes its last rollout
    assert 1024 <= card["cost"]["env_steps"] < 1024 + rollout
    assert card["cost"]["env_steps_before_resume"] == 256
    assert card["cost"]["cpu_s"] > before["cpu_s"] and card["cost"]["wall_s"] > before["wall_s"]
    assert (tmp_path / "resumed" / "vecnormalize.pkl").exists()


def test_residual_wrapper_with_zero_correction_is_the_base_controller():
    """Zero correction: the wrapper drives the rig exactly as feedforward-pd does, sample by sample."""
    from agents import make_controller
    from addedinertia_env.learning.envs import make_env

    residual = {"enabled": True, "base": "feedforward-pd", "scale": 0.1}
    wrapped = make_env(DEFAULT_ENV_ID, {"action_repeat": 10}, residual)
    obs, _ = wrapped.reset(seed=5)
    done, agent_steps = False, 0
    while not done:
        obs, _, term, trunc, info_wrapped = wrapped.step(np.zeros(1, np.float32))
        done, agent_steps = term or trunc, agent_steps + 1

    import gymnasium as gym

    plain = gym.make(DEFAULT_ENV_ID, action_repeat=1)
    obs, _ = plain.reset(seed=5)
    base = make_controller("feedforward-pd")
    base.reset(plain.unwrapped.controller_context())
    done, samples = False, 0
    while not done:
        action, _ = base.predict(obs)
        obs, _, term, trunc, info_plain = plain.step(action)
        done, samples = term or trunc, samples + 1
    assert samples > agent_steps * 9  # the wrapper holds one correction for 10 samples
    assert info_wrapped["lambda66_est"] == info_plain["lambda66_est"]
    assert info_wrapped["energy_J"] == info_plain["energy_J"]


def test_residual_base_at_the_policy_rate_with_zero_correction_is_the_two_rate_board():
    """base_rate "policy", zero correction: the training wrapper drives the rig exactly as the
    two-rate board (loop/board_loop.py, zoh) does under lqr at 100 Hz, sample for sample: the
    base decides once per 10 samples with a 10 ms context, and the drive holds it."""
    from addedinertia_env.envs.reverse_stroke import simulated_rig
    from addedinertia_env.experiment.runner import run_experiment
    from addedinertia_env.learning.envs import make_env
    from agents import make_controller

    residual = {"enabled": True, "base": "lqr", "scale": 0.1, "base_rate": "policy"}
    wrapped = make_env(DEFAULT_ENV_ID, {"action_repeat": 10, "randomize": False, "hold_s": 0.3,
                                        "scenario_seed": 3}, residual)
    wrapped.reset(seed=0)
    assert wrapped.base.ctx.dt == pytest.approx(0.01) and wrapped.base.ctx.policy_rate_hz == pytest.approx(100.0)
    done = False
    while not done:
        _, _, term, trunc, _ = wrapped.step(np.zeros(1, np.float32))
        done = term or trunc
    env_rec = wrapped.unwrapped.experiment.record("env")
    scenario = wrapped.unwrapped.scenario
    board_rec = run_experiment(simulated_rig(scenario), make_controller("lqr", tuned=False, **wrapped.base_params),
                               scenario.plan, policy_rate_hz=100.0, board_mode="zoh")
    for col in ("t", "phi", "i", "i_cmd", "brake"):
        assert np.array_equal(env_rec.samples[col], board_rec.samples[col]), col
    i_cmd = env_rec.samples["i_cmd"][np.isin(env_rec.samples["phase"], ["reverse"])]
    assert np.count_nonzero(np.diff(i_cmd)) <= len(i_cmd) // 10 + 2  # held for 10 samples


@pytest.mark.slow
def test_short_training_learns_to_track(tmp_path):
    """PPO on the stand-in task: 20k steps cut the tracking cost on fixed eval seeds at least 3-fold."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecNormalize

    from addedinertia_env.learning.envs import make_vec

    cfg = toy_config("ppo", 20_000)
    card = train(cfg, seed=0, out=tmp_path / "run")
    trained = card["final_eval"]["mean_reward"]

    env = make_vec(TOY_ENV_ID, cfg.env_kwargs, None, 1, cfg.eval["seed"])
    untrained_model = PPO(cfg.policy, env, seed=0, device="cpu", **cfg.model_kwargs())
    norm = VecNormalize.load(str(tmp_path / "run" / "vecnormalize.pkl"), env)
    norm.training = norm.norm_reward = False
    norm.seed(cfg.eval["seed"])
    untrained, _ = evaluate_policy(untrained_model, norm, n_eval_episodes=cfg.eval["n_episodes"], deterministic=True)
    assert trained < 0 and untrained < 0
    assert trained > untrained / 3.0, f"trained {trained:.1f} vs untrained {untrained:.1f}"
