"""The cogging feed-forward entry (agents/cogging_ff.py, issue 28 Build 3): its angle from the
flywheel rate does not drift, its map finds the motor's cogging in the hold (and none where there is
none), and its feed-forward cancels the cogging the flywheel feels in the stroke."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from addedinertia_env.bench.suites import load_suite
from addedinertia_env.experiment.filters import RateEstimator
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.sim.forces import true_torque_constant
from addedinertia_env.sim.mujoco_rig import MujocoRig
from agents import make_controller


def test_summed_flywheel_rate_follows_the_encoder_without_drift():
    """The controller's angle, the rate estimate summed over the samples, is the encoder's angle up
    to a constant: exact for a quadratic, a small smoothing error on a fast ripple, no drift."""
    dt, q = 1e-3, 2 * math.pi / 4096
    t = np.arange(0.0, 6.0, dt)
    angle = 1.5 * t**2 - 0.8 * t + 2e-3 * np.sin(2 * math.pi * 3.0 * t)
    est = RateEstimator(dt)
    rates = np.array([est.update(float(np.round(a / q) * q)) for a in angle])
    summed = np.concatenate([[0.0], np.cumsum(0.5 * (rates[1:] + rates[:-1])) * dt])  # as the entry sums it
    k0 = 100  # once the window has filled
    err = (summed - angle) - (summed[k0] - angle[k0])
    assert np.max(np.abs(err[k0:])) < 3e-3, np.max(np.abs(err[k0:]))
    # no drift: the error's mean over the last second as over the second
    assert abs(np.mean(err[-1000:]) - np.mean(err[1000:2000])) < 2e-4


def _ripple(rec, p):
    """Amplitude (N m) of the net torque on the flywheel ``k_t i + T_cog`` at the cogging's period over
    the reverse stroke, where a cycle spans 8 samples or more (a held command can act on it)."""
    d = p.drive
    N, m = d.gear_ratio, d.cogging_periods * d.gear_ratio
    t, psi, i = np.asarray(rec.t), np.asarray(rec["psi"], float), np.asarray(rec["i"], float)
    om = np.gradient(psi, t)
    th = m * psi + d.cogging_phase
    net = true_torque_constant(p) * i + N * d.cogging_torque * np.sin(th)
    sel = (rec.phase == "reverse") & (m * np.abs(om) * float(np.median(np.diff(t))) * 8 < 2 * math.pi)
    assert sel.sum() > 200, sel.sum()
    tt = t[sel] - t[sel][0]
    A = np.column_stack([np.ones(sel.sum()), tt, tt**2, np.sin(th[sel]), np.cos(th[sel])])
    c, *_ = np.linalg.lstsq(A, net[sel], rcond=None)
    return math.hypot(c[3], c[4])


@pytest.mark.slow
def test_cogging_map_and_feedforward_on_a_drive_v1_scenario():
    """drive-v1 tuning scenario 720000 (a 4.75 s hold, 7.7:1, 4.5 mN m x 24 at the motor): the map
    finds 24 cycles per motor turn and the amplitude at the flywheel within 20 %; fed forward, the
    cogging the flywheel feels in the stroke falls to less than 40 % of the same controller's without
    the feed-forward (same scenario, same sensor noise); with the cogging switched off nothing is
    mapped."""
    sc = load_suite("drive-v1").scenarios("tuning")[0]
    d = sc.rig.drive
    assert sc.plan.hold_s > 2.5 and d.cogging_torque > 0  # the scenario this test is about

    runs = {}
    for comp in (True, False):
        c = make_controller("cogging-ff", tuned=False, compensate=comp)
        rec = run_experiment(MujocoRig(sc.rig, seed=sc.sensor_seed), c, sc.plan)
        runs[comp] = (c.cogging, _ripple(rec, sc.rig))
    cg = runs[True][0]
    assert cg["found"] and cg["n"] == round(d.cogging_periods), cg
    assert cg["amplitude"] == pytest.approx(d.gear_ratio * d.cogging_torque, rel=0.2)
    assert runs[True][1] < 0.4 * runs[False][1], (runs[True][1], runs[False][1])

    clean = dataclasses.replace(sc, rig=sc.rig.replace(drive=dataclasses.replace(d, cogging_torque=0.0)))
    c = make_controller("cogging-ff", tuned=False)
    run_experiment(MujocoRig(clean.rig, seed=clean.sensor_seed), c, clean.plan)
    assert not c.cogging["found"], c.cogging


def test_a_suites_tuned_loop_gains_reach_cogging_ff():
    """cogging-ff adds no loop knob: on a suite with its own tuned file it runs feedforward-pd's gains
    from that file (the same tuning budget), not the global defaults."""
    from agents.tuned import load_tuned
    from addedinertia_env.bench.suites import load_suite

    suite = load_suite("drive-v1")
    scenario = suite.scenarios("test")[0]
    own = load_tuned("feedforward-pd", suite.tuned_path)
    assert own, "drive-v1 has tuned feedforward-pd gains"
    kwargs = suite.task(scenario, "cogging-ff").controller_kwargs
    assert {k: kwargs[k] for k in own} == own and kwargs["tuned"] is False
    assert suite.task(scenario, "cogging-ff", tuned=False).controller_kwargs == {"tuned": False}
