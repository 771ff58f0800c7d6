"""The two-rate bench end to end: ``deploy --host-rate-hz`` against the emulator, the same
board in the simulator, and the refusal of a policy whose rate the bench does not match."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from addedinertia_env.cli import main
from addedinertia_env.experiment.protocol import Experiment
from addedinertia_env.experiment.two_rate import drive_two_rate
from addedinertia_env.identify import identify
from addedinertia_env.loop.board_loop import TwoRateSimRig
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from agents import make_controller
from hw_adapter.deploy import EXIT_BAD_INPUT, DeployOptions, deploy
from hw_adapter.lab import load_lab
from hw_adapter.loopback import start_emulator

RIG = "wigley-2m"
HOLD_S = 0.3
POLICY = Path(__file__).resolve().parents[1] / "agents" / "policies" / "reverse_stroke.onnx"
POLICY_100HZ = POLICY.with_name("reverse_stroke_100hz.onnx")  # residual on lqr, the whole policy at 100 Hz


def test_lockstep_two_rate_deploy_matches_the_simulated_two_rate_board(tmp_path):
    """The emulator's board and the simulator's two-rate rig run the same inner loop: with
    no link latency (lock-step) the host's record and lambda66 agree with the simulation."""
    server = start_emulator(RIG, fast=True)
    try:
        # rtt_pings=0: the link's timing is not what this test is about (a loaded machine can stretch
        # an echo past the bound); the round-trip check has its own test in test_deploy.py.
        opts = DeployOptions(bench=server.url, controller="lqr", lab=load_lab(RIG), out=tmp_path, hold_s=HOLD_S,
                             host_rate_hz=100.0, rtt_pings=0)
        summary, status = deploy(opts, make_controller("lqr"))
    finally:
        server.stop()
    assert status == 0 and summary["status"] == "complete", summary["status"]
    assert summary["samples_lost"] == 0 and summary["late_segments"] == 0 and summary["host_rate_hz"] == 100.0
    assert summary["segments_sent"] > 0 and summary["board_mode"] == "zoh"
    assert server.board.segments_received == summary["segments_sent"]
    params = rig_from_mapping(load_preset(RIG))
    truth = params.hull.lambda66  # scoring only
    rig = TwoRateSimRig(MujocoRig(params, seed=0), 100.0)
    exp = Experiment(rig, load_lab(RIG).plan(hold_s=HOLD_S))
    exp.start()
    drive_two_rate(exp, make_controller("lqr"), 100.0)
    sim = identify([exp.record("sim")], "energy").lambda66
    assert abs(summary["lambda66"] / truth - 1) < 0.03 and abs(sim / truth - 1) < 0.03
    assert abs(summary["lambda66"] / sim - 1) < 0.01, (summary["lambda66"], sim)


@pytest.mark.skipif(not POLICY.exists(), reason="no exported policy")
def test_a_policy_at_another_rate_is_refused_before_arming(capsys):
    """reverse_stroke.onnx is a residual policy whose base runs at every 1 kHz sample: at a
    100 Hz host it would not be the policy that was trained. deploy says so, exit 2, and
    the board was never armed."""
    server = start_emulator(RIG, fast=True)
    try:
        status = main(["deploy", "--bench", server.url, "--policy", str(POLICY), "--host-rate-hz", "100", "--json"])
        captured = capsys.readouterr()
        assert not server.board.commands and not server.board.armed  # nothing was sent to move it
    finally:
        server.stop()
    assert status == EXIT_BAD_INPUT
    summary = json.loads(captured.out)
    assert summary["status"].startswith("refused:") and "1000 Hz" in summary["refused"]
    assert "omit --host-rate-hz" in captured.err
    assert "refused before arming" in captured.err and "100 Hz" in captured.err


def test_the_environment_holds_its_action_exactly_as_the_board_loop_does():
    """A policy trained in the environment at action_repeat 10 (100 Hz) sees the board it
    will drive: the same actions through the two-rate board loop (zero-order hold, the
    brake released on its sample) give the same record, sample for sample."""
    import gymnasium as gym
    import numpy as np

    from addedinertia_env.envs.reverse_stroke import simulated_rig

    env = gym.make("AddedInertia/ReverseStroke-v0", randomize=False, hold_s=0.3, scenario_seed=3,
                   action_repeat=10).unwrapped
    env.reset(seed=0)
    assert env.policy_rate_hz == pytest.approx(100.0) and env.board_mode == "zoh"
    actions = np.random.default_rng(1).uniform(-0.3, 0.3, 1000)
    k = 0
    done = False
    while not done:
        _, _, done, _, _ = env.step(actions[k:k + 1])
        k += 1
    env_rec = env.experiment.record("env")

    class Replay:
        def __init__(self):
            self.k = 0

        def predict(self, obs, deterministic=True):
            self.k += 1
            return actions[self.k - 1:self.k], None

    rig = TwoRateSimRig(simulated_rig(env.scenario), 100.0)
    exp = Experiment(rig, env.scenario.plan)
    exp.start()
    drive_two_rate(exp, Replay(), 100.0, "zoh")
    board_rec = exp.record("board")
    for col in ("t", "phi", "i", "i_cmd", "brake"):
        assert np.array_equal(env_rec.samples[col], board_rec.samples[col]), col



def test_the_host_link_to_the_emulator_sends_small_frames_at_once():
    """TCP_NODELAY on socket:// links: without it, once the board goes silent (a dropped
    link), its delayed ACKs held the host's safe stop back by about 40 ms (docs/BENCH.md)."""
    import socket

    from hw_adapter.link import Link

    server = start_emulator(RIG, fast=True)
    try:
        link = Link(server.url)
        assert link.port._socket.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)
        link.close()
    finally:
        server.stop()


@pytest.mark.skipif(not POLICY_100HZ.exists(), reason="no exported 100 Hz policy")
def test_the_100hz_policy_on_the_two_rate_board_equals_its_training_loop():
    """reverse_stroke_100hz.onnx acts at 100 Hz (its base, lqr, decides with the network and
    the drive holds the sum): through the two-rate board loop, as deploy --host-rate-hz 100
    runs it, it drives the simulated rig exactly as the training wrapper did, sample for
    sample (same scenario, same sensor noise); so does the benchmark's single-rate loop, which
    calls it every sample and lets it hold its own action."""
    import numpy as np

    from addedinertia_env.envs.reverse_stroke import simulated_rig
    from addedinertia_env.experiment.runner import run_experiment
    from addedinertia_env.learning.envs import make_env
    from agents.onnx_policy import OnnxPolicy

    policy = OnnxPolicy(POLICY_100HZ)
    assert policy.policy_rate_hz == pytest.approx(100.0) and policy.board_mode == "zoh"
    assert policy.residual_base_rate == "policy" and policy.action_repeat == 10
    residual = {"enabled": True, "base": policy.residual_base, "scale": policy.residual_scale,
                "base_params": policy.residual_base_params, "base_rate": "policy"}
    wrapped = make_env("AddedInertia/ReverseStroke-v0", {"action_repeat": 10, "randomize": False, "hold_s": HOLD_S,
                                                         "scenario_seed": 7}, residual)
    obs, _ = wrapped.reset(seed=0)
    done = False
    while not done:
        obs, _, term, trunc, info_train = wrapped.step(policy.network(obs).reshape(1))
        done = term or trunc
    train_rec = wrapped.unwrapped.experiment.record("train")
    scenario = wrapped.unwrapped.scenario
    board_rec = run_experiment(simulated_rig(scenario), policy, scenario.plan, policy_rate_hz=100.0)
    every_sample_rec = run_experiment(simulated_rig(scenario), policy, scenario.plan)  # as `bench run` calls it
    for col in ("t", "phi", "i", "i_cmd", "brake"):
        assert np.array_equal(train_rec.samples[col], board_rec.samples[col]), col
        assert np.array_equal(train_rec.samples[col], every_sample_rec.samples[col]), col
    assert identify([board_rec], "energy").lambda66 == pytest.approx(info_train["lambda66_est"], rel=1e-9)


@pytest.mark.skipif(not POLICY_100HZ.exists(), reason="no exported 100 Hz policy")
def test_the_100hz_policy_completes_a_two_rate_deploy_and_is_refused_at_another_host_rate(tmp_path, capsys):
    """deploy --policy reverse_stroke_100hz.onnx --host-rate-hz 100 (lock-step emulator):
    complete, identified, 0 samples lost, and equal to the same policy through the simulated
    two-rate board; at --host-rate-hz 1000 it is refused before anything is armed (exit 2)."""
    params = rig_from_mapping(load_preset(RIG))
    truth = params.hull.lambda66  # scoring only
    server = start_emulator(RIG, fast=True)
    try:
        status = main(["deploy", "--bench", server.url, "--policy", str(POLICY_100HZ), "--host-rate-hz", "1000",
                       "--json"])
        captured = capsys.readouterr()
        assert not server.board.commands and not server.board.armed
        assert status == EXIT_BAD_INPUT
        refused = json.loads(captured.out)
        assert refused["status"].startswith("refused:") and "acts at 100 Hz" in refused["refused"]
        assert "--host-rate-hz 100" in captured.err
        opts = DeployOptions(bench=server.url, controller=f"onnx:{POLICY_100HZ}", lab=load_lab(RIG), out=tmp_path,
                             hold_s=HOLD_S, host_rate_hz=100.0)
        summary, status = deploy(opts, make_controller(f"onnx:{POLICY_100HZ}"))
    finally:
        server.stop()
    assert status == 0 and summary["status"] == "complete", summary["status"]
    assert summary["samples_lost"] == 0 and summary["late_segments"] == 0 and summary["host_rate_hz"] == 100.0
    rig = TwoRateSimRig(MujocoRig(params, seed=0), 100.0)
    exp = Experiment(rig, load_lab(RIG).plan(hold_s=HOLD_S))
    exp.start()
    drive_two_rate(exp, make_controller(f"onnx:{POLICY_100HZ}"), 100.0)
    sim = identify([exp.record("sim")], "energy").lambda66
    assert abs(summary["lambda66"] / truth - 1) < 0.01 and abs(sim / truth - 1) < 0.01
    assert abs(summary["lambda66"] / sim - 1) < 0.005, (summary["lambda66"], sim)


def test_a_held_classical_controller_on_the_every_sample_loop_equals_the_two_rate_board():
    """agents.held:lqr_100hz (the simulated benchmark calls it every sample; it decides every
    10th with a 10 ms context) drives the rig exactly as lqr through the two-rate board at
    100 Hz does: the benchmark row of a 100 Hz controller is the bench's controller."""
    import numpy as np

    from agents.held import lqr_100hz

    params = rig_from_mapping(load_preset(RIG))
    plan = load_lab(RIG).plan(hold_s=HOLD_S)
    from addedinertia_env.experiment.runner import run_experiment

    held = run_experiment(MujocoRig(params, seed=0), lqr_100hz(), plan)
    board = run_experiment(MujocoRig(params, seed=0), make_controller("lqr"), plan, policy_rate_hz=100.0)
    for col in ("t", "phi", "i", "i_cmd", "brake"):
        assert np.array_equal(held.samples[col], board.samples[col]), col
    every = run_experiment(MujocoRig(params, seed=0), make_controller("lqr"), plan)
    assert not np.array_equal(held.samples["i_cmd"], every.samples["i_cmd"])  # the rate matters
