"""Discovery's word ``supply_limit`` (discover/supply_limit.py, issue 28 Build 2): the driver pinned at its
supply by the back-EMF is named from the record's voltage and flywheel angle; a drive with headroom, and
the shared development sets, name nothing. Records are judged without their ``truth``."""

from __future__ import annotations

import dataclasses

import pytest
from conftest import REALISTIC_SEED, preset_rig

from addedinertia_env.apps.simulate import simulate_run
from addedinertia_env.discover import drive_flaws
from addedinertia_env.discover.supply_limit import judge
from addedinertia_env.records.record import read_record


def _run(u_max: float, J_flywheel: float = 0.03):
    """wigley-2m with a light flywheel (its pre-spin turns it at about 22 rad/s: 5.5 V of back-EMF at
    0.25 N m/A), feedforward-pd, realistic sensors, on a supply of ``u_max`` volts."""
    params, plan = preset_rig("wigley-2m")
    params = params.replace(motor=dataclasses.replace(params.motor, u_max=u_max, J_flywheel=J_flywheel))
    return simulate_run(params, "feedforward-pd", plan, seed=REALISTIC_SEED, run_id="supply").without_truth()


@pytest.fixture(scope="module")
def low_supply():
    # 9 V: above R i_max = 7.5 V (a drive block accepts it), below what the spin-up asks at speed
    return _run(9.0)


def test_a_low_supply_is_named_with_the_back_emf_share(low_supply):
    ev = judge([low_supply])
    assert ev["named"], ev["why"]
    run = ev["runs"][0]
    assert run["saturated_s"] >= 0.02 and run["emf_share"] > 0.3, run
    assert run["shortfall_a"] > 0.5, run  # the current falls short of its command where the voltage is pinned
    assert "supply_limit" in drive_flaws.candidate([low_supply])["named"]


def test_the_same_drive_with_headroom_names_nothing():
    ev = judge([_run(48.0)])
    assert not ev["named"] and ev["saturated_s"] == 0.0, ev


def test_a_record_without_a_stated_supply_is_not_judged(low_supply):
    meta = dict(low_supply.meta, rig={k: v for k, v in low_supply.meta["rig"].items() if k != "u_max"})
    ev = judge([dataclasses.replace(low_supply, meta=meta)])
    assert not ev["named"] and "states no supply" in ev["why"], ev


@pytest.mark.parametrize("archive", ["foreign-lab.tar.xz",
                                     pytest.param("foreign-lab-2.tar.xz", marks=pytest.mark.slow)])
def test_no_development_case_names_a_supply_limit(unpack_shared, archive):
    root = unpack_shared(archive)
    cases = sorted(p for p in root.iterdir() if p.is_dir())
    assert cases
    for case in cases:
        ev = judge([read_record(p) for p in sorted(case.glob("*.csv"))])
        assert not ev["named"], (case.name, ev["why"])
