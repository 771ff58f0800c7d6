"""Forced-oscillation experiment and estimator (Chinese patent's method, physics.md section 5)."""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.experiment.forced import ForcedPlan, run_forced
from addedinertia_env.identify import IdentificationError, identify
from addedinertia_env.records.record import RunRecord
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import HullParams, RigParams, SensorParams

PLAN = ForcedPlan(alpha=0.05, ratios=(0.75, 1.3), periods=2)


@pytest.fixture(scope="module")
def forced_run() -> RunRecord:
    """Quadratic + linear damping (the method needs no damping law), ideal sensors."""
    rig = RigParams(hull=HullParams(lambda66=8.0, b1=0.2, b2=60.0), sensors=SensorParams.ideal())
    return run_forced(MujocoRig(rig, seed=3), PLAN, run_id="forced")


def test_record_lists_its_drive(forced_run):
    rec = forced_run
    assert rec.experiment["kind"] == "forced-oscillation"
    segs = rec.experiment["segments"]
    assert [s["ratio"] for s in segs] == [0.75, 1.3]
    assert rec.experiment["frequencies_hz"] == pytest.approx([s["omega"] / (2 * np.pi) for s in segs])
    first = rec.t < segs[0]["t_start"]
    assert set(rec.phase[first]) == {"idle", "free"} and np.all(rec["i_cmd"][first] == 0.0)
    driven = (rec.t > segs[0]["t_start"]) & (rec.t <= segs[-1]["t_end"])
    assert set(rec.phase[driven]) == {"idle"}
    assert np.max(np.abs(rec["i_cmd"][driven])) > 0.1
    # The natural-frequency guess from the half swing is close to the truth (damped).
    J = 5.8 + 8.0
    assert rec.experiment["omega_guess"] == pytest.approx(np.sqrt(rec.known.c_torsion / J), rel=0.05)


def test_recovers_lambda66(forced_run):
    truth = forced_run.truth_lambda66()
    result = identify([forced_run], "forced")
    assert result.lambda66 == pytest.approx(truth, rel=0.01)
    lo, hi = result.ci95
    assert lo <= truth <= hi
    assert result.n_intervals >= 4
    # At the zero-rate instants the damping is gone: torque/acceleration is the inertia there.
    ratios = [p["torque"] / p["accel"] for p in result.details["intervals"]]
    assert np.median(ratios) == pytest.approx(truth + forced_run.known.J_hull, rel=0.01)


def test_current_offset_is_removed(forced_run):
    """A constant current-sensor offset (measurable while the motor is passive) changes nothing."""
    samples = dict(forced_run.samples)
    samples["i"] = samples["i"] + 0.05
    shifted = identify([RunRecord(samples=samples, meta=forced_run.meta)], "forced")
    assert shifted.lambda66 == pytest.approx(identify([forced_run], "forced").lambda66, rel=1e-6)


def test_refuses_other_kinds_and_missing_segments(forced_run):
    meta = dict(forced_run.meta)
    meta["experiment"] = {**forced_run.experiment, "kind": "free-decay"}
    with pytest.raises(IdentificationError, match="forced-oscillation"):
        identify([RunRecord(samples=forced_run.samples, meta=meta)], "forced")
    meta["experiment"] = {k: v for k, v in forced_run.experiment.items() if k != "segments"}
    with pytest.raises(IdentificationError, match="segments"):
        identify([RunRecord(samples=forced_run.samples, meta=meta)], "forced")


def test_plan_validation():
    with pytest.raises(ValueError, match="ratios"):
        ForcedPlan(ratios=(1.0, 1.2))
