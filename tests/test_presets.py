"""Rig presets (configs/rigs/*.yaml), their strict validation, and Lamb's spheroid numbers."""

from __future__ import annotations

from pathlib import Path

import copy
import math

import pytest
import yaml
from scipy.integrate import quad

from addedinertia_env.experiment.protocol import ExperimentPlan, plan_from_preset
from addedinertia_env.hydro import closed_forms as hydro
from addedinertia_env.sim.params import RigParams, SensorParams
from addedinertia_env.sim.presets import (
    SENSOR_QUALITY,
    ConfigError,
    available_rigs,
    load_preset,
    load_rig,
    rig_from_mapping,
    sensors_for_quality,
)

# Every preset shipped in configs/rigs/ (found, not listed: a new preset is tested too).
PRESETS = tuple(sorted(p.stem for p in (Path(__file__).resolve().parents[1] / "configs" / "rigs").glob("*.yaml")))


def mapping(name: str = "wigley-2m") -> dict:
    """A private deep copy of a preset's raw mapping, free to spoil."""
    return copy.deepcopy(load_preset(name))


# --- Lamb's prolate spheroid (physics.md section 6) ------------------------------------

def lamb_integrals(a: float, b: float) -> tuple[float, float]:
    """Lamb's alpha0, beta0 from their defining integrals (Hydrodynamics, art. 114), by quadrature."""
    alpha0 = a * b * b * quad(lambda s: 1.0 / ((a * a + s) ** 1.5 * (b * b + s)), 0.0, math.inf, epsabs=0,
                              epsrel=1e-12, limit=200)[0]
    beta0 = a * b * b * quad(lambda s: 1.0 / ((a * a + s) ** 0.5 * (b * b + s) ** 2), 0.0, math.inf, epsabs=0,
                             epsrel=1e-12, limit=200)[0]
    return alpha0, beta0


def rotation_coefficient(a: float, b: float) -> float:
    """k' = e^4 (beta0 - alpha0) / ((2 - e^2) [2 e^2 - (2 - e^2)(beta0 - alpha0)]), from the integrals."""
    e2 = 1.0 - (b / a) ** 2
    alpha0, beta0 = lamb_integrals(a, b)
    d = beta0 - alpha0
    return e2 * e2 * d / ((2.0 - e2) * (2.0 * e2 - (2.0 - e2) * d))


@pytest.mark.parametrize("ratio", [2.0, 7.0, 10.0])
def test_lamb_closed_forms_match_their_integrals(ratio):
    a, b = 1.0, 1.0 / ratio
    e = math.sqrt(1.0 - (b / a) ** 2)
    # Closed forms vs adaptive quadrature at rtol 1e-12: agreement to 1e-9 leaves no doubt.
    assert hydro.lamb_coefficients(e) == pytest.approx(lamb_integrals(a, b), rel=1e-9)
    assert hydro.lamb_rotation_coefficient(ratio) == pytest.approx(rotation_coefficient(a, b), rel=1e-9)


def test_lamb_rotation_coefficient_for_length_to_beam_7():
    # physics.md section 6 (Lamb): L/B = 7 gives k' = 0.807, to the 3 decimals quoted.
    assert round(hydro.lamb_rotation_coefficient(7.0), 3) == 0.807


def test_spheroid_preset_lambda66_is_lambs_closed_form():
    data = load_preset("spheroid-7")
    ai = data["hull"]["added_inertia"]
    a, b = 0.5 * ai["length"], 0.5 * ai["beam"]
    half_mass = 0.5 * 4.0 / 3.0 * math.pi * hydro.RHO_WATER * a * b * b  # floating: half the double body
    expected = rotation_coefficient(a, b) * half_mass * (a * a + b * b) / 5.0
    rig = load_rig("spheroid-7")
    assert rig.hull.lambda66 == pytest.approx(expected, rel=1e-9)
    J = data["hull"]["J_hull"]
    assert rig.hull.J_hull == pytest.approx(half_mass * (a * a + b * b) / 5.0 + J["extra"], rel=1e-12)


# --- loading ---------------------------------------------------------------------------

def test_the_shipped_presets_are_found():
    assert {"wigley-2m", "spheroid-7"} <= set(PRESETS) and set(PRESETS) == set(available_rigs())


@pytest.mark.parametrize("name", PRESETS)
def test_presets_load(name):
    assert name in available_rigs()
    rig = load_rig(name)
    assert isinstance(rig, RigParams) and rig.hull.name == name
    assert rig.hull.J_hull > 0 and rig.hull.lambda66 > 0 and rig.spring.c > 0
    # physics.md section 7: the rod is chosen for a 3 to 6 s period.
    assert 3.0 < rig.natural_period < 6.0
    plan = plan_from_preset(load_preset(name))
    assert isinstance(plan, ExperimentPlan) and 0 < abs(plan.alpha) < 1


def test_wigley_preset_numbers_follow_physics_md():
    rig = load_rig("wigley-2m")
    assert rig.hull.lambda66 == 11.7  # panel-method A66(0), physics.md section 6
    # b2 = rho Cd T L^4 / 64 with Cd = 2, T = 0.125 m, L = 2 m: 31 Cd = 62.5 N m s^2.
    assert rig.hull.b2 == pytest.approx(1000.0 * 2.0 * 0.125 * 2.0**4 / 64.0, rel=1e-12)


def test_a_preset_can_be_loaded_from_a_yaml_path(tmp_path):
    data = mapping()
    data.pop("_path")
    data["spring"]["c"] = 50.0
    path = tmp_path / "stiff.yaml"
    path.write_text(yaml.safe_dump(data))
    assert load_rig(str(path)).spring.c == 50.0


def test_unknown_preset_name_lists_the_known_ones():
    with pytest.raises(ConfigError, match=r"unknown rig 'nosuch'.*wigley-2m"):
        load_rig("nosuch")


# --- unknown keys refused by name, at each level ----------------------------------------

def _spoil(data: dict, path: tuple[str, ...], key: str = "colour", value=1.0) -> dict:
    node = data
    for part in path:
        node = node[part]
    node[key] = value
    return data


@pytest.mark.parametrize("path, where", [
    ((), "allowed keys"),
    (("hull",), "hull"),
    (("hull", "added_inertia"), "hull.added_inertia"),
    (("hull", "damping"), "hull.damping"),
    (("spring",), "spring"),
    (("motor",), "motor"),
    (("sensors",), "sensors"),
    (("experiment",), "experiment"),
])
def test_unknown_keys_are_refused_by_name(path, where, tmp_path):
    data = _spoil(mapping(), path)
    with pytest.raises(ConfigError) as info:
        rig_from_mapping(data)
        plan_from_preset(data)
    message = str(info.value)
    assert "colour" in message and where in message and "allowed keys" in message
    assert data["_path"] in message  # the file is named


def test_unknown_key_in_a_computed_J_hull_is_refused():
    data = _spoil(mapping("spheroid-7"), ("hull", "J_hull"))
    with pytest.raises(ConfigError, match=r"hull\.J_hull.*'colour'"):
        rig_from_mapping(data)


def test_unknown_top_level_key_is_refused_when_the_file_is_read(tmp_path):
    data = mapping()
    data.pop("_path")
    data["colour"] = "red"
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=rf"{path}.*unknown key\(s\) \['colour'\]"):
        load_preset(str(path))


def test_unknown_effect_is_refused_by_name():
    data = mapping()
    data["effects"] = {"gremlins": {"size": 1.0}}
    with pytest.raises(ConfigError, match=r"effects.*unknown effect 'gremlins'.*bearing_coulomb"):
        rig_from_mapping(data)
    data["effects"] = {"bearing_coulomb": {"torque": 0.05, "colour": 1.0}}
    with pytest.raises(ConfigError, match=r"effects\.bearing_coulomb: expected keys \['torque'\]"):
        rig_from_mapping(data)
    data["effects"] = {"bearing_coulomb": {"torque": 0.05}}
    assert rig_from_mapping(data).effects.bearing_coulomb.torque == 0.05


# --- bad values refused with the key named ----------------------------------------------

@pytest.mark.parametrize("path, key, value", [
    (("spring",), "c", -43.4),
    (("spring",), "c", "stiff"),
    (("spring",), "c", float("nan")),
    (("motor",), "k_t", 0.0),
    (("motor",), "R", -0.5),
    (("motor",), "J_flywheel", "heavy"),
    (("motor",), "friction_coulomb", -0.002),
    (("motor",), "i_max", float("inf")),
    (("hull",), "J_hull", -5.8),
    (("hull",), "b1", -0.2),
    (("hull",), "b1", True),
    (("sensors",), "sample_rate", 0.0),
    (("sensors",), "current_noise", -0.01),
    (("hull", "added_inertia"), "value", -11.7),
    (("hull", "added_inertia"), "value", "big"),
    (("hull", "damping"), "draft", -0.125),
    (("hull", "damping"), "drag_coefficient", "high"),
    ((), "brake_torque", -60.0),
    ((), "physics_substeps", 1.5),
    ((), "physics_substeps", 0),
])
def test_bad_values_are_refused_with_the_key_named(path, key, value):
    data = _spoil(mapping(), path, key, value)
    with pytest.raises(ConfigError) as info:
        rig_from_mapping(data)
    message = str(info.value)
    assert key in message and "expected" in message and data["_path"] in message


@pytest.mark.parametrize("key, value", [("length", -2.0), ("beam", "wide"), ("extra", -1.0), ("extra", "lots")])
def test_bad_spheroid_geometry_is_refused_with_the_key_named(key, value):
    data = mapping("spheroid-7")
    data["hull"]["J_hull"][key] = value
    with pytest.raises(ConfigError, match=rf"hull\.J_hull\.{key} = .*expected"):
        rig_from_mapping(data)


def test_bad_lamb_immersion_is_refused():
    data = mapping("spheroid-7")
    data["hull"]["added_inertia"]["immersion"] = "quarter"
    with pytest.raises(ConfigError, match=r"added_inertia\.immersion = 'quarter': expected 'half' or 'full'"):
        rig_from_mapping(data)


@pytest.mark.parametrize("section", ["hull", "spring", "motor", "sensors"])
def test_a_section_that_is_not_a_mapping_is_refused(section):
    data = mapping()
    data[section] = [1, 2, 3]
    with pytest.raises(ConfigError, match=rf"{section}.*expected a mapping"):
        rig_from_mapping(data)


def test_conflicting_keys_are_refused():
    data = mapping()
    data["hull"]["lambda66"] = 11.7
    with pytest.raises(ConfigError, match="either 'lambda66' or 'added_inertia'"):
        rig_from_mapping(data)
    data = mapping()
    data["hull"]["b2"] = 60.0
    with pytest.raises(ConfigError, match="either 'b2' or 'damping'"):
        rig_from_mapping(data)


# --- experiment plan and sensor sets ----------------------------------------------------

def test_plan_from_preset_applies_overrides_and_ignores_none():
    data = mapping()
    plan = plan_from_preset(data, hold_s=5.0, alpha=None)
    assert plan.hold_s == 5.0 and plan.alpha == data["experiment"]["alpha"]


@pytest.mark.parametrize("key, value", [("alpha", 0.0), ("alpha", 1.5), ("alpha", "wide"), ("hold_s", -1.0),
                                        ("hold_s", float("inf")), ("tail_s", -0.1)])
def test_plan_from_preset_refuses_bad_values_with_the_key_named(key, value):
    data = mapping()
    data["experiment"][key] = value
    with pytest.raises(ConfigError, match=rf"experiment.*{key}"):
        plan_from_preset(data)
    with pytest.raises(ConfigError, match=rf"experiment.*{key}"):
        plan_from_preset(mapping(), **{key: value})


def test_sensors_for_quality():
    realistic = SensorParams()
    sets = {q: sensors_for_quality(q) for q in SENSOR_QUALITY}
    assert sets["realistic"] == realistic  # physics.md section 7 as it stands
    assert sets["ideal"] == SensorParams.ideal(realistic.sample_rate)
    assert sets["ideal"].current_noise == 0 and sets["ideal"].phi_counts == 0
    noise = [sets[q].current_noise for q in ("ideal", "good", "realistic", "poor")]
    assert noise == sorted(noise) and len(set(noise)) == 4  # strictly worse down the list
    resolution = [sets[q].phi_counts for q in ("good", "realistic", "poor")]
    assert resolution == sorted(resolution, reverse=True)
    # A base set keeps its sampling rate through every quality.
    base = SensorParams(sample_rate=500.0)
    assert all(sensors_for_quality(q, base).sample_rate == 500.0 for q in SENSOR_QUALITY)
    with pytest.raises(ConfigError, match=r"sensor quality 'perfect'.*ideal, good, realistic, poor"):
        sensors_for_quality("perfect")
