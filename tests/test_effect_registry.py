"""The effect registry: every registered effect runs in every engine and is a discovery
candidate, and a new effect (a toy one, registered here) flows end to end from its one file."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import both_engines

from addedinertia_env.apps.discovery_dataset import DatasetSpec
from addedinertia_env.discover.diagnose import Thresholds, discover
from addedinertia_env.discover.model import GrayBoxModel, candidates
from addedinertia_env.discover.prepare import prepare
from addedinertia_env.sim import effects as E
from addedinertia_env.sim.effects import registry
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.experiment.protocol import plan_from_preset
from addedinertia_env.apps.simulate import simulate_run

BUILT_IN = E.EFFECT_NAMES


# --- a toy effect, written as an effect file would be ---------------------------------
@dataclass(frozen=True)
class CubicDamping:
    d3: float  # N m s^3/rad^3, torque = -d3 w^3


def _cubic_torque(e, d, w, p):
    return -e.d3 * w**3


TOY = registry.EffectSpec(
    name="toy_cubic_damping", summary="cubic damping of the hull rate (a test's toy effect)",
    params_type=CubicDamping,
    params=(registry.Param("d3", "N m s^3/rad^3", "cubic damping coefficient", realistic=(150.0, 250.0),
                           neutral=0.0, fit=registry.FitRange(0.0, -1e4, 1e4, 10.0)),),
    size_param="d3", min_size=5.0, hull_torque=_cubic_torque)


@pytest.fixture
def toy():
    registry.register(TOY)
    yield TOY.name
    registry.unregister(TOY.name)


# --- helpers --------------------------------------------------------------------------
def _drive(k: int) -> MotorCommand:
    """A current that changes (so a channel lag and a torque-constant error show)."""
    return MotorCommand("current", 2.0 * math.sin(0.02 * k) + (1.0 if k % 200 < 100 else -1.0))


def _both_engines(params: RigParams, n: int = 600) -> tuple[np.ndarray, np.ndarray]:
    """(MuJoCo, batched) histories of [phi, w, psi, omega, i, read u, read i], same seed and inputs."""
    return both_engines(params, _drive, n)


def _drawn(name: str, seed: int = 5) -> E.Effects:
    return E.draw_effect(name, np.random.default_rng(seed))


@pytest.fixture(scope="module")
def nominal_data():
    """One short simulated run, prepared for discovery (no effect)."""
    data = load_preset("wigley-2m")
    rec = simulate_run(rig_from_mapping(data), "feedforward-pd", plan_from_preset(data, alpha=0.1, hold_s=0.5),
                       seed=2)
    return prepare([rec.without_truth()])


# --- every registered effect ----------------------------------------------------------
def test_registry_holds_the_vocabulary_in_order():
    assert registry.effect_names()[: len(BUILT_IN)] == BUILT_IN
    assert BUILT_IN == ("bearing_coulomb", "fluid_memory", "spring_stiffening", "neutral_offset", "sensor_delay",
                        "torque_constant")


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_effect_runs_alike_in_both_engines_and_changes_the_run(name):
    plain = RigParams()
    with_effect = plain.replace(effects=_drawn(name))
    a, b = _both_engines(with_effect)
    assert np.abs(a - b).max() < 1e-8, f"{name}: MuJoCo and batched differ by {np.abs(a - b).max():.2e}"
    a0, _ = _both_engines(plain)
    assert np.abs(a - a0).max() > 1e-6, f"{name}: switching it on changes nothing in the MuJoCo rig"  # >> rounding


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_effect_is_a_discovery_candidate_with_a_size(name, nominal_data):
    spec = registry.get(name)
    assert name in candidates() and spec.size_param in Thresholds().min_size
    nominal = GrayBoxModel(nominal_data)
    extended = GrayBoxModel(nominal_data, name)
    theta0 = np.array([11.7, 0.2, 31.0])
    at_neutral = np.r_[theta0, [spec.param(n).neutral for n in spec.param_names]]
    np.testing.assert_allclose(extended.residuals(at_neutral), nominal.residuals(theta0), rtol=0, atol=1e-12)
    drawn = _drawn(name).to_dict()[name]
    moved = extended.residuals(np.r_[theta0, [drawn[n] for n in spec.param_names]])
    assert np.abs(moved - nominal.residuals(theta0)).max() > 0.1, f"{name}: its parameters do not enter the model"


# --- a new effect flows end to end ----------------------------------------------------
def test_a_toy_effect_flows_from_its_file_to_discovery(toy):
    # presets and scenario draws know it
    eff = E.Effects.from_dict({toy: {"d3": 200.0}}, "preset: effects")
    assert eff.active == (toy,) and eff.to_dict() == {toy: {"d3": 200.0}}
    assert 150.0 <= _drawn(toy).to_dict()[toy]["d3"] <= 250.0
    # both engines run it, alike, and it changes the motion
    params = RigParams().replace(effects=eff)
    a, b = _both_engines(params)
    assert np.abs(a - b).max() < 1e-8
    assert np.abs(a - _both_engines(RigParams())[0]).max() > 1e-4
    # the simulator's truth names it, and discovery tries it and names it
    data = load_preset("wigley-2m")
    rig = rig_from_mapping(data, effects=eff)
    spec = DatasetSpec(alphas=(0.06, 0.12), holds=(0.5,))
    records = [simulate_run(rig, spec.controller, plan_from_preset(data, alpha=a, hold_s=h), seed=20 + k)
               for k, (a, h) in enumerate(spec.runs)]
    assert records[0].meta["truth"]["effects"] == {toy: {"d3": 200.0}}
    diag = discover(records, heldout=False)
    assert toy in [c.cause for c in diag.candidates]
    assert diag.cause == toy, [(c.cause, round(c.delta_bic, 1), c.reason) for c in diag.candidates]
    assert diag.best.fit.params["d3"] == pytest.approx(200.0, rel=0.3)


def test_an_incomplete_effect_is_refused_at_registration():
    with pytest.raises(ValueError, match="no physics hook"):
        registry.register(registry.EffectSpec(name="toy_nothing", summary="", params_type=CubicDamping,
                                              params=TOY.params, size_param="d3", min_size=1.0))
    with pytest.raises(ValueError, match="already used"):
        registry.register(registry.EffectSpec(name="toy_clash", summary="", params_type=E.BearingCoulomb,
                                              params=registry.get("bearing_coulomb").params, size_param="torque",
                                              min_size=1.0, hull_torque=_cubic_torque))
    assert "toy_nothing" not in registry.effect_names() and "toy_clash" not in registry.effect_names()
