"""The energy method's rotor Coulomb smoothing rate is its own and sits where the physics puts it
(identify/rotor_friction.py, docs/RELIABILITY.md section 2b): far below any rate a record's
motor encoder resolves, far above the rounding noise of a resting flywheel's rate."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.identify.energy_work import WORK_SMOOTHING_S
from addedinertia_env.identify.rotor_friction import ROTOR_COULOMB_RATE_SCALE
from addedinertia_env.sim.presets import SENSOR_QUALITY, available_rigs, load_rig, sensors_for_quality

IDENTIFY = Path(__file__).resolve().parents[1] / "addedinertia_env" / "identify"


@pytest.mark.parametrize("preset", available_rigs())
@pytest.mark.parametrize("quality", SENSOR_QUALITY)
def test_any_resolved_rate_gets_the_full_coulomb_torque(preset, quality):
    sensors = sensors_for_quality(quality, load_rig(preset).sensors)
    if not sensors.psi_counts:
        pytest.skip(f"{quality} sensors: the motor encoder is not quantised")
    # the smallest rate the smoothed angle shows: one count over the work-smoothing window
    resolved = 2 * math.pi / sensors.psi_counts / WORK_SMOOTHING_S
    assert np.tanh(resolved / ROTOR_COULOMB_RATE_SCALE) > 0.999, (preset, quality, resolved)


def test_rounding_noise_of_a_resting_flywheel_stays_linear():
    # a flywheel at rest far from zero angle (100 rad) logged at the spec's fastest rate (10 kHz): the rate
    # of its smoothed angle is a few ulps of the angle per sample interval at most
    noise = 16 * np.finfo(float).eps * 100.0 * 1e4
    assert np.tanh(noise / ROTOR_COULOMB_RATE_SCALE) < 1e-4


def test_the_estimator_does_not_take_its_friction_law_from_the_simulator():
    for path in IDENTIFY.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                assert not node.module.startswith("addedinertia_env.sim"), (path.name, node.module)
            if isinstance(node, ast.Import):
                assert not any(a.name.startswith("addedinertia_env.sim") for a in node.names), path.name
