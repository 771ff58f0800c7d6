"""The energy method books a gearhead's loss identified on the flywheel's own balance (issue 28,
identify/energy_gear.py): through a gearbox the fit finds the hidden mesh loss and drag that the
simulator drew, and the estimate moves toward the truth; records without a gearbox are untouched."""

from __future__ import annotations

import pytest

import addedinertia_env.identify.energy_balance as energy_balance
from addedinertia_env.bench.runner import build_rig, cycle_seed, episode_controller
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.identify import identify
from addedinertia_env.identify.energy_balance import RunBalance


def _record(suite: str, controller: str, index: int = 0):
    """The benchmark's first cycle of ``controller`` (its default gains) on the suite's tuning scenario ``index``."""
    s = load_suite(suite)
    task = s.task(s.scenarios("tuning")[index], controller, tuned=False)  # the defaults: no tuned file read
    rig = build_rig(task.scenario, seed=cycle_seed(task.scenario, 0))
    return run_experiment(rig, episode_controller(controller, task.controller_kwargs, rig), task.scenario.plan)


def _error(rec) -> float:
    r = identify([rec.without_truth()], "energy", asymmetry_correction=False, interval_details=False)
    return r.lambda66 / rec.meta["truth"]["lambda66"] - 1.0


@pytest.fixture(scope="module")
def geared():
    """drive-v1's first tuning scenario (wigley-2m through 7.7:1, efficiency 93.6 %, drag 15 mN m),
    feedforward-pd: its pre-spin drives the flywheel and then brakes it, so both quadrants are seen."""
    return _record("drive-v1", "feedforward-pd")


def test_the_fit_finds_the_hidden_mesh_loss_and_drag(geared):
    g = RunBalance(geared.without_truth(), "reaction", False).gear_loss
    truth = geared.meta["truth"]["drive"]
    assert g is not None and g.both_quadrants
    assert g.mesh == pytest.approx(1.0 - truth["gear_efficiency"], rel=0.2)
    assert g.drag == pytest.approx(truth["gear_drag"], rel=0.2)
    assert g.scale == pytest.approx(1.0, abs=0.02)  # the preset's current gain error is 0.5 %


def test_booking_the_loss_takes_out_most_of_its_bias(geared, monkeypatch):
    booked = _error(geared)
    monkeypatch.setattr(energy_balance, "GEAR_LOSS", False)
    written = _error(geared)
    assert abs(written) > 0.01  # the loss biases the method as it was by percents
    assert abs(booked) < 0.4 * abs(written), (booked, written)


def test_a_flywheel_without_current_books_nothing():
    """`zero` drives no current: no mesh loss, and the drag alone is not read (module doc)."""
    rec = _record("drive-v1", "zero")
    assert RunBalance(rec.without_truth(), "reaction", False).gear_loss is None


def test_a_record_without_a_gearbox_is_estimated_bit_for_bit_as_before(monkeypatch):
    rec = _record("standard-v0", "feedforward-pd", 1)
    assert rec.known.gear_ratio == 1.0
    on = identify([rec.without_truth()], "energy", asymmetry_correction=False)
    monkeypatch.setattr(energy_balance, "GEAR_LOSS", False)
    off = identify([rec.without_truth()], "energy", asymmetry_correction=False)
    assert on.lambda66 == off.lambda66 and on.ci95 == off.ci95
