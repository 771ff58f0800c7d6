"""The ``Controller`` protocol (addedinertia_env/experiment/controller.py, issue 29 item 4).

Every controller the registry can make (classical by name, exported policies ``onnx:PATH``,
outside ``module:factory``) and the benchmark's references satisfy it: ``isinstance`` with
the runtime-checkable protocol, and their ``reset``/``predict`` accept the runner's calls
(a signature check, since ``isinstance`` looks only at the names). No signature says
``controller: Any`` any more.
"""

from __future__ import annotations

import ast
import inspect
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.experiment.controller import DECLARATIONS, Controller
from agents.registry import CLASSICAL, make_controller

ROOT = Path(__file__).resolve().parents[1]
POLICIES = sorted((ROOT / "agents" / "policies").glob("*.onnx"))


def _accepts_the_runners_calls(controller) -> None:
    """reset(context) and predict(obs), predict(obs, state, episode_start, deterministic),
    predict(obs, deterministic=True) bind to the controller's own signatures."""
    obs = np.zeros(4, np.float32)
    inspect.signature(controller.reset).bind(object())
    predict = inspect.signature(controller.predict)
    predict.bind(obs)
    predict.bind(obs, None, None, True)
    predict.bind(obs, deterministic=True)


@pytest.mark.parametrize("name", sorted(CLASSICAL))
def test_every_classical_controller_is_a_controller(name):
    controller = make_controller(name)
    assert isinstance(controller, Controller)
    _accepts_the_runners_calls(controller)


@pytest.mark.parametrize("path", POLICIES, ids=[p.name for p in POLICIES])
def test_every_shipped_policy_is_a_controller(path):
    pytest.importorskip("onnxruntime")
    controller = make_controller(f"onnx:{path}")
    assert isinstance(controller, Controller)
    _accepts_the_runners_calls(controller)
    for key in ("policy_rate_hz", "board_mode", "train_env_steps", "train_cpu_minutes"):
        assert key in DECLARATIONS and hasattr(controller, key)  # what its card declares


def test_the_references_and_wrappers_are_controllers():
    from addedinertia_env.experiment.oracle import OracleController
    from addedinertia_env.sim.mujoco_rig import MujocoRig
    from addedinertia_env.sim.presets import load_rig
    from agents.held import HeldController
    from agents.zero import ZeroCurrent

    for controller in (ZeroCurrent(), HeldController("pd", every=10),
                       OracleController(MujocoRig(load_rig("wigley-2m"), seed=0))):
        assert isinstance(controller, Controller)
        _accepts_the_runners_calls(controller)


def test_an_outside_module_factory_controller_is_a_controller_and_one_without_reset_is_not(tmp_path, monkeypatch):
    (tmp_path / "outside_ctrl.py").write_text(textwrap.dedent('''
        import numpy as np

        class Mine:
            def reset(self, context):
                self.ctx = context

            def predict(self, observation, state=None, episode_start=None, deterministic=True):
                return np.zeros(1, np.float32), state

        class NoReset:
            def predict(self, observation, state=None, episode_start=None, deterministic=True):
                return np.zeros(1, np.float32), state

        def make():
            return Mine()
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        controller = make_controller("outside_ctrl:make")
        assert isinstance(controller, Controller)
        _accepts_the_runners_calls(controller)
        assert not isinstance(make_controller("outside_ctrl:NoReset"), Controller)
    finally:
        sys.modules.pop("outside_ctrl", None)


def test_a_predict_that_cannot_take_the_runners_arguments_fails_the_signature_check():
    class Narrow:
        def reset(self, context):
            pass

        def predict(self, observation):  # no deterministic=: the runner's call would fail
            return np.zeros(1, np.float32), None

    assert isinstance(Narrow(), Controller)  # isinstance sees only the names ...
    with pytest.raises(TypeError):
        _accepts_the_runners_calls(Narrow())  # ... the signature check sees the call


def test_no_signature_types_a_controller_as_any():
    offenders = []
    for pkg in ("addedinertia_env", "agents", "hw_adapter"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                    for a in args:
                        if a.arg == "controller" and a.annotation is not None and "Any" in ast.unparse(a.annotation):
                            offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}({a.arg})")
                    if "controller" in node.name and node.returns is not None and ast.unparse(node.returns) == "Any":
                        offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} -> Any")
    assert not offenders, offenders
