"""smith-pd (agents/smith_pd.py, agents/dead_time.py, agents/stroke_inertia.py) and drive-v3
(configs/suites/drive-v3.yaml): the dead-time predictor against an independent simulation of the delayed
plant, the whole-stroke inertia against an oscillator's, the stated round trip (drawn, carried, refused)."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import expm

from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.reference import fit_stroke
from addedinertia_env.experiment.runner import stated_round_trip
from addedinertia_env.loop.control_loop import ControlLoop, LoopRig
from addedinertia_env.sim.presets import ConfigError
from agents import make_controller
from agents.dead_time import DeadTimePredictor
from agents.observer import HullObserver
from agents.smith_pd import fit_prespin, link_delay_samples
from agents.stroke_inertia import stroke_fit_inertia

J, C, K_T, DT = 12.0, 40.0, 0.2, 0.001  # kg m^2, N m/rad, N m/A, s


def _plant(n_steps: int, delay: int, braked: int, seed: int = 0):
    """The hull ``J phi'' = -c phi - k_t i + d`` integrated exactly over each sample (zero-order hold, matrix
    exponential: independent of the observer's own discretisation), braked at rest for the first ``braked``
    samples; random commands and a known torque. Returns the true states, the commands, the known torques and
    the readings as they arrive ``delay`` samples late."""
    rng = np.random.default_rng(seed)
    M = np.zeros((3, 3))
    M[0, 1], M[1, 0], M[1, 2] = 1.0, -C / J, 1.0 / J
    Phi = expm(M * DT)
    x = np.array([0.05, 0.0])
    states, cmds, dexp = [], [], []
    for k in range(n_steps):
        i, d = float(rng.normal(0.0, 3.0)), float(rng.normal(0.0, 0.5))
        states.append(x.copy())
        cmds.append(i)
        dexp.append(d)
        if k >= braked:  # the brake holds the hull until then
            x = (Phi @ np.array([x[0], x[1], -K_T * i + d]))[:2]
    states = np.array(states)
    readings = [states[max(0, k - delay), 0] for k in range(n_steps)]
    return states, np.array(cmds), np.array(dexp), np.array(readings)


@pytest.mark.parametrize("delay", [0, 4, 12])
def test_the_predictor_gives_the_undelayed_state_of_a_linear_plant(delay):
    braked = 20
    states, cmds, dexp, y = _plant(400, delay, braked)
    obs = HullObserver(J, C, K_T, DT, encoder_counts=2**40, disturbance_bandwidth=1e-6)
    pred = DeadTimePredictor(obs, delay)
    pred.start(y[braked])  # the first reading of the controlled part: the hull braked at rest, n samples ago
    worst, moved = 0.0, 0.0
    for k in range(braked + 1, 400):
        x = pred.update(cmds[k - 1], dexp[k - 1], y[k])
        worst = max(worst, abs(x[0] - states[k, 0]), DT * abs(x[1] - states[k, 1]))
        moved = max(moved, abs(states[k, 0] - states[max(0, k - delay), 0]))
    assert worst < 1e-7  # the prediction is the state now, to the discretisations' difference
    if delay:
        assert moved > 1e3 * worst  # while the reading is far from it


def test_the_predictor_refuses_a_negative_delay():
    with pytest.raises(ValueError, match="delay_samples"):
        DeadTimePredictor(HullObserver(J, C, K_T, DT, 2**17), -1)


def _law_context(phi_of_t, t_stop: float, c: float = C):
    t = np.arange(0.0, t_stop + 0.2, DT)
    law = fit_stroke(t, phi_of_t(t), 0.2 * t_stop, t_stop)
    return SimpleNamespace(reference=SimpleNamespace(law=law), rig=SimpleNamespace(c_torsion=c, phi_neutral=0.0))


def test_the_whole_stroke_inertia_is_an_undamped_oscillators_and_lower_with_damping():
    w = math.sqrt(C / J)
    t_stop = math.pi / w  # released at -0.06 rad at t = 0, stops at +0.06 rad half a period later
    undamped = _law_context(lambda t: -0.06 * np.cos(w * t), t_stop)
    assert stroke_fit_inertia(undamped) == pytest.approx(J, rel=0.01)
    zeta = 0.05  # a viscously damped one: J phi'' + 2 zeta w J phi' + c phi = 0
    wd = w * math.sqrt(1 - zeta**2)
    damped = _law_context(lambda t: -0.06 * np.exp(-zeta * w * t) * (np.cos(wd * t) + zeta * w / wd * np.sin(wd * t)),
                          math.pi / wd)
    assert 0.6 * J < stroke_fit_inertia(damped) < J


def test_the_prespin_moves_to_the_nearest_that_fits_or_is_given_up():
    assert fit_prespin(-5.0, 5.0, -3.0) == -3.0
    assert fit_prespin(-2.0, 5.0, -3.0) == -2.0
    assert fit_prespin(4.0, 1.0, -3.0) == 0.0  # no pre-spin fits the supply: none, as pd


def _context(link):
    from addedinertia_env.experiment.protocol import Experiment
    from addedinertia_env.experiment.runner import controller_context
    from addedinertia_env.experiment.scenarios import build_rig

    suite = load_suite("drive-v3")
    sc = suite.scenario(suite.seeds("tuning")[0])
    exp = Experiment(build_rig(sc), sc.plan)
    exp.start()
    ctx = controller_context(exp)
    assert ctx.link_round_trip_s == sc.loop.stated_round_trip_s  # the suite's statement reaches the controller
    return dataclasses.replace(ctx, link_round_trip_s=link) if link != "as-drawn" else ctx


@pytest.mark.parametrize("link, words", [(None, "link_round_trip_s = None"), (-0.001, "link_round_trip_s = -0.001"),
                                         (math.nan, "link_round_trip_s = nan"), (0.5, "link_round_trip_s = 0.5"),
                                         ("8 ms", "link_round_trip_s = '8 ms'")])
def test_smith_pd_refuses_a_missing_or_invalid_stated_round_trip_by_name(link, words):
    ctx = _context(link)
    with pytest.raises(ValueError) as err:
        make_controller("smith-pd").reset(ctx)
    assert "smith-pd" in str(err.value) and words in str(err.value), str(err.value)


def test_smith_pd_takes_the_stated_round_trip_in_samples():
    ctx = _context("as-drawn")
    c = make_controller("smith-pd")
    c.reset(ctx)
    assert c.delay == link_delay_samples(ctx) == round(ctx.link_round_trip_s / ctx.dt) > 0


def test_drive_v3_is_drive_v2s_physics_with_the_round_trip_stated_within_a_millisecond():
    v2, v3 = load_suite("drive-v2"), load_suite("drive-v3")
    assert v3.seeds("tuning") == v2.seeds("tuning")  # the same tuning scenarios: drive-v2's gains stay valid
    assert len(v3.seeds("test")) == 64 and not set(v3.seeds("test")) & set(v2.seeds("test"))
    for seed in [*v3.seeds("tuning")[:3], v3.seeds("test")[0], 10**9 + 1]:
        a, b = v3.scenario(seed), v2.scenario(seed)
        assert a.rig == b.rig and a.plan == b.plan
        assert a.loop.obs_delay_s == b.loop.obs_delay_s and b.loop.stated_round_trip_s is None
        assert abs(a.loop.stated_round_trip_s - a.loop.obs_delay_s) <= 0.001
        assert a.loop.stated_round_trip_s != a.loop.obs_delay_s  # measured, not copied from the truth


def test_the_stated_round_trip_comes_only_from_the_loop_that_states_it():
    rig = SimpleNamespace(dt=DT, source="sim")
    assert stated_round_trip(rig) is None
    assert stated_round_trip(LoopRig(rig, ControlLoop(obs_delay_s=0.008))) is None
    assert stated_round_trip(LoopRig(rig, ControlLoop(obs_delay_s=0.008, stated_round_trip_s=0.0085))) == 0.0085
    with pytest.raises(ValueError, match="stated_round_trip_s"):
        ControlLoop(obs_delay_s=0.008, stated_round_trip_s=-1.0)


@pytest.mark.parametrize("block, words", [
    ("link: {stated: guessed}", "link.stated = 'guessed'"),
    ("link: {stated: measured}", "link.error_s = None"),
    ("link: {stated: measured, error_s: -0.001}", "link.error_s = -0.001"),
    ("link: {stated: measured, error_s: 0.05}", "link.error_s = 0.05"),
    ("link: {stated: exact, error_s: 0.001}", "link.error_s = 0.001"),
    ("link: {stated: exact, ping_ms: 3}", "link.ping_ms"),
    ("link: exact", "link = 'exact'"),
    ("loop: {stated_round_trip_s: 0.01}", "loop.stated_round_trip_s"),
])
def test_a_bad_link_block_is_refused_by_name(tmp_path, block, words):
    path = tmp_path / "bad-link.yaml"
    loop = "" if block.startswith("loop") else "loop: {obs_delay_s: [0.001, 0.016]}\n"
    path.write_text(f"name: t\nsplits: {{test: {{first_seed: 1, count: 2}}}}\n{loop}{block}\n")
    with pytest.raises(ConfigError) as err:
        load_suite(str(path))
    assert words in str(err.value) and str(path) in str(err.value), str(err.value)


def test_a_link_block_needs_a_drawn_round_trip(tmp_path):
    path = tmp_path / "no-loop.yaml"
    path.write_text("name: t\nsplits: {test: {first_seed: 1, count: 2}}\nlink: {stated: exact}\n")
    with pytest.raises(ConfigError, match="obs_delay_s"):
        load_suite(str(path))


@pytest.mark.parametrize("controller", ["smith-pd", "pd", "pid", "lqr", "feedforward-pd", "supply-aware"])
def test_drive_v3_tuned_gains_load_and_the_older_entries_keep_drive_v2s(controller):
    from addedinertia_env.bench.runner import episode_controller

    v2, v3 = load_suite("drive-v2"), load_suite("drive-v3")
    task = v3.task(v3.scenarios("tuning")[0], controller)
    assert task.controller_kwargs  # the suite's own file holds gains for the entry
    episode_controller(controller, task.controller_kwargs, None)  # unknown or stale keys would raise
    if controller != "smith-pd":
        assert task.controller_kwargs == v2.task(v2.scenarios("tuning")[0], controller).controller_kwargs
