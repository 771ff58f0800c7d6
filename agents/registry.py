"""Controllers by name: ``pid``, ``feedforward-pd``, ``lqr``, ``ilc``, ``mpc``, ``pd``,
``onnx:PATH`` (an exported policy) and ``module:factory`` (an outside controller)."""

from __future__ import annotations

import importlib
from typing import Any, Callable

# The controller used where none is named (demo, simulate, the accuracy table): the best
# classical controller on realistic sensors in docs/LEADERBOARD.md.
DEFAULT_CONTROLLER = "lqr"

# name -> "module:attribute" of a zero-argument factory (usually the class).
CLASSICAL: dict[str, str] = {
    "pd": "agents.feedforward_pd:PD",
    "feedforward-pd": "agents.feedforward_pd:FeedforwardPD",
    "pid": "agents.pid:PID",
    "lqr": "agents.lqr:LQR",
    "ilc": "agents.ilc:ILC",
    "mpc": "agents.mpc:MPC",
}


class UnknownController(ValueError):
    pass


def _load(spec: str) -> Callable[..., Any]:
    module, _, attr = spec.partition(":")
    try:
        obj = importlib.import_module(module)
    except ImportError as e:
        raise UnknownController(f"controller {spec!r}: cannot import module {module!r} ({e})") from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise UnknownController(f"controller {spec!r}: module {module!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise UnknownController(f"controller {spec!r}: {attr!r} is not callable")
    return obj


REFERENCE_ROWS = ("oracle", "zero")  # benchmark references (addedinertia_env/bench/runner.py), not controllers


def make_controller(name: str, **kwargs: Any) -> Any:
    """A controller from its name; see the module docstring for the accepted forms."""
    if name in REFERENCE_ROWS:
        raise UnknownController(f"{name!r} is a reference row of the simulated benchmark suites "
                                f"(`addedinertia bench run --suite NAME --controller {name}`); it cannot drive "
                                "a bench or an experiment")
    if name in CLASSICAL:
        return _load(CLASSICAL[name])(**kwargs)
    if name.startswith("onnx:"):
        from .onnx_policy import OnnxPolicy  # noqa: PLC0415 - optional heavy import

        return OnnxPolicy(name[len("onnx:"):])
    if ":" in name:
        return _load(name)(**kwargs)
    known = ", ".join(sorted(CLASSICAL))
    raise UnknownController(f"unknown controller {name!r}; expected one of {known}, onnx:PATH or module:factory")
