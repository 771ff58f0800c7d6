"""Drive effects judged on the flywheel's own balance (discover/radiation_memory.flywheel_effects).

Where water that remembers swamps the gray-box model's hull residuals, a wrong torque constant
still shows in ``J_f theta'' = s k_t i - M_f``, which no water enters (PHYSICS.md section 8).
The check must name it when the simulated motor's torque constant is off its data sheet, and
name nothing on the same run with the data sheet right (realistic sensors: a 0.5 % current gain
error, under the effect's smallest size)."""

from __future__ import annotations

from conftest import REALISTIC_SEED, preset_rig

from addedinertia_env.apps.simulate import simulate_run
from addedinertia_env.discover.radiation_memory import flywheel_effects
from addedinertia_env.sim.effects import Effects


def _run(effects: Effects | None):
    params, plan = preset_rig("wigley-2m")
    if effects is not None:
        params = params.replace(effects=effects)
    return simulate_run(params, "feedforward-pd", plan, seed=REALISTIC_SEED, run_id="flywheel")


def test_a_torque_constant_off_its_data_sheet_is_named_on_the_flywheel_alone():
    words, balance = flywheel_effects([_run(Effects.from_dict({"torque_constant": {"ratio": 1.05}}, "test"))])
    assert words == ["torque_constant"], balance
    assert abs(balance["torque_scales"][0] - 1.05) < 0.01, balance


def test_a_right_data_sheet_names_nothing():
    words, balance = flywheel_effects([_run(None)])
    assert words == [], balance
    assert abs(balance["torque_scales"][0] - 1.0) < 0.01, balance
