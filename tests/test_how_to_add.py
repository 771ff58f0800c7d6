"""docs/ARCHITECTURE.md "How to add ...": each recipe done here, with the files it names.

(An effect: tests/test_effect_registry.py registers a toy effect and follows it from its
file through both engines to discovery.)
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
import yaml

from addedinertia_env.experiment.protocol import ExperimentPlan, plan_from_preset
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.identify import METHODS, identify
from addedinertia_env.identify.common import Result
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.presets import RIG_DIR, load_preset, rig_from_mapping
from addedinertia_env.apps.simulate import simulate_run
from agents import make_controller
from agents.base import Controller
from agents.classical import CLASSICAL
from agents.tuned import resolve_params
from hw_adapter import faults

HERE = sys.modules[__name__].__name__


# --- a controller: agents/<name>.py + one line in agents/classical.py CLASSICAL ---------
class ToyP(Controller):
    """Proportional on the tracking error plus the stroke feed-forward-free hold (A)."""

    name = "toy-p"
    DEFAULTS = {"gain": 2000.0}  # A/rad
    KNOBS = {"gain": (100.0, 1e4, "log")}

    def __init__(self, tuned: bool = True, **overrides):
        self.params = resolve_params(self.name if tuned else None, self.DEFAULTS, overrides)

    def current(self, obs: dict[str, float]) -> float:
        return self.params["gain"] * obs["tracking_error"] if obs["is_reverse"] > 0.5 else 0.0


def test_add_a_controller(monkeypatch):
    monkeypatch.setitem(CLASSICAL, "toy-p", f"{HERE}:ToyP")
    controller = make_controller("toy-p", gain=1500.0)
    assert controller.params == {"gain": 1500.0}
    rec = run_experiment(MujocoRig(RigParams(), seed=1), controller, ExperimentPlan(hold_s=0.2))
    rev = rec.phase == "reverse"
    assert rev.any() and np.abs(rec["i_cmd"][rev]).max() > 0.0  # it drove the reverse stroke
    with pytest.raises(TypeError, match="unknown controller parameter"):
        make_controller("toy-p", gian=1.0)


# --- a preset: configs/rigs/<name>.yaml (found by name; tests/test_presets.py picks it up) ---
def test_add_a_preset(tmp_path):
    data = yaml.safe_load((RIG_DIR / "wigley-2m.yaml").read_text())
    data["name"] = "toy-hull"
    data["hull"]["J_hull"] = 6.5  # kg m^2
    path = tmp_path / "toy-hull.yaml"
    path.write_text(yaml.safe_dump(data))
    preset = load_preset(str(path))
    rig = rig_from_mapping(preset)
    assert rig.hull.name == "toy-hull"
    rec = simulate_run(rig, "feedforward-pd", plan_from_preset(preset, hold_s=0.2), seed=2)
    assert rec.known.J_hull == rig.hull.J_hull and identify([rec], "energy").lambda66 > 0


# --- an identification method: identify/<name>.py + one line in identify METHODS -------
def identify_toy(records, **options) -> Result:
    """A stand-in method: lambda66 from the free stroke's inertia prior seen in the record."""
    rec = records[0]
    assert "truth" not in rec.meta  # identify() strips the truth before any method sees it
    J = rec.known.J_hull
    return Result(method="toy", lambda66=10.0, ci95=(9.0, 11.0), n_intervals=1, details={"J_hull": J})


def test_add_an_identification_method(monkeypatch, realistic_record):
    rec, _ = realistic_record
    monkeypatch.setitem(METHODS, "toy", f"{HERE}:identify_toy")
    result = identify([rec], "toy")
    assert result.method == "toy" and result.lambda66 == 10.0


# --- a bench fault: hw_adapter/faults.py NAMES (+ its line in the docstring table), and where
# it acts in hw_adapter/board.py or hw_adapter/emulator.py (``faults_plan.active(name, t)``) ---
def test_add_a_bench_fault(monkeypatch):
    monkeypatch.setattr(faults, "NAMES", faults.NAMES + ("toy_fault",))
    plan = faults.parse_faults("toy_fault=0.5@1.0")
    assert plan.active("toy_fault", 0.5) == 0.0 and plan.active("toy_fault", 2.0) == 0.5
    with pytest.raises(KeyError, match="no fault is called 'toy_falut'"):
        plan.active("toy_falut", 2.0)  # a misspelt name in the board code is an error, not "off"
    for name in faults.NAMES[:-1]:
        assert f"``{name}" in faults.__doc__, f"fault {name!r} is not in hw_adapter/faults.py's table"
