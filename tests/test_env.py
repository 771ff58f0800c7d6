"""AddedInertia/ReverseStroke-v0: API conformance, determinism, reward bookkeeping, options.

Most tests share short episodes (hold 0.2 s, nominal wigley-2m rig) to stay cheap.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import env_render_passive_checker

import addedinertia_env  # noqa: F401 - registers the id
from addedinertia_env.envs import ReverseStrokeEnv
from addedinertia_env.envs.reverse_stroke import simulated_rig
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.identify import identify
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.experiment.task import OBS_LIMIT, TERM_NAMES, TRACKING_UNIT, RewardWeights

ENV_ID = "AddedInertia/ReverseStroke-v0"
SHORT = {"hold_s": 0.2, "randomize": False}  # nominal rig, realistic sensors, short hold


def run_episode(env, policy, seed=0, options=None):
    """Roll out one episode; ``policy(obs, k) -> action``. Returns lists of everything."""
    obs, info = env.reset(seed=seed, options=options)
    out = {"obs": [obs], "rewards": [], "infos": [info], "actions": []}
    k = 0
    while True:
        action = policy(obs, k)
        obs, reward, terminated, truncated, info = env.step(action)
        out["obs"].append(obs)
        out["rewards"].append(reward)
        out["infos"].append(info)
        out["actions"].append(action)
        k += 1
        if terminated or truncated:
            out["terminated"] = terminated
            return out


def random_policy(seed):
    rng = np.random.default_rng(seed)
    return lambda obs, k: rng.uniform(-1, 1, size=1).astype(np.float32)


@pytest.fixture(scope="module")
def ffpd_episode():
    """One episode at 1 kHz under the default controller, and the env that ran it."""
    from agents.feedforward_pd import FeedforwardPD

    env = ReverseStrokeEnv(hold_s=0.5, randomize=False, scenario_seed=3)
    controller = FeedforwardPD()
    first = {"done": False}

    def policy(obs, k):
        if not first["done"]:
            controller.reset(env.controller_context())
            first["done"] = True
        return controller.predict(obs, deterministic=True)[0]

    return env, run_episode(env, policy, seed=0)


@pytest.fixture(scope="module")
def random_episode():
    env = ReverseStrokeEnv(action_repeat=10, **SHORT)
    return env, run_episode(env, random_policy(1), seed=1)


# --- Gymnasium conformance --------------------------------------------------------------
def test_check_env_passes_with_no_warnings():
    env = gym.make(ENV_ID, action_repeat=10, **SHORT)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # Rendering needs an OpenGL backend: checked in test_rgb_array_render_* below.
        check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_spaces_are_flat_float32_boxes_with_finite_bounds():
    env = ReverseStrokeEnv()
    assert env.observation_space == gym.spaces.Box(-OBS_LIMIT, OBS_LIMIT, (env.layout.size,), np.float32)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (1,), np.float32)


def test_observations_finite_in_bounds_and_not_shared(random_episode, ffpd_episode):
    for env, ep in (random_episode, ffpd_episode):
        obs = ep["obs"]
        for o in obs:
            assert o.dtype == np.float32 and o.shape == env.observation_space.shape
            assert np.all(np.isfinite(o))
            assert env.observation_space.contains(o)
        for a, b in zip(obs[:-1], obs[1:]):
            assert not np.shares_memory(a, b)
    # Writing into a returned observation changes nothing the env returns next.
    env = ReverseStrokeEnv(action_repeat=10, **SHORT)
    o0, _ = env.reset(seed=4)
    keep = o0.copy()
    o0[:] = 99.0
    o1 = env.step(np.zeros(1, np.float32))[0]
    env2 = ReverseStrokeEnv(action_repeat=10, **SHORT)
    ref0, _ = env2.reset(seed=4)
    np.testing.assert_array_equal(ref0, keep)
    np.testing.assert_array_equal(env2.step(np.zeros(1, np.float32))[0], o1)


def test_agent_starts_in_the_hold_and_the_episode_ends_after_the_reverse_stroke(random_episode):
    env, ep = random_episode
    layout = env.layout
    assert ep["infos"][0]["phase"] == "hold"
    assert layout.get(ep["obs"][0], "is_hold") == 1.0
    phases = [info["phase"] for info in ep["infos"][1:]]
    assert "reverse" in phases and phases[-1] == "idle"
    assert ep["terminated"]
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(1, np.float32))


# --- determinism ----------------------------------------------------------------------
def test_same_seed_gives_identical_trajectories_and_different_seeds_differ():
    a = run_episode(ReverseStrokeEnv(action_repeat=25, **{**SHORT, "randomize": True}), random_policy(7), seed=11)
    b = run_episode(ReverseStrokeEnv(action_repeat=25, **{**SHORT, "randomize": True}), random_policy(7), seed=11)
    assert len(a["obs"]) == len(b["obs"])
    for x, y in zip(a["obs"], b["obs"]):
        np.testing.assert_array_equal(x, y)
    assert a["rewards"] == b["rewards"]
    assert a["infos"][-1]["lambda66_est"] == b["infos"][-1]["lambda66_est"]
    c_env = ReverseStrokeEnv(action_repeat=25, **{**SHORT, "randomize": True})
    c0, c_info = c_env.reset(seed=12)
    assert c_info["scenario_seed"] != a["infos"][0]["scenario_seed"]
    assert not np.array_equal(c0, a["obs"][0])


def test_scenario_seed_option_pins_the_scenario():
    env = ReverseStrokeEnv(action_repeat=10, **SHORT)
    _, info1 = env.reset(seed=1, options={"scenario_seed": 42})
    _, info2 = env.reset(seed=2, options={"scenario_seed": 42})
    _, info3 = env.reset(seed=2)
    assert info1["scenario_seed"] == info2["scenario_seed"] == 42
    assert info1["scenario"].endswith("/42") and info3["scenario_seed"] != 42


# --- reward -----------------------------------------------------------------------------
def test_reward_terms_sum_to_the_reward(random_episode, ffpd_episode):
    for _, ep in (random_episode, ffpd_episode):
        for reward, info in zip(ep["rewards"], ep["infos"][1:]):
            terms = info["reward_terms"]
            assert tuple(terms) == TERM_NAMES
            assert reward == pytest.approx(sum(terms.values()), rel=1e-12, abs=1e-15)
            assert all(v <= 0.0 for v in terms.values())


def test_reward_terms_add_up_to_the_episode_totals(ffpd_episode):
    """Energy and tracking terms, summed, equal the episode's measured energy and RMS error."""
    env, ep = ffpd_episode
    w, dt, final = RewardWeights(), env.experiment.rig.dt, ep["infos"][-1]
    total = {name: sum(info["reward_terms"][name] for info in ep["infos"][1:]) for name in TERM_NAMES}
    assert total["energy"] == pytest.approx(-w.energy * final["energy_J"], rel=1e-9)
    reverse_samples = np.count_nonzero(env.record().phase == "reverse")
    expected = -w.tracking * final["tracking_rms_rad"] ** 2 * reverse_samples * dt / TRACKING_UNIT**2
    assert total["tracking"] == pytest.approx(expected, rel=0.01)
    assert total["accuracy"] == pytest.approx(-w.accuracy * abs(final["rel_error"]) / 0.01, rel=1e-9)
    assert final["energy_J"] > 0.5  # the pre-spin and the stroke draw real energy


def test_return_is_the_same_at_any_action_repeat_for_a_constant_action():
    returns = {}
    for repeat in (1, 10):
        ep = run_episode(ReverseStrokeEnv(action_repeat=repeat, **SHORT), lambda o, k: np.array([0.2], np.float32))
        returns[repeat] = (sum(ep["rewards"]), ep["infos"][-1]["energy_J"], len(ep["rewards"]))
    assert returns[1][0] == pytest.approx(returns[10][0], rel=1e-9)
    assert returns[1][1] == returns[10][1]
    assert returns[1][2] == pytest.approx(10 * returns[10][2], abs=10)


# --- the benchmark metric ---------------------------------------------------------------
def test_feedforward_pd_through_the_env_matches_the_runner_and_is_accurate(ffpd_episode):
    from agents.feedforward_pd import FeedforwardPD

    env, ep = ffpd_episode
    final = ep["infos"][-1]
    for key in ("lambda66_est", "lambda66_true", "rel_error", "ci95", "energy_J", "tracking_rms_rad",
                "saturated_frac", "failed"):
        assert key in final
    assert final["failed"] is False
    assert final["lambda66_true"] == env.scenario.rig.hull.lambda66
    assert final["rel_error"] == pytest.approx((final["lambda66_est"] - final["lambda66_true"]) / final["lambda66_true"])
    assert abs(final["rel_error"]) < 0.05
    assert final["tracking_rms_rad"] < 0.005 and final["saturated_frac"] < 0.05
    # The env adds nothing: the shared runner gives the same estimate on the same scenario.
    record = run_experiment(simulated_rig(env.scenario), FeedforwardPD(), env.scenario.plan)
    assert identify([record], "energy").lambda66 == pytest.approx(final["lambda66_est"], rel=1e-12)


def test_a_failed_estimate_is_reported_and_costs_the_accuracy_cap():
    ep = run_episode(ReverseStrokeEnv(action_repeat=50, **SHORT), lambda o, k: np.ones(1, np.float32))
    final = ep["infos"][-1]
    assert final["failed"] is True and "rejected" in final["failure"]
    assert math.isnan(final["lambda66_est"]) and math.isnan(final["rel_error"])
    assert final["saturated_frac"] > 0.9
    assert final["reward_terms"]["accuracy"] == -10.0 * RewardWeights().accuracy


class _BenchLikeRig(MujocoRig):
    """A rig that, like the real bench, knows no truth."""

    source = "bench"

    def truth(self):
        return None


def test_without_a_true_lambda66_the_error_is_unknown_and_costs_nothing():
    env = ReverseStrokeEnv(action_repeat=50, rig_factory=lambda sc: _BenchLikeRig(sc.rig, seed=sc.sensor_seed),
                           **SHORT)
    ep = run_episode(env, lambda o, k: np.full(1, 0.1, np.float32))
    final = ep["infos"][-1]
    assert "truth" not in env.record().meta
    assert final["failed"] is False and final["lambda66_est"] > 0
    assert math.isnan(final["lambda66_true"]) and math.isnan(final["rel_error"])
    assert final["reward_terms"]["accuracy"] == 0.0


def test_controller_context_has_the_control_period():
    env = ReverseStrokeEnv(action_repeat=10, **SHORT)
    env.reset(seed=0)
    ctx = env.controller_context()
    assert ctx.dt == pytest.approx(10 * env.experiment.rig.dt)
    assert ctx.inertia_prior == env.experiment.inertia_prior
    assert "lambda66" not in ctx.rig.to_block()  # known constants only


def test_voltage_mode_puts_the_commanded_voltage_on_the_terminals():
    env = ReverseStrokeEnv(control_mode="voltage", sensor_quality="ideal", action_repeat=5, **SHORT)
    env.reset(seed=0)
    env.step(np.array([0.25], np.float32))
    u_max = env.experiment.known.u_max
    np.testing.assert_allclose(env.record()["u"][-5:], 0.25 * u_max, rtol=1e-12)


# --- options ------------------------------------------------------------------------------
BAD_OPTIONS = [
    ("preset", "no-such-rig"),
    ("randomize", "yes"),
    ("ranges", {"lambda_ratio": [2.0, 1.0]}),
    ("ranges", {"hull_mass": [1.0, 2.0]}),
    ("ranges", {"sensor_quality": ["great"]}),
    ("ranges", {"alpha": [-0.1, 0.1]}),
    ("fixed", {"lambda_ratio": -1.0}),
    ("fixed", {"colour": 1.0}),
    ("sensor_quality", "great"),
    ("hold_s", -1.0),
    ("hold_s", 60.0),
    ("alpha", 0.0),
    ("alpha", 1.5),
    ("alpha", float("nan")),
    ("scenario_seed", -1),
    ("action_repeat", 0),
    ("action_repeat", 2.5),
    ("control_mode", "torque"),
    ("reward_weights", {"speed": 1.0}),
    ("reward_weights", {"energy": -1.0}),
    ("render_mode", "human"),
    ("width", 0),
    ("rig_factory", "mujoco"),
]


@pytest.mark.parametrize(("option", "value"), BAD_OPTIONS, ids=[f"{o}={v!r}" for o, v in BAD_OPTIONS])
def test_bad_option_raises_value_error_naming_it(option, value):
    with pytest.raises(ValueError, match=option) as excinfo:
        ReverseStrokeEnv(**{option: value})
    message = str(excinfo.value)
    assert "expected" in message
    if isinstance(value, dict):  # the offending key or value is named
        assert any(repr(k) in message or repr(v) in message for k, v in value.items())
    else:
        assert repr(value) in message


def test_ranges_with_randomize_off_is_refused():
    with pytest.raises(ValueError, match="ranges"):
        ReverseStrokeEnv(randomize=False, ranges={"lambda_ratio": [1.0, 2.0]})


@pytest.mark.parametrize(("options", "name"), [({"action_repeat": 5}, "options"), ({"hold_s": -2.0}, "hold_s"),
                                               ({"preset": 7}, "preset"), ("hold", "options")])
def test_bad_reset_option_raises_value_error_naming_it(options, name):
    env = ReverseStrokeEnv(**SHORT)
    with pytest.raises(ValueError, match=name):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("action", [np.array([np.nan], np.float32), np.zeros(2, np.float32)])
def test_bad_action_raises(action):
    env = ReverseStrokeEnv(action_repeat=10, **SHORT)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(action)


def test_scenario_options_reach_the_scenario():
    env = ReverseStrokeEnv(preset="spheroid-7", fixed={"lambda_ratio": 1.5}, sensor_quality="poor",
                           hold_s=0.3, alpha=0.08)
    _, info = env.reset(seed=0)
    s = env.scenario
    assert s.plan.hold_s == 0.3 and s.plan.alpha == 0.08 and info["sensor_quality"] == "poor"
    assert s.rig.hull.lambda66 == pytest.approx(1.5 * s.rig.hull.J_hull)
    assert info["scenario"].startswith("spheroid-7/")


# --- vectorised -------------------------------------------------------------------------
def _vector_rollout(mode, n_steps):
    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode=mode, action_repeat=50, **SHORT)
    try:
        obs, _ = envs.reset(seed=5)
        rewards, finals = [], []
        for _ in range(n_steps):
            obs, reward, terminated, truncated, info = envs.step(np.full((2, 1), 0.1, np.float32))
            assert obs.shape == (2, 22) and obs.dtype == np.float32 and np.all(np.abs(obs) <= OBS_LIMIT)
            rewards.append(reward.copy())
            if terminated.any():
                finals.append(info["lambda66_est"][info["_lambda66_est"]])
        return np.array(rewards), finals
    finally:
        envs.close()


def test_sync_vector_env_runs_whole_episodes():
    rewards, finals = _vector_rollout("sync", 40)
    assert rewards.shape == (40, 2) and np.all(np.isfinite(rewards))
    assert finals and all(np.all(f > 0) for f in finals)


def test_async_vector_env_matches_sync():
    a, _ = _vector_rollout("async", 6)
    s, _ = _vector_rollout("sync", 6)
    np.testing.assert_array_equal(a, s)


# --- rendering --------------------------------------------------------------------------
def test_plot_render_returns_an_rgb_frame_of_the_episode():
    env = ReverseStrokeEnv(render_mode="plot", action_repeat=50, **SHORT)
    env.reset(seed=0)
    env.step(np.array([0.3], np.float32))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 10  # a drawing, not a blank canvas
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env_render_passive_checker(env)
    env.close()


GL_BACKENDS = [{"MUJOCO_GL": "egl", "EGL_PLATFORM": "surfaceless"}, {"MUJOCO_GL": "osmesa"}]
RGB_SCRIPT = textwrap.dedent("""
    import json, sys, warnings
    import numpy as np, gymnasium as gym
    import addedinertia_env
    from gymnasium.utils.env_checker import check_env
    from addedinertia_env.envs import ReverseStrokeEnv
    env = ReverseStrokeEnv(render_mode="rgb_array", width=160, height=120, action_repeat=50,
                           hold_s=0.2, randomize=False)
    env.reset(seed=0)
    try:
        first = env.render()
    except RuntimeError as e:
        if "OpenGL" in str(e):
            print(json.dumps({"no_gl": str(e)}))
            sys.exit(0)
        raise
    for _ in range(6):
        env.step(np.array([1.0], np.float32))
    later = env.render()
    env.close()
    env.close()
    if sys.argv[1] == "check_env":
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(gym.make("AddedInertia/ReverseStroke-v0", action_repeat=50, hold_s=0.2,
                               randomize=False).unwrapped)  # with every declared render mode
    print(json.dumps({"shape": list(first.shape), "dtype": str(first.dtype),
                      "changed": float(np.abs(first.astype(int) - later.astype(int)).mean()),
                      "std": float(first.std())}))
""")


def _render_in_fresh_interpreter(mode: str) -> dict:
    """MuJoCo fixes its OpenGL backend (MUJOCO_GL) at import: try each in a new interpreter."""
    reasons = []
    for backend in GL_BACKENDS:
        proc = subprocess.run([sys.executable, "-c", RGB_SCRIPT, mode], env={**os.environ, **backend},
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
        result = json.loads(proc.stdout.strip().splitlines()[-1])
        if "no_gl" not in result:
            return result
        reasons.append(f"{backend}: {result['no_gl'][-200:]}")
    pytest.skip("no OpenGL backend for MuJoCo on this machine: " + " | ".join(reasons))


def test_rgb_array_render_draws_the_rig():
    result = _render_in_fresh_interpreter("frames")
    assert result["shape"] == [120, 160, 3] and result["dtype"] == "uint8"
    assert result["std"] > 5  # the scene, not a blank frame
    assert result["changed"] > 0  # the flywheel and hull moved


@pytest.mark.slow
def test_check_env_with_every_render_mode_passes_with_no_warnings():
    result = _render_in_fresh_interpreter("check_env")
    assert result["dtype"] == "uint8"


@pytest.mark.parametrize("repeat", [1, 10])
def test_controller_context_period_is_the_agents_on_a_suite_with_a_slow_drive(repeat):
    """hard-v0's drive takes a set-point every 10 samples; a controller called once per agent
    step must still be told the agent's period (sample dt x action_repeat), not 10x it."""
    env = ReverseStrokeEnv(suite="hard-v0", action_repeat=repeat)
    env.reset(seed=3)
    ctx = env.controller_context()
    assert ctx.dt == pytest.approx(repeat * env.rig.dt)
    assert ctx.policy_rate_hz == pytest.approx(env.policy_rate_hz)
    assert ctx.board_dt == pytest.approx(env.rig.dt)
