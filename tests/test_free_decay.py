"""Free-decay experiment and the textbook free-decay estimator (physics.md section 5)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from addedinertia_env.experiment.free_decay import FreeDecayPlan, run_free_decay
from addedinertia_env.identify import IdentificationError, identify
from addedinertia_env.records.record import RunRecord
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import HullParams, MotorParams, RigParams, SensorParams


@pytest.fixture(scope="module")
def linear_decay() -> RunRecord:
    """Linear hull damping only (the method's assumption), ideal sensors, a real flywheel bearing."""
    rig = RigParams(hull=HullParams(lambda66=9.0, b1=0.6, b2=0.0), sensors=SensorParams.ideal())
    return run_free_decay(MujocoRig(rig, seed=1), FreeDecayPlan(alpha=0.08, periods=4), run_id="linear")


def test_record_is_a_free_decay(linear_decay):
    rec = linear_decay
    assert rec.experiment["kind"] == "free-decay"
    phases = list(dict.fromkeys(rec.phase.tolist()))
    assert phases == ["idle", "free"]
    free = rec.phase == "free"
    assert np.all(rec["i_cmd"][free] == 0.0) and np.all(rec["brake"][free] == 0.0)
    assert rec.experiment["neutral_crossings"] >= 2 * 4 + 1
    assert rec["phi"][0] == pytest.approx(-0.08, abs=1e-9)


def test_recovers_lambda66_with_linear_damping(linear_decay):
    truth = linear_decay.truth_lambda66()
    result = identify([linear_decay], "free-decay")
    assert result.lambda66 == pytest.approx(truth, rel=0.005)
    lo, hi = result.ci95
    assert lo < result.lambda66 < hi
    assert result.n_intervals >= 4


def test_flywheel_drag_is_measured_not_assumed():
    """A stiff flywheel bearing drags the 'free' flywheel along; ignoring that would add kappa J_f."""
    rig = RigParams(hull=HullParams(lambda66=9.0, b1=0.6, b2=0.0), sensors=SensorParams.ideal(),
                    motor=MotorParams(J_flywheel=0.2, friction_coulomb=0.01))
    rec = run_free_decay(MujocoRig(rig, seed=2), FreeDecayPlan(alpha=0.03, periods=3), run_id="drag")
    result = identify([rec], "free-decay")
    periods = result.details["intervals"]
    assert min(p["kappa"] for p in periods) > 0.3
    truth = rec.truth_lambda66()
    uncorrected = float(np.mean([p["lambda66"] + p["kappa"] * rig.motor.J_flywheel for p in periods]))
    assert abs(result.lambda66 - truth) < 0.25 * abs(uncorrected - truth)
    assert result.lambda66 == pytest.approx(truth, rel=0.01)


def test_locked_flywheel_counts_its_inertia(linear_decay):
    """A record that says the flywheel was locked has J_f taken off with kappa = 1."""
    meta = dict(linear_decay.meta)
    meta["experiment"] = {**linear_decay.experiment, "flywheel": "locked"}
    locked = RunRecord(samples=linear_decay.samples, meta=meta)
    free = identify([linear_decay], "free-decay")
    res = identify([locked], "free-decay")
    assert all(p["kappa"] == 1.0 for p in res.details["intervals"])
    assert res.lambda66 < free.lambda66


def test_refuses_other_kinds(linear_decay):
    meta = dict(linear_decay.meta)
    meta["experiment"] = {**linear_decay.experiment, "kind": "reverse-symmetric"}
    with pytest.raises(IdentificationError, match="free-decay"):
        identify([RunRecord(samples=linear_decay.samples, meta=meta)], "free-decay")


def test_refuses_a_record_without_swings(linear_decay):
    keep = slice(0, 300)  # idle and the first 0.1 s of release
    samples = {k: v[keep] for k, v in linear_decay.samples.items()}
    with pytest.raises(IdentificationError):
        identify([RunRecord(samples=samples, meta=linear_decay.meta)], "free-decay")


def test_plan_reuses_a_preset_twist():
    from addedinertia_env.experiment.protocol import ExperimentPlan

    assert FreeDecayPlan.from_any(ExperimentPlan(alpha=0.07)).alpha == 0.07
    with pytest.raises(ValueError, match="periods"):
        dataclasses.replace(FreeDecayPlan(), periods=1)
