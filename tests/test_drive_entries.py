"""The drive entries of issue 28 (agents/backlash_inversion.py, agents/voltage_antiwindup.py): each does
what its physics says on a drive-v1 rig."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.sim.mujoco_rig import MujocoRig
from agents import make_controller


@pytest.fixture(scope="module")
def geared_scenario():
    return load_suite("drive-v1").scenarios("tuning")[0]


def _episode(name, sc, **kw):
    rig = MujocoRig(sc.rig, seed=sc.sensor_seed)
    rec = run_experiment(rig, make_controller(name, tuned=False, **kw), sc.plan)
    return rec, rig.true_state()


@pytest.mark.slow
def test_backlash_inversion_keeps_the_torque_sign_and_loses_less_in_the_gap(geared_scenario):
    """Through the stroke the command keeps one sign at or beyond the pre-load, so the rotor stays on
    its flank: the impacts lose less than feedforward-pd's (same scenario, same sensor noise)."""
    sc = geared_scenario
    rec, state = _episode("backlash-inversion", sc, preload=0.1)
    rev = rec.phase == "reverse"
    i = rec["i_cmd"][rev]
    s = np.sign(np.median(i))
    assert np.all(s * i >= 0.1 - 1e-12), f"min signed command {np.min(s * i):.3f} A"
    _, ff_state = _episode("feedforward-pd", sc)
    assert state.impact_loss < ff_state.impact_loss, (state.impact_loss, ff_state.impact_loss)


def test_voltage_antiwindup_clamps_to_the_supply_and_stops_integrating():
    """With the back-EMF near the supply the command is cut to ``(u_max h - k_t Omega) / R`` and the
    integral does not grow; inside the reach it integrates as the PID does."""
    ctrl = make_controller("pid-antiwindup", tuned=False)
    ctrl.ctx = SimpleNamespace(rig=SimpleNamespace(u_max=24.0, R=0.5), k_t=0.25, i_max=15.0, dt=1e-3)
    ctrl.J, ctrl.integral = 10.0, 0.0
    reach = (0.95 * 24.0 - 0.25 * 80.0) / 0.5  # 5.6 A at Omega = 80 rad/s
    i = ctrl.feedback({"flywheel_rate": 80.0}, -0.05, 0.0)  # hull ahead: a large positive command
    assert i == pytest.approx(reach) and ctrl.integral == 0.0
    i = ctrl.feedback({"flywheel_rate": 0.0}, -1e-4, 0.0)
    assert 0 < i < reach and ctrl.integral == pytest.approx(-1e-7)
