"""Identification of lambda66 from run records.

Methods: ``energy`` (the patent's), ``free-decay`` (the textbook's), ``forced`` (the
Chinese patent's), ``whole-record`` (gray-box fit). :func:`identify` dispatches by name.
"""

from __future__ import annotations

import importlib

from ..record import RunRecord
from .common import IdentificationError, Result

METHODS = {
    "energy": "addedinertia_env.identify.energy:identify_energy",
    "free-decay": "addedinertia_env.identify.free_decay:identify_free_decay",
    "forced": "addedinertia_env.identify.forced:identify_forced",
    "whole-record": "addedinertia_env.identify.whole_record:identify_whole_record",
}


def identify(records: list[RunRecord], method: str = "energy", **options) -> Result:
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    module, _, func = METHODS[method].partition(":")
    estimator = getattr(importlib.import_module(module), func)
    return estimator([r.without_truth() for r in records], **options)


__all__ = ["IdentificationError", "METHODS", "Result", "identify"]
