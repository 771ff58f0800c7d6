"""Episode metrics are computed once, from the record: the env, the bench and the live
experiment agree, and there is one definition of "at the limit"."""

from __future__ import annotations

import math

import numpy as np
import pytest

from addedinertia_env.bench.runner import cycle_seed, run_episode
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.envs import ReverseStrokeEnv
from addedinertia_env.experiment.protocol import Experiment, ExperimentPlan
from addedinertia_env.experiment.runner import controller_context, run_experiment
from addedinertia_env.experiment.metrics import (
    SATURATION_FRACTION,
    current_at_limit,
    episode_metrics,
    samples_at_limit,
    stroke_reference,
    tracking_errors,
    voltage_at_limit,
)
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.sensors import Reading
from addedinertia_env.experiment.scenarios import build_rig
from addedinertia_env.experiment.task import ReverseStrokeTask
from agents import make_controller


@pytest.fixture(scope="module")
def episode():
    """One feedforward-PD experiment, with the live reference and per-sample tracking errors."""
    exp = Experiment(MujocoRig(RigParams(), seed=3), ExperimentPlan(hold_s=0.3))
    exp.start()
    task = ReverseStrokeTask.for_rig(exp.known)
    controller = make_controller("feedforward-pd")
    controller.reset(controller_context(exp))
    live_errors, limits = [], 0
    while exp.needs_control:
        action, _ = controller.predict(task.observe(exp))
        cmd = task.command(action)
        r = exp.step(cmd)
        e = task.tracking_error(exp, r)
        if e is not None:
            live_errors.append(e)
        limits += task.at_limit(cmd, r)
    return exp, exp.record("m"), np.array(live_errors), limits


def test_the_reference_refitted_from_the_record_is_the_one_driven(episode):
    exp, rec, _, _ = episode
    ref = stroke_reference(rec)
    assert ref.t_begin == exp.reference.t_begin and ref.t_end == exp.reference.t_end
    np.testing.assert_array_equal(ref.law.coef, exp.reference.law.coef)


def test_record_metrics_equal_the_live_ones(episode):
    exp, rec, live_errors, limits = episode
    errors = tracking_errors(rec)
    np.testing.assert_array_equal(errors, live_errors)
    m = episode_metrics(rec)
    assert m.tracking_rms_rad == pytest.approx(math.sqrt(np.mean(live_errors**2)), rel=1e-12)
    assert m.energy_J == pytest.approx(exp.electric_energy, rel=1e-12)
    controlled = np.isin(rec.phase, ("hold", "reverse")).sum()
    assert m.saturated_frac == pytest.approx(limits / controlled)


def test_bench_row_and_env_info_are_the_metrics_of_their_records():
    suite = load_suite("smoke")
    scenario = suite.scenarios("test")[0]
    row = run_episode(suite.task(scenario, "feedforward-pd"))
    assert row["failure"] is None
    rec = run_experiment(build_rig(scenario, seed=cycle_seed(scenario, 0)), make_controller("feedforward-pd"),
                         scenario.plan)
    m = episode_metrics(rec)
    assert (row["energy_J"], row["tracking_rms_rad"], row["saturated_frac"]) == (
        m.energy_J, m.tracking_rms_rad, m.saturated_frac)
    env = ReverseStrokeEnv(hold_s=0.2, randomize=False)
    obs, _ = env.reset(seed=1)
    controller = make_controller("feedforward-pd")
    controller.reset(env.controller_context())
    done, info = False, {}
    while not done:
        action, _ = controller.predict(obs)
        obs, _, done, _, info = env.step(action)
    m = episode_metrics(env.record())
    assert (info["energy_J"], info["tracking_rms_rad"], info["saturated_frac"]) == (
        m.energy_J, m.tracking_rms_rad, m.saturated_frac)


def test_one_saturation_rule_for_reward_records_and_identification():
    task = ReverseStrokeTask(i_max=10.0, control_mode="voltage", u_max=48.0)
    reading = Reading(t=0.0, phi=0.0, psi=0.0, u=0.0, i=3.0, brake=False)
    assert task.at_limit(MotorCommand("current", SATURATION_FRACTION * 10.0), reading)
    assert not task.at_limit(MotorCommand("current", 0.99 * 10.0), reading)
    assert task.at_limit(MotorCommand("voltage", -48.0), reading)
    assert task.at_limit(MotorCommand("voltage", 1.0), Reading(0.0, 0.0, 0.0, 1.0, -10.0, False))
    assert bool(current_at_limit(-9.995, 10.0)) and not bool(current_at_limit(9.98, 10.0))
    assert bool(voltage_at_limit(0.0, 10.0, 48.0, 10.0))


def test_samples_at_limit_reads_the_command_columns(episode):
    _, rec, _, _ = episode
    i_max = rec.known.i_max
    rec2 = type(rec)(samples={**rec.samples, "i_cmd": np.where(rec.phase == "reverse", i_max, 0.0)}, meta=rec.meta)
    flags = samples_at_limit(rec2)
    assert flags[rec.phase == "reverse"].all() and not flags[rec.phase == "free"].any()
