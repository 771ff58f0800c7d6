"""The learned drive controller (issue 28 item 6): the trainer on the ranked score, the shipped
ONNX policy and its card, and its deploy on the emulator with a geared drive in two-rate mode."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.bench.score import CAP, GEARED_SCORE_VERSION
from addedinertia_env.experiment.task import OBSERVATION_FIELDS
from addedinertia_env.learning import score_ars
from addedinertia_env.learning.score_ars import GatedLinearPolicy, episode_scores

ROOT = Path(__file__).resolve().parents[1]
POLICY = ROOT / "agents" / "policies" / "drive_ars.onnx"
GEARED = "wigley-2m-drive-v1"  # every flaw of drive-v1 (configs/rigs/wigley-2m-drive-v1.yaml)
N = len(OBSERVATION_FIELDS)


def test_episode_scores_are_the_leaderboards():
    e = np.array([0.02, -0.5, np.nan, -0.003])
    assert episode_scores(e) == pytest.approx([0.02, CAP, CAP, 0.003])


def test_the_gated_policy_acts_only_in_its_phase():
    rng = np.random.default_rng(1)
    pol = GatedLinearPolicy(np.zeros(N), np.ones(N), rng.normal(size=2 * N + 2))
    obs = rng.uniform(-1, 1, (6, N))
    obs[:, score_ars.HOLD] = [1, 0, 0, 1, 0, 0]
    obs[:, score_ars.REVERSE] = [0, 1, 0, 0, 1, 0]
    r = pol(obs)
    assert r[2] == 0 and r[5] == 0  # neither hold nor reverse: no correction
    hold_only = pol.theta.copy()
    hold_only[N:2 * N] = 0
    hold_only[-1] = 0
    assert np.array_equal(pol(obs, hold_only)[[1, 4]], np.zeros(2, np.float32))  # the reverse rows need their own weights
    assert np.all(np.abs(r) <= 1)


def test_one_generation_trains_from_the_base_and_writes_its_card(tmp_path):
    """Generation 0's policy (theta = 0) is its base, episode for episode; the first step moves theta;
    the card says the objective (the geared version: the default suite, drive-v1, is geared), the cost and the validation."""
    card = score_ars.train(tmp_path, generations=1, scenarios=2, directions=1, top=1, validate=2, log=lambda m: None)
    row = json.loads((tmp_path / "curve.jsonl").read_text().splitlines()[0])
    assert row["paired_mean_diff"] == 0.0 and row["base_score"] == row["policy_score"]
    assert np.linalg.norm(score_ars.load_policy(tmp_path).theta) > 0
    assert card["objective"].startswith(GEARED_SCORE_VERSION) and card["cost"]["episodes"] == 2 + 4 * 2 + 2 * 2
    assert card["validation"]["scenarios"] == 2 and len(card["validation"]["ci95"]) == 2


def test_the_action_limit_bounds_base_plus_correction():
    from agents.residual import residual_action

    assert residual_action(0.8, 1.0, 0.3)[0] == pytest.approx(1.0)  # the drive's clip only
    assert residual_action(0.8, 1.0, 0.3, 0.9)[0] == pytest.approx(0.9)
    assert residual_action(-0.95, 0.0, 0.3, 0.9)[0] == pytest.approx(-0.9)  # the base alone is held inside it too
    assert residual_action(0.2, 0.5, 0.3, 0.9)[0] == pytest.approx(0.35)  # inside the limit: unchanged


def test_a_limited_run_never_commands_the_drives_limit():
    """On the batched engine, a correction pushing hard (theta = large bias) reaches the drive's limit
    without the policy's limit, and never with it (the energy method's at-limit samples are gone)."""
    from addedinertia_env.bench.suites import load_suite
    from addedinertia_env.learning.ars_residual import base_factory
    from addedinertia_env.learning.paired_batch import run_batch

    suite = load_suite("drive-v1")
    make_base = base_factory("feedforward-pd", score_ars.running_params("feedforward-pd"))
    push = lambda obs, slots: np.ones(len(obs), np.float32)  # noqa: E731 - +0.6 i_max on top of the base
    free = run_batch(suite, [3], make_base, policy=push, residual_scale=0.6)
    held = run_batch(suite, [3], make_base, policy=push, residual_scale=0.6, action_limit=0.9)
    assert free.limit_samples[0] > 0 and held.limit_samples[0] == 0
    with pytest.raises(ValueError, match="action_limit"):
        run_batch(suite, [3], make_base, policy=push, residual_scale=0.6, action_limit=1.5)


@pytest.mark.skipif(not POLICY.exists(), reason="no shipped drive policy")
def test_the_shipped_drive_policy_keeps_its_current_limit():
    """The shipped policy's own limit (card and metadata) holds on the bench's path (OnnxPolicy.predict)
    whatever its base asks for."""
    from agents.onnx_policy import OnnxPolicy

    card = json.loads(POLICY.with_suffix(".json").read_text())
    limit = card["residual"]["action_limit"]
    policy = OnnxPolicy(POLICY)
    assert limit < 1 and policy.action_limit == pytest.approx(limit)

    class Saturating:  # a base that asks for more than the drive (its correction cannot bring it back inside)
        def predict(self, obs, deterministic=True):
            return np.array([1.5 if obs[0] > 0 else -1.5], np.float32), None

    policy.base = Saturating()
    rng = np.random.default_rng(3)
    got = []
    for _ in range(40):
        obs = rng.uniform(-3, 3, N).astype(np.float32)
        obs[score_ars.HOLD], obs[score_ars.REVERSE] = 0.0, 1.0
        got.append(abs(float(policy.predict(obs)[0][0])))
    assert got == pytest.approx([limit] * len(got), abs=1e-6)


@pytest.mark.skipif(not POLICY.exists(), reason="no shipped drive policy")
def test_the_shipped_drive_policy_matches_its_card():
    card = json.loads(POLICY.with_suffix(".json").read_text())
    blob = POLICY.read_bytes()
    assert len(blob) < 1_000_000 and card["size_bytes"] == len(blob)
    assert card["sha256"] == hashlib.sha256(blob).hexdigest()
    assert card["policy_rate_hz"] == 100.0 and card["board_mode"] == "zoh"
    assert card["residual"]["base_rate"] == "policy" and card["parity_max_abs_diff"] < 1e-5
    assert card["training"]["cost"]["cpu_minutes"] <= 30
    # the graph is the card's policy: same corrections on observations in both phases
    import onnxruntime as ort

    whole = card["gated_linear_policy"]
    pol = GatedLinearPolicy(np.array(whole["mean"]), np.array(whole["std"]), np.array(whole["theta"]))
    obs = np.random.default_rng(2).uniform(-3, 3, (200, N)).astype(np.float32)
    obs[:, score_ars.HOLD] = np.arange(200) % 2
    obs[:, score_ars.REVERSE] = 1 - obs[:, score_ars.HOLD]
    got = ort.InferenceSession(str(POLICY), providers=["CPUExecutionProvider"]).run(None, {"obs": obs})[0]
    assert np.max(np.abs(got.reshape(-1) - pol(obs))) < 1e-5


@pytest.mark.slow
@pytest.mark.skipif(not POLICY.exists(), reason="no shipped drive policy")
def test_the_drive_policy_deploys_on_the_geared_emulator_in_two_rate_mode(tmp_path):
    """deploy --policy drive_ars.onnx --host-rate-hz 100 against the lock-step emulator serving a geared
    drive: complete, 0 samples lost, and lambda66 inside the spread of the same policy on the simulated
    two-rate board over four sensor seeds (widened by 0.5 % of the truth)."""
    from addedinertia_env.experiment.protocol import Experiment
    from addedinertia_env.experiment.two_rate import drive_two_rate
    from addedinertia_env.identify import identify
    from addedinertia_env.loop.board_loop import TwoRateSimRig
    from addedinertia_env.sim.mujoco_rig import MujocoRig
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping
    from agents import make_controller
    from hw_adapter.deploy import DeployOptions, deploy
    from hw_adapter.lab import load_lab
    from hw_adapter.loopback import start_emulator

    params = rig_from_mapping(load_preset(GEARED))
    truth = params.hull.lambda66  # scoring only
    lab = load_lab(GEARED)
    server = start_emulator(GEARED, fast=True)
    try:
        opts = DeployOptions(bench=server.url, controller=f"onnx:{POLICY}", lab=lab, out=tmp_path, host_rate_hz=100.0)
        summary, status = deploy(opts, make_controller(f"onnx:{POLICY}"))
    finally:
        server.stop()
    assert status == 0 and summary["status"] == "complete", summary["status"]
    assert summary["samples_lost"] == 0 and summary["late_segments"] == 0
    sims = []
    for seed in range(4):
        exp = Experiment(TwoRateSimRig(MujocoRig(params, seed=seed), 100.0), lab.plan())
        exp.start()
        drive_two_rate(exp, make_controller(f"onnx:{POLICY}"), 100.0)
        sims.append(identify([exp.record("sim")], "energy").lambda66)  # as deploy identifies
    lo, hi = min(sims) - 0.005 * truth, max(sims) + 0.005 * truth
    assert lo <= summary["lambda66"] <= hi, (summary["lambda66"], sims)
