"""The typed known rig: one dataclass built from a record, a preset or a lab file."""

import json
import math

import pytest

from addedinertia_env.records.record import read_record, write_record
from addedinertia_env.rig.known import KnownRig, KnownRigError
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.apps.simulate import simulate_run
from hw_adapter.lab import known_rig, load_lab
from hw_adapter.messages import Caps

SPEC_KEYS = ["J_hull", "J_flywheel", "c_torsion", "phi_neutral", "k_t", "R", "L", "i_max", "u_max",
             "motor_friction", "encoder_counts", "sample_rate"]


def test_from_params_writes_the_spec_block_and_reads_back_the_same():
    params = RigParams()
    known = params.known()
    block = known.to_block()
    assert list(block) == SPEC_KEYS
    assert block["c_torsion"] == params.spring.c and block["motor_friction"]["coulomb"] == params.motor.friction_coulomb
    assert KnownRig.from_block(json.loads(json.dumps(block))) == known
    assert "lambda66" not in json.dumps(block)


def test_a_record_block_with_extra_keys_keeps_them_and_optional_keys_may_be_absent():
    block = {"J_hull": 5.8, "J_flywheel": 0.1, "c_torsion": 43.4, "phi_neutral": 0.0, "k_t": 0.25, "R": 0.5,
             "sample_rate": 500, "rod_serial": "R-17"}
    known = KnownRig.from_block(block)
    assert known.L is None and known.i_max is None and known.current_limit == math.inf
    assert known.friction_viscous == 0.0 and known.phi_counts == 0 and known.dt == pytest.approx(0.002)
    assert known.to_block()["rod_serial"] == "R-17" and "L" not in known.to_block()
    with pytest.raises(KnownRigError, match="needs rig.L"):
        known.require_L("the electric work")
    assert KnownRig.from_block({**block, "L": 0}).require_L("x") == 0.0  # 0: inductance neglected


def test_bad_constants_are_refused_by_name():
    with pytest.raises(KnownRigError, match="c_torsion"):
        KnownRig(J_hull=5.8, J_flywheel=0.1, c_torsion=-1.0, k_t=0.25, R=0.5, sample_rate=1000.0)


def test_preset_and_lab_give_the_same_known_rig():
    params = rig_from_mapping(load_preset("wigley-2m"))
    lab = load_lab("wigley-2m")  # a preset standing in for a lab file: its known constants
    caps = Caps(firmware_version=1, flags=0, sample_period_us=1000, phi_counts=params.sensors.phi_counts,
                psi_counts=params.sensors.psi_counts, i_max=params.motor.i_max, u_max=params.motor.u_max,
                watchdog_ms=100, brake_response_ms=5, board_id="test")
    from_lab = known_rig(lab, caps)
    assert from_lab == params.known()  # ``extra`` (board, lab names) is not compared
    assert from_lab.to_block()["lab"] == lab.name


def test_a_record_reads_as_the_known_rig_it_was_written_from(tmp_path):
    params = RigParams()
    rec = simulate_run(params, "pd", seed=3)
    path = write_record(rec, tmp_path / "run.csv")
    assert read_record(path).known == params.known()
