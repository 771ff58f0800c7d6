"""Controllers by name: ``pid``, ``feedforward-pd``, ``lqr``, ``ilc``, ``mpc``, ``pd``,
``onnx:PATH`` (an exported policy) and ``module:factory`` (an outside controller)."""

from __future__ import annotations

from typing import Any

from addedinertia_env.experiment.controller import Controller

from agents.classical import CLASSICAL, UnknownController, controller_class, load_factory, make_plain_controller

__all__ = ["CLASSICAL", "DEFAULT_CONTROLLER", "REFERENCE_ROWS", "UnknownController", "controller_class",
           "load_factory", "make_controller"]

# The controller used where none is named (demo, simulate, the accuracy table): the best
# classical controller on realistic sensors in docs/LEADERBOARD.md.
DEFAULT_CONTROLLER = "lqr"

REFERENCE_ROWS = ("oracle", "zero")  # benchmark references (addedinertia_env/bench/runner.py), not controllers


def make_controller(name: str, **kwargs: Any) -> Controller:
    """A controller from its name; see the module docstring for the accepted forms."""
    if name in REFERENCE_ROWS:
        raise UnknownController(f"{name!r} is a reference row of the simulated benchmark suites "
                                f"(`addedinertia bench run --suite NAME --controller {name}`); it cannot drive "
                                "a bench or an experiment")
    if name.startswith("onnx:"):
        from agents.onnx_policy import OnnxPolicy  # noqa: PLC0415 - optional heavy import (onnxruntime)

        if kwargs:
            raise TypeError(f"controller {name!r}: an exported policy takes no parameters, got {sorted(kwargs)} "
                            "(its settings are in the policy's metadata)")
        return OnnxPolicy(name[len("onnx:"):])
    return make_plain_controller(name, **kwargs)
