"""Controllers that need no optional package: the classical ones by name and outside
factories by ``module:attribute`` (the registry adds exported policies, ``onnx:PATH``)."""

from __future__ import annotations

import importlib
from typing import Any, Callable

from addedinertia_env.experiment.controller import Controller

# name -> "module:attribute" of a zero-argument factory (usually the class).
CLASSICAL: dict[str, str] = {
    "pd": "agents.feedforward_pd:PD",
    "feedforward-pd": "agents.feedforward_pd:FeedforwardPD",
    "pid": "agents.pid:PID",
    "lqr": "agents.lqr:LQR",
    "ilc": "agents.ilc:ILC",
    "mpc": "agents.mpc:MPC",
    "drive-aware": "agents.drive_aware:DriveAwarePD",
    "backlash-inversion": "agents.backlash_inversion:BacklashInversionPD",
    "pid-antiwindup": "agents.voltage_antiwindup:VoltageAntiWindupPID",
    "cogging-ff": "agents.cogging_ff:CoggingFeedforwardPD",
    "supply-aware": "agents.supply_aware:SupplyAwarePD",
    "smith-pd": "agents.smith_pd:SmithPD",
}


class UnknownController(ValueError):
    """A controller name or ``module:attribute`` that names no controller; the message lists the known ones."""

    pass


def load_factory(spec: str) -> Callable[..., Any]:
    """The callable named by ``"module:attribute"``; ``UnknownController`` saying what is missing."""
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


def controller_class(name: str) -> Callable[..., Any]:
    """The class (factory) of the classical controller ``name``; ``UnknownController`` otherwise."""
    if name not in CLASSICAL:
        raise UnknownController(f"unknown classical controller {name!r}; expected one of {', '.join(sorted(CLASSICAL))}")
    return load_factory(CLASSICAL[name])


def make_plain_controller(name: str, **kwargs: Any) -> Controller:
    """A classical controller by name, or an outside one by ``module:factory``, with ``kwargs``."""
    if name in CLASSICAL:
        return load_factory(CLASSICAL[name])(**kwargs)
    if ":" in name:
        return load_factory(name)(**kwargs)
    known = ", ".join(sorted(CLASSICAL))
    raise UnknownController(f"unknown controller {name!r}; expected one of {known}, onnx:PATH or module:factory")
