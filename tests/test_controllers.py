"""Classical controllers: each runs an episode of the smoke suite within the current limit."""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.sim.mujoco_rig import MujocoRig
from agents import make_controller
from agents.observer import HullObserver
from addedinertia_env.bench.tuning import sample_candidates, score
from agents.tuned import resolve_params

CONTROLLERS = ["pd", "feedforward-pd", "pid", "lqr", "ilc", "mpc"]


@pytest.fixture(scope="module")
def smoke_scenario():
    return load_suite("smoke").scenarios("test")[0]


@pytest.mark.parametrize("name", CONTROLLERS)
def test_controller_runs_within_current_limit(name, smoke_scenario):
    """Hand-set gains (``tuned=False``): the controller's physics, apart from tuning noise."""
    sc = smoke_scenario
    ctrl = make_controller(name) if name == "pd" else make_controller(name, tuned=False)
    rec = run_experiment(MujocoRig(sc.rig, seed=sc.sensor_seed), ctrl, sc.plan)
    rev = rec.phase == "reverse"
    i_max = rec.known.i_max
    assert rev.sum() > 100
    assert np.all(np.isfinite(rec["i_cmd"]))
    assert np.max(np.abs(rec["i_cmd"])) <= i_max + 1e-9
    # The reverse stroke retraces the free one mirrored in time about the reversal:
    # phi_rev(t_begin + s) = phi_free(t_brake - s) over most of the stroke. Doing
    # nothing (zero current) misses this by about 2.4 % of alpha on this scenario.
    t, phi = rec.t, rec["phi"]
    t_rev = t[rev]
    s = t_rev[: int(0.8 * len(t_rev))] - t_rev[0]
    free = rec.phase == "free"
    mirrored = np.interp(rec.experiment["t_brake"] - s, t[free], phi[free])
    rms = float(np.sqrt(np.mean((phi[rev][: len(s)] - mirrored) ** 2)))
    assert rms < 0.01 * abs(rec.experiment["alpha"])


def test_observer_tracks_a_simulated_hull_better_than_differences():
    """Kalman rate vs raw differences on a quantised, spring-driven hull with known torque."""
    J, c, k_t, dt, counts = 10.0, 40.0, 0.25, 1e-3, 2**17
    q = 2 * np.pi / counts
    obs = HullObserver(J, c, k_t, dt, counts, disturbance_bandwidth=5.0)
    rng = np.random.default_rng(1)
    phi, w = 0.05, 0.0
    obs.start(round(phi / q) * q, 0.0)
    errs_kf, errs_diff, prev = [], [], round(phi / q) * q
    for k in range(3000):
        i = 2.0 * np.sin(0.003 * k) + 0.1 * rng.standard_normal()
        acc = (-c * phi - k_t * i) / J
        phi, w = phi + w * dt + 0.5 * acc * dt * dt, w + acc * dt
        meas = round(phi / q) * q
        obs.predict(i, 0.0)
        obs.correct(meas)
        if k > 500:
            errs_kf.append(obs.rate - w)
            errs_diff.append((meas - prev) / dt - w)
        prev = meas
    rms_kf, rms_diff = np.sqrt(np.mean(np.square(errs_kf))), np.sqrt(np.mean(np.square(errs_diff)))
    assert rms_kf < 0.1 * rms_diff
    assert rms_kf < 2e-3  # rad/s


def test_ilc_keeps_its_correction_between_cycles(smoke_scenario):
    sc = smoke_scenario
    ctrl = make_controller("ilc")
    run_experiment(MujocoRig(sc.rig, seed=1), ctrl, sc.plan)
    assert not ctrl.learned.any()
    run_experiment(MujocoRig(sc.rig, seed=2), ctrl, sc.plan)  # reset() folds cycle 1 in
    assert ctrl.cycles_seen == 1 and np.abs(ctrl.learned).max() > 0


def test_tuned_params_resolution_refuses_unknown_keys():
    assert resolve_params(None, {"a": 1.0}, {"a": 2.0}) == {"a": 2.0}
    with pytest.raises(TypeError, match="unknown controller parameter"):
        resolve_params(None, {"a": 1.0}, {"b": 2.0})
    with pytest.raises(TypeError):
        make_controller("lqr", no_such_knob=1.0)


def test_tuning_candidates_and_score():
    cands = sample_candidates({"x": (1.0, 100.0, "log"), "y": (0.0, 1.0, "lin")}, 20, seed=3)
    assert cands[0] == {} and len(cands) == 20
    xs = np.array([c["x"] for c in cands[1:]])
    assert np.all((xs >= 1.0) & (xs <= 100.0)) and np.median(np.log10(xs)) == pytest.approx(1.0, abs=0.4)
    assert sample_candidates({"x": (1.0, 2.0, "lin")}, 5, seed=3) == sample_candidates({"x": (1.0, 2.0, "lin")}, 5, seed=3)
    assert score([0.01, -0.02, None]) == pytest.approx((0.01 + 0.02 + 0.10) / 3)  # a failure at the 10 % cap
    assert score([0.01, None, 0.5]) == pytest.approx(0.07)
