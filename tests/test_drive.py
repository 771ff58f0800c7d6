"""The drive's flaws (sim/drive.py): every engine runs them alike, each changes the run as its
physics says, a YAML drive block is checked with its units, and a gearbox shows in the record."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import both_engines

from addedinertia_env.foundation.config_io import ConfigError
from addedinertia_env.sim import forces
from addedinertia_env.sim.batched import BatchedRig
from addedinertia_env.sim.drive import DriveParams, backlash_step
from addedinertia_env.rig.known import KnownRig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import MotorParams, RigParams
from addedinertia_env.sim.presets import load_preset, rig_from_mapping

FLAWS = {
    "gearbox": DriveParams(gear_ratio=5.0),
    "gear_friction": DriveParams(gear_ratio=5.0, gear_efficiency=0.85, gear_drag=0.02),
    "cogging": DriveParams(cogging_torque=0.02, cogging_periods=12.0, cogging_phase=0.3),
    "driver": DriveParams(driver_time_constant=0.004),
    # 1 deg at the flywheel, a 45 mm motor's rotor (180 g cm^2) through 5:1
    "backlash": DriveParams(gear_ratio=5.0, backlash=math.radians(1.0), rotor_inertia=1.8e-5),
}


def _geared(drive: DriveParams) -> RigParams:
    """The default rig with ``drive``; a geared motor's own k_t scaled so the flywheel sees 0.25 N m/A."""
    p = RigParams()
    return p.replace(motor=MotorParams(k_t=0.25 / drive.gear_ratio), drive=drive)


def _command(k: int) -> MotorCommand:
    return MotorCommand("current", 2.0 * math.sin(0.02 * k) + (1.0 if k % 200 < 100 else -1.0))


def _both_engines(params: RigParams, n: int = 600) -> tuple[np.ndarray, np.ndarray]:
    return both_engines(params, lambda k: _command(k) if k < 500 else MotorCommand("passive"), n, omega0=3.0)


@pytest.mark.parametrize("name", sorted(FLAWS))
def test_every_drive_flaw_runs_alike_in_both_engines_and_changes_the_run(name):
    rig = _geared(FLAWS[name])
    a, b = _both_engines(rig)
    assert np.abs(a - b).max() < 1e-8, f"{name}: MuJoCo and batched differ by {np.abs(a - b).max():.2e}"
    a0, _ = _both_engines(_geared(DriveParams(gear_ratio=FLAWS[name].gear_ratio)) if name != "gearbox"
                          else RigParams())
    if name == "gearbox":  # an ideal gearbox with k_t / N at the motor is the direct drive, to rounding
        assert np.abs(a - a0).max() < 1e-9
    else:
        assert np.abs(a - a0).max() > 1e-6, f"{name}: switching it on changes nothing"


def test_a_batch_mixing_drives_equals_each_alone():
    rigs = [_geared(d) for d in FLAWS.values()] + [RigParams()]
    batch = BatchedRig(rigs, seed=[4] * len(rigs))
    singles = [BatchedRig([r], seed=[4]) for r in rigs]
    for rig in [batch, *singles]:
        rig.reset(phi0=-0.08, omega0=3.0, brake=False)
    for k in range(300):
        cmd = _command(k)
        batch.step(np.full(len(rigs), 1), np.full(len(rigs), cmd.value))
        for s in singles:
            s.step([1], [cmd.value])
    for j, s in enumerate(singles):
        assert np.allclose([batch.psi[j], batch.omega[j], batch.phi[j]], [s.psi[0], s.omega[0], s.phi[0]],
                           rtol=0, atol=1e-12)


def test_cogging_is_conservative_and_mesh_friction_dissipates():
    """Passive flywheel spinning down: with cogging alone the energy the flywheel loses beyond the
    rotor friction is the cogging potential's change; mesh drag takes more."""
    def spin(drive):
        p = RigParams().replace(drive=drive)
        rig = MujocoRig(p, seed=1)
        rig.reset(omega0=20.0, brake=True)
        for _ in range(400):
            rig.step(MotorCommand("passive"))
        s = rig.true_state()
        return s, p
    s0, p0 = spin(DriveParams())
    s1, p1 = spin(DriveParams(cogging_torque=0.05, cogging_periods=8.0))
    e = lambda s, p: 0.5 * p.motor.J_flywheel * s.omega**2  # braked hull: w = 0
    # energy balance of the braked flywheel: T + U_cog - work of the rotor friction stays what it was
    pot = float(forces.cogging_energy(s1.psi, p1) - forces.cogging_energy(0.0, p1))
    rot_fric = s1.dissipated_flywheel + pot  # dissipated_flywheel holds the rotor friction + cogging work
    assert abs(e(s1, p1) + pot - (0.5 * 0.1 * 400.0 + rot_fric)) < 2e-4 * 20.0
    s2, _ = spin(DriveParams(gear_drag=0.05))
    assert e(s2, p0) < e(s0, p0) - 0.5 * 0.05 * 18.0 * 0.4  # the drag's work over ~0.4 s at ~18 rad/s


def test_the_rotor_crosses_the_gap_as_a_held_torque_says_and_loses_its_work_in_the_impact():
    """From one flank at rest, a held torque T takes the rotor (J at the flywheel) across a gap b in
    sqrt(2 b J / T), transmits nothing on the way, and the impact takes all its work T b; the
    flywheel gets the rotor's momentum sqrt(2 J T b). Pressing into a flank transmits all."""
    b, J, T, h = math.radians(1.0), 4.5e-4, -0.5, 1e-3
    t_cross = math.sqrt(2 * b * J / abs(T))
    g, v, t, loss, impulse, engaged_time = b / 2, 0.0, 0.0, 0.0, 0.0, 0.0
    while t < 3 * t_cross:
        g, v, engaged, imp, lost = backlash_step(g, v, T, J, b, h)
        loss += lost
        impulse += imp
        engaged_time += engaged * h
        t += h
    assert g == -b / 2 and v == 0.0
    assert loss == pytest.approx(abs(T) * b, rel=1e-9)
    assert impulse == pytest.approx(-math.sqrt(2 * J * abs(T) * b), rel=1e-9)
    assert engaged_time == pytest.approx(t - t_cross, rel=1e-9)
    assert backlash_step(-b / 2, 0.0, -0.3, J, b, h)[2:] == (1.0, 0.0, 0.0)  # pressing: all through
    assert backlash_step(-b / 2, 0.0, 0.0, J, b, h)[2:] == (1.0, 0.0, 0.0)  # no torque: at rest on the flank
    # arrays and an environment without a gap (width 0: the engaged drive)
    g, v, e, _, _ = backlash_step(np.array([0.0, 0.0]), np.zeros(2), np.array([0.2, 0.2]), J, np.array([b, 0.0]), h)
    assert e[1] == 1.0 and e[0] == 0.0 and g[0] > 0


@pytest.mark.parametrize("substeps", [2, 4])
def test_backlash_impacts_close_the_energy_balance(substeps):
    """A +-2 A square wave through a 1 deg gap, braked hull: what the supply gives equals the
    ohmic and magnetic losses, the flywheel's kinetic energy, its friction and the impact losses
    (the work the current times the flywheel's angle does not show). Left out, the impacts are
    the balance's whole gap; the residual is the held current's O(h), halving with the step."""
    drive = FLAWS["backlash"]
    p = _geared(drive).replace(physics_substeps=substeps)
    rig = MujocoRig(p, seed=1)
    rig.reset(omega0=2.0, brake=True)
    for k in range(2000):
        rig.step(MotorCommand("current", 2.0 if (k // 50) % 2 == 0 else -2.0))
    s = rig.true_state()
    m = p.motor
    kinetic = 0.5 * m.J_flywheel * (s.omega**2 - 2.0**2) + 0.5 * drive.reflected_rotor_inertia * s.gap_rate**2
    supplied = s.electric_energy - s.ohmic_loss - 0.5 * m.L * s.i**2
    without_impacts = supplied - kinetic + s.dissipated_flywheel
    assert s.impact_loss > 0.1  # 40 crossings of 1.6-8.7 mJ (the driver's current sags while the rotor runs free)
    assert s.impact_loss > 20 * abs(s.motor_work - (supplied - s.backlash_work))  # the electric side closes
    residual = without_impacts - s.impact_loss
    assert abs(residual) < 0.06 * s.impact_loss / (substeps / 2), (residual, s.impact_loss)
    # the method's bookkeeping, the current times the flywheel's angle, misses the impacts
    assert abs(s.motor_work - (kinetic - s.dissipated_flywheel)) < 0.1 * s.impact_loss


def test_driver_bandwidth_is_a_first_order_lag():
    """A current step through a driver with tau = 5 ms reaches 1 - 1/e of the step after about tau."""
    p = RigParams().replace(drive=DriveParams(driver_time_constant=0.005))
    rig = MujocoRig(p, seed=1)
    rig.reset(brake=True)
    i = []
    for _ in range(20):
        rig.step(MotorCommand("current", 4.0))
        i.append(rig.true_state().i)
    assert abs(i[4] / 4.0 - (1 - math.exp(-1.0))) < 0.01  # after 5 samples of 1 ms
    assert i[-1] < 4.0


def _with_drive(block, u_max: bool = False):
    data = load_preset("wigley-2m")
    data["drive"] = block
    if not u_max:
        data["motor"].pop("u_max")
    return rig_from_mapping(data)


def test_a_drive_block_states_units_and_is_refused_by_name():
    rig = _with_drive({"gear_ratio": "4 -", "gear_efficiency": "90 %", "gear_drag": "20 mN m",
                       "cogging_torque": "15 mN m", "cogging_periods": "24 /turn", "driver_bandwidth": "1 kHz",
                       "supply": "24 V"})
    assert rig.drive.gear_ratio == 4.0 and rig.drive.gear_efficiency == 0.9 and rig.motor.u_max == 24.0
    assert abs(rig.drive.driver_time_constant - 1 / (2 * math.pi * 1000)) < 1e-12
    for block, words in [({"gear_ratio": 4}, "drive.gear_ratio = 4: missing unit"),
                         ({"gear_drag": "0.02"}, "drive.gear_drag"),
                         ({"gear_drag": "0.02 furlong"}, "unit one of"),
                         ({"gear_drag": "-0.02 N m"}, "gear_drag = -0.02: expected >= 0"),
                         ({"gear_efficiency": "120 %"}, "gear_efficiency"),
                         ({"backlash_typo": "1 deg"}, "unknown key(s) ['backlash_typo']"),
                         ({"backlash": "-0.5 deg", "rotor_inertia": "180 g cm^2"},
                          "DriveParams.backlash = -0.008726646259971648: expected >= 0"),
                         ({"backlash": "1 deg"}, "DriveParams.rotor_inertia = 0.0: expected > 0"),
                         ({"backlash": "0.5"}, "drive.backlash = '0.5': expected '<number> <unit>'"),
                         ({"supply": "5 V"}, "drive.supply = '5 V': expected more than R i_max = 7.5 V")]:
        with pytest.raises(ConfigError, match=None) as err:
            _with_drive(block)
        assert words in str(err.value), str(err.value)
    with pytest.raises(ConfigError, match="both motor.u_max and drive.supply"):
        _with_drive({"supply": "24 V"}, u_max=True)


def test_a_gearbox_shows_as_rig_gear_ratio_and_reads_back():
    rig = _geared(DriveParams(gear_ratio=5.0))
    known = rig.known()
    block = known.to_block()
    assert block["gear_ratio"] == 5.0 and block["k_t"] == 0.05
    back = KnownRig.from_block(block)
    assert back.k_t == pytest.approx(0.25) and back.gear_ratio == 5.0 and back.to_block() == block
    assert "gear_ratio" not in RigParams().known().to_block()
    assert MujocoRig(rig, seed=0).truth()["drive"] == {"gear_ratio": 5.0}


def test_a_suite_draws_its_drive_with_units_and_keeps_the_flywheel_k_t(tmp_path):
    from addedinertia_env.bench.suites import load_suite
    from addedinertia_env.experiment.scenarios import make_scenario

    suite = load_suite("drive-v0")
    for seed in suite.seeds("test")[:4]:
        sc = suite.scenario(seed)
        d = sc.rig.drive
        assert 3.0 <= d.gear_ratio <= 8.0 and 0.81 <= d.gear_efficiency <= 0.90 and 24.0 <= sc.rig.motor.u_max <= 48.0
        base = make_scenario(seed, preset=suite.preset_for(seed), ranges=suite.ranges, fixed=suite.fixed)
        assert sc.rig.known().k_t == pytest.approx(base.rig.motor.k_t, rel=1e-12)  # the flywheel sees the drawn k_t
        assert sc.rig.hull == base.rig.hull and sc.plan == base.plan  # the drive draws from its own stream
    text = (suite_dir := tmp_path / "s.yaml")
    for block, words in [("{gear_drag: [0.005, 0.02]}", "missing unit"),
                         ("{gear_efficiency: ['80 %', '110 %']}", "gear_efficiency"),
                         ("{slack: ['1 deg', '2 deg']}", "unknown key 'slack'"),
                         ("{backlash: ['-1 deg', '2 deg'], rotor_inertia: '100 g cm^2'}", "DriveParams.backlash = -0.017453292519943295: expected >= 0"),
                         ("{supply: ['5 V', '6 V']}", "expected more than R i_max = 7.5 V")]:
        text.write_text(f"name: t\nsplits: {{test: {{first_seed: 1, count: 2}}}}\ndrive: {block}\n")
        with pytest.raises(ConfigError) as err:
            load_suite(str(suite_dir))
        assert words in str(err.value) and str(suite_dir) in str(err.value), str(err.value)


def test_a_geared_preset_runs_its_drive_and_its_lab_states_the_ratio():
    from hw_adapter.lab import known_rig, lab_from_mapping, load_lab
    from hw_adapter.messages import Caps

    rig = rig_from_mapping(load_preset("wigley-2m-geared"))
    assert rig.drive.gear_ratio == 5.0 and rig.drive.gear_efficiency == 0.85 and rig.motor.u_max == 24.0
    assert rig.known().k_t == pytest.approx(0.25)
    lab = load_lab("wigley-2m-geared")  # the emulator's stand-in lab: the motor's own k_t and the ratio
    assert lab.constants["k_t"] == 0.05 and lab.constants["gear_ratio"] == 5.0
    caps = Caps(firmware_version=1, flags=0, sample_period_us=1000, phi_counts=131072, psi_counts=16384,
                i_max=15.0, u_max=24.0, watchdog_ms=50, brake_response_ms=5)
    known = known_rig(lab, caps)
    assert known.k_t == pytest.approx(0.25) and known.to_block()["gear_ratio"] == 5.0
    with pytest.raises(ConfigError, match="gear_ratio = 0.5"):
        lab_from_mapping({**{k: 1.0 for k in ("J_hull", "J_flywheel", "c_torsion", "k_t", "R", "L")},
                          "phi_neutral": 0.0, "gear_ratio": 0.5}, "lab.yaml")


def test_drive_v1_draws_backlash_and_cogging_within_its_stated_ranges():
    """drive-v1 (configs/suites/drive-v1.yaml): every tuning scenario's drive within the suite's ranges,
    the backlash with a rotor to cross it, the gear ratio known in the record."""
    from addedinertia_env.bench.suites import load_suite

    suite = load_suite("drive-v1")
    for sc in suite.scenarios("tuning")[:4]:
        d = sc.rig.drive
        assert 3.0 <= d.gear_ratio <= 8.0 and 0.88 <= d.gear_efficiency <= 0.96
        assert math.radians(0.5) <= d.backlash <= math.radians(1.5) and 1e-5 <= d.rotor_inertia <= 2e-5
        assert 3e-3 <= d.cogging_torque <= 10e-3 and d.cogging_periods == 24.0
        assert sc.rig.known().to_block()["gear_ratio"] == pytest.approx(d.gear_ratio)


def test_a_rig_config_with_backlash_runs_it_as_the_emulator_would():
    """A rig config's drive block (what `bench-server --rig` loads) carries the backlash into the MuJoCo
    rig the emulator serves: current reversals lose energy in impacts; the same rig without it loses none."""
    losses = []
    for extra in ({"backlash": "1 deg", "rotor_inertia": "150 g cm^2"}, {}):
        rig_params = _with_drive({"gear_ratio": "5 -", **extra})
        rig = MujocoRig(rig_params, seed=2)
        rig.reset(brake=True)
        for k in range(300):
            rig.step(MotorCommand("current", 1.0 if (k // 50) % 2 == 0 else -1.0))
        losses.append(rig.true_state().impact_loss)
    assert losses[0] > 5 * 0.25 * math.radians(1.0) * 0.1 and losses[1] == 0.0, losses
