"""The batched rig against the MuJoCo rig: same inputs, same trajectories.

Tolerances (stated in sim/batched.py and docs/PERFORMANCE.md):
* float64, hull free or braked from standstill: 1e-9 rad in phi and psi, 1e-9 rad/s in the
  rates (the engines differ only by rounding, ~1e-14, and by MuJoCo's soft brake, ~1e-9);
* brake set while the hull moves at w0: phi within |w0| physics_dt; Omega within 0.2 |w0| for
  the 10 ms MuJoCo's constraint takes to stop the hull, then within 1e-3 |w0|
  (MuJoCo's brake constraint needs about two physics steps to stop the hull);
* float32: 1e-4 rad in phi, 1e-4 relative in psi over 1 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from addedinertia_env.sim import effects as E
from addedinertia_env.sim.batched import CURRENT, PASSIVE, VOLTAGE, BatchedRig, reference_substep, substep_matrix
from addedinertia_env.sim.batched_params import BatchedParams
from addedinertia_env.sim.batched_single import BatchedSingleRig
from addedinertia_env.rig.interface import Rig
from addedinertia_env.sim.motor import MODES, MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import HullParams, MotorParams, RigParams

ALL_EFFECTS = E.Effects(bearing_coulomb=E.BearingCoulomb(0.06), fluid_memory=E.FluidMemory(8.0, 0.2),
                        spring_stiffening=E.SpringStiffening(6.0), neutral_offset=E.NeutralOffset(0.01),
                        sensor_delay=E.SensorDelay(0.0067), torque_constant=E.TorqueConstant(1.05))


def three_rigs() -> list[RigParams]:
    """Three different rigs (domain randomisation in one batch); one with every effect."""
    return [
        RigParams(),
        RigParams(hull=HullParams(J_hull=3.0, lambda66=4.0, b1=0.5, b2=10.0),
                  motor=MotorParams(J_flywheel=0.05, k_t=0.2), effects=ALL_EFFECTS),
        RigParams(hull=HullParams(lambda66=20.0), effects=E.Effects(bearing_coulomb=E.BearingCoulomb(0.03))),
    ]


def command(k: int, env: int, t: float) -> MotorCommand:
    """Per-environment inputs that switch between the drive's modes."""
    if env == 0:
        return MotorCommand("current", 3.0 * math.sin(7.0 * t))
    if env == 1:
        return MotorCommand("voltage", 6.0 * math.cos(3.0 * t)) if k < 500 else MotorCommand("passive")
    return MotorCommand("passive") if k < 300 else MotorCommand("current", -2.0 + 0.003 * k)


def run_both(rigs, n_samples, brake_events=(), dtype=np.float64, seed_base=10):
    """Step MujocoRigs and one BatchedRig with the same per-env inputs; returns state histories."""
    mj = [MujocoRig(p, seed=seed_base + k) for k, p in enumerate(rigs)]
    batch = BatchedRig(rigs, seed=[seed_base + k for k in range(len(rigs))], dtype=dtype)
    for r in mj:
        r.reset(phi0=-0.1, brake=False)
    batch.reset(phi0=-0.1, brake=False)
    events = dict(brake_events)
    hist_mj, hist_b, readings = [], [], []
    for k in range(n_samples):
        if k in events:
            for r in mj:
                r.set_brake(events[k])
            batch.set_brake(events[k])
        t = k * rigs[0].sensors.dt
        cmds = [command(k, e, t) for e in range(len(rigs))]
        ra = [r.step(c) for r, c in zip(mj, cmds)]
        rb = batch.step([MODES.index(c.mode) for c in cmds], [c.value for c in cmds])
        hist_mj.append([[s.phi, s.w, s.psi, s.omega, s.i] for s in (r.true_state() for r in mj)])
        hist_b.append(np.stack([batch.phi, batch.w, batch.psi, batch.omega, batch.i], axis=1).astype(float))
        readings.append((np.array([[x.phi, x.psi, x.u, x.i] for x in ra]),
                         np.stack([rb.phi, rb.psi, rb.u, rb.i], axis=1).astype(float)))
    return np.array(hist_mj), np.array(hist_b), readings


def test_substep_matrix_equals_stage_by_stage_rk4():
    rng = np.random.default_rng(3)
    c, J, J_f, k_t, R, L = 43.4, 17.5, 0.1, 0.25, 0.5, 5e-4
    for kind in range(4):
        G = substep_matrix(5e-4, kind, c, J, J_f, k_t, R, L)[:, :, 0]
        for _ in range(5):
            x = rng.normal(size=8) * np.array([0.1, 0.3, 10.0, 50.0, 5.0, 20.0, 3.0, 0.01])
            direct = np.array(reference_substep(tuple(x), 5e-4, kind, c, J, J_f, k_t, R, L))
            np.testing.assert_allclose(G @ x, direct, rtol=1e-12, atol=1e-15)


def test_batched_equals_mujoco_for_mixed_modes_and_every_effect():
    rigs = three_rigs()
    a, b, readings = run_both(rigs, 1000)
    err = np.abs(a - b)
    assert err[:, :, 0].max() < 1e-9, f"phi differs by {err[:, :, 0].max():.2e} rad"
    assert err[:, :, 2].max() < 1e-9, f"psi differs by {err[:, :, 2].max():.2e} rad"
    assert err[:, :, 1].max() < 1e-9 and err[:, :, 3].max() < 1e-8
    assert err[:, :, 4].max() < 1e-9, f"current differs by {err[:, :, 4].max():.2e} A"
    # The runs did move: the comparison is not between two resting rigs.
    assert np.ptp(a[:, :, 0]) > 0.05 and np.abs(a[:, :, 3]).max() > 1.0
    # Readings (quantisation, gain, offset, noise of the same seed, delay) agree too.
    worst = max(np.abs(ra - rb).max() for ra, rb in readings)
    assert worst < 1e-9, f"readings differ by {worst:.2e}"


def test_brake_hold_release_and_set_while_moving():
    rigs = [RigParams(), three_rigs()[1]]
    # braked from the start (flywheel spun by the drive), released, set again while moving, released
    events = {0: True, 300: False, 700: True, 1000: False}
    mj = [MujocoRig(p, seed=1) for p in rigs]
    batch = BatchedRig(rigs, seed=1)
    for r in mj:
        r.reset(phi0=-0.1, brake=True)
    batch.reset(phi0=-0.1, brake=True)
    h = rigs[0].physics_dt
    w0 = None
    errs = []
    for k in range(1200):
        if k in events:
            if k == 700:
                w0 = np.array([r.true_state().w for r in mj])
            for r in mj:
                r.set_brake(events[k])
            batch.set_brake(events[k])
        value = 2.0 * math.sin(0.005 * k)
        for r in mj:
            r.step(MotorCommand("current", value))
        batch.physics_step(CURRENT, value)
        s = [r.true_state() for r in mj]
        errs.append([[abs(x.phi - batch.phi[e]), abs(x.omega - batch.omega[e])] for e, x in enumerate(s)])
    errs = np.array(errs)
    assert errs[:700, :, 0].max() < 1e-8, "braked from standstill and released: phi within 1e-8 rad"
    assert errs[:700, :, 1].max() < 1e-6
    assert np.all(np.abs(w0) > 0.01), "the second brake must catch the hull moving"
    assert np.all(errs[700:, :, 0].max(axis=0) <= np.abs(w0) * h), "phi within |w0| physics_dt"
    # Omega: a transient while MuJoCo's constraint stops the hull, then within 1e-3 |w0|.
    assert np.all(errs[700:710, :, 1].max(axis=0) <= 0.2 * np.abs(w0))
    assert np.all(errs[710:, :, 1].max(axis=0) <= 1e-3 * np.abs(w0))
    assert np.all(errs[750:1000, :, 0] < 1e-9 + errs[705, :, 0]), "braked: the hull stays put"


def test_float32_agrees_within_its_tolerance():
    rigs = three_rigs()[:2]
    a, b, _ = run_both(rigs, 1000, dtype=np.float32)
    assert np.abs(a[:, :, 0] - b[:, :, 0]).max() < 1e-4
    assert (np.abs(a[:, :, 2] - b[:, :, 2]) / np.maximum(1.0, np.abs(a[:, :, 2]))).max() < 1e-4
    assert np.abs(a[:, :, 0] - b[:, :, 0]).max() > 0.0  # it really ran in float32


def test_batched_params_keep_per_env_values_and_neutral_effects():
    rigs = three_rigs()
    p = BatchedParams.stack(rigs)
    assert p.hull.lambda66.tolist() == [11.7, 4.0, 20.0]
    assert p.effects.bearing_coulomb.torque.tolist() == [0.0, 0.06, 0.03]
    assert p.effects.fluid_memory.beta.tolist() == [0.0, 0.2, 0.0]
    assert not p.uniform
    same = BatchedParams.repeat(RigParams(), 4)
    assert same.uniform and np.ndim(same.hull.lambda66) == 0 and same.effects.fluid_memory is None
    with pytest.raises(ValueError, match="physics_substeps"):
        BatchedParams.stack([RigParams(), RigParams(physics_substeps=4)])


def test_single_view_implements_the_rig_protocol_and_matches_mujoco():
    p = three_rigs()[1]
    a, b = MujocoRig(p, seed=5), BatchedSingleRig(p, seed=5)
    assert isinstance(b, Rig)
    ra, rb = a.reset(phi0=-0.08), b.reset(phi0=-0.08)
    assert ra == rb
    b.set_brake(False)
    a.set_brake(False)
    for k in range(300):
        cmd = MotorCommand("current", 1.5) if k % 100 < 50 else MotorCommand("passive")
        ra, rb = a.step(cmd), b.step(cmd)
    assert abs(ra.phi - rb.phi) < 1e-9 and abs(ra.i - rb.i) < 1e-9 and ra.t == pytest.approx(rb.t)
    assert b.truth() == a.truth()


def test_step_accepts_names_codes_and_refuses_bad_modes():
    rig = BatchedRig(RigParams(), n_envs=3, seed=0)
    rig.reset(phi0=-0.1, brake=False)
    rig.step(["current", "voltage", "passive"], [1.0, 2.0, 0.0])
    rig.step(np.array([CURRENT, VOLTAGE, PASSIVE]), 0.5)
    assert rig.i[2] == 0.0 and rig.i[0] != 0.0
    with pytest.raises(ValueError, match="motor mode"):
        rig.step("torque", 1.0)
    with pytest.raises(ValueError, match="expected 3 codes"):
        rig.step([1, 1], 1.0)


def test_experiment_on_the_single_view_gives_the_mujoco_estimate():
    """run_experiment drives the batched single view end to end; same seed, same lambda66."""
    from addedinertia_env.experiment.protocol import ExperimentPlan
    from addedinertia_env.experiment.runner import run_experiment
    from addedinertia_env.identify import identify
    from agents import make_controller

    p, plan = RigParams(), ExperimentPlan(hold_s=0.5)
    rec_mj = run_experiment(MujocoRig(p, seed=3), make_controller("feedforward-pd"), plan)
    rec_b = run_experiment(BatchedSingleRig(p, seed=3), make_controller("feedforward-pd"), plan)
    assert len(rec_b.samples["t"]) == len(rec_mj.samples["t"])
    assert rec_b.meta["experiment"]["t_brake"] == rec_mj.meta["experiment"]["t_brake"]
    est_mj = identify([rec_mj], "energy").lambda66
    est_b = identify([rec_b], "energy").lambda66
    assert abs(est_b - est_mj) < 1e-6 * est_mj, (est_b, est_mj)
    assert abs(est_mj - p.hull.lambda66) < 0.05 * p.hull.lambda66  # a real estimate, not a degenerate one




@pytest.mark.parametrize("effects", [E.Effects(), ALL_EFFECTS], ids=["plain", "every effect"])
def test_a_paused_environment_resumes_as_if_never_paused(effects):
    """Two copies of one rig, the second paused (``active`` False, given ``passive`` as the
    pool gives its paused slots) for 37 samples in the middle of a driven stretch: its state,
    clock and readings stay as they were, so sample by sample of its own it is the first copy.
    (Before, open terminals were applied to paused environments: a driven one lost its current.)"""
    rig = RigParams(effects=effects)
    batch = BatchedRig([rig, rig], seed=[5, 5])
    batch.reset(phi0=-0.1, brake=False)
    mine: list[list[np.ndarray]] = [[], []]
    pause = range(100, 137)
    for k in range(300 + len(pause)):
        active = np.array([True, k not in pause])
        if not active[1]:
            frozen = np.stack([batch.phi, batch.w, batch.psi, batch.omega, batch.i])[:, 1].copy()
        modes = np.array([CURRENT, CURRENT if active[1] else PASSIVE])
        r = batch.step(modes, np.array([1.5, 1.5]), active=active)
        state = np.stack([batch.phi, batch.w, batch.psi, batch.omega, batch.i]).astype(float)
        for e in (0, 1):
            if active[e]:
                mine[e].append(np.concatenate([state[:, e], [batch.t[e], r.phi[e], r.psi[e], r.u[e], r.i[e]]]))
        if not active[1]:
            assert np.array_equal(state[:, 1], frozen)
    n = len(mine[1])
    assert n == 300 and np.array_equal(np.array(mine[1]), np.array(mine[0][:n]))
