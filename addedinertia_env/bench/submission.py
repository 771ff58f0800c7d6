"""What an outside submission declares about itself: kind (classical or learned) and training cost.

A ``module:factory`` controller is an outside submission. It says what it is either on the
command line (``bench run --entry-kind learned --train-cost 40960,6.5``) or in a card file
beside its module, ``<module>.card.yaml`` (or ``.card.json``)::

    entry_kind: learned        # or classical
    train_env_steps: 40960     # environment samples used in training (learned only)
    train_cpu_minutes: 6.5     # CPU minutes of training (learned only)

The command line wins over the card. Without either, a submission is ``classical`` with
no training cost. Exported policies (``onnx:PATH``) carry their cost in their own metadata
and are ``learned``; the registry's controllers are ``classical``; ``oracle`` and ``zero``
are ``reference`` rows. docs/SUBMITTING.md is the whole protocol.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from typing import Any

import yaml

KINDS = ("classical", "learned")
CARD_KEYS = {"entry_kind", "train_env_steps", "train_cpu_minutes", "name", "description", "contact"}


class SubmissionError(ValueError):
    """A declaration that cannot be used; the message names the value and what was expected."""


def parse_train_cost(text: str) -> dict[str, float | int]:
    """``"ENV_STEPS,CPU_MINUTES"`` -> ``{"train_env_steps": int, "train_cpu_minutes": float}``."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        if len(parts) != 2:
            raise ValueError
        steps, minutes = int(parts[0]), float(parts[1])
    except ValueError:
        raise SubmissionError(f"--train-cost {text!r}: expected ENV_STEPS,CPU_MINUTES, e.g. 40960,6.5") from None
    if steps < 0 or not math.isfinite(minutes) or minutes < 0:
        raise SubmissionError(f"--train-cost {text!r}: expected ENV_STEPS >= 0 and CPU_MINUTES >= 0")
    return {"train_env_steps": steps, "train_cpu_minutes": minutes}


def card_path(controller: str) -> Path | None:
    """The card file beside a ``module:factory`` submission's module, if there is one."""
    if ":" not in controller or controller.startswith("onnx:"):
        return None
    module = controller.partition(":")[0]
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.origin or spec.origin in ("built-in", "frozen"):
        return None
    origin = Path(spec.origin)
    for suffix in (".card.yaml", ".card.yml", ".card.json"):
        path = origin.with_name(origin.stem + suffix)
        if path.is_file():
            return path
    return None


def read_card(path: Path) -> dict[str, Any]:
    """A submission card, validated (see module doc)."""
    try:
        text = path.read_text()
        data = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    except (OSError, json.JSONDecodeError, yaml.YAMLError) as e:
        raise SubmissionError(f"{path}: not a readable card ({e})") from None
    if not isinstance(data, dict):
        raise SubmissionError(f"{path}: expected a mapping with keys among {sorted(CARD_KEYS)}")
    unknown = sorted(set(data) - CARD_KEYS)
    if unknown:
        raise SubmissionError(f"{path}: unknown key(s) {unknown}; allowed keys are {sorted(CARD_KEYS)}")
    out: dict[str, Any] = {}
    kind = data.get("entry_kind", "classical")
    if kind not in KINDS:
        raise SubmissionError(f"{path}: entry_kind = {kind!r}; expected one of {KINDS}")
    out["entry_kind"] = kind
    for key, typ in (("train_env_steps", int), ("train_cpu_minutes", float)):
        if key in data:
            v = data[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0 \
                    or (typ is int and int(v) != v):
                raise SubmissionError(f"{path}: {key} = {v!r}; expected a {'whole ' if typ is int else ''}number >= 0")
            out[key] = typ(v)
    return out


def declared_entry(controller: str, kind: str | None = None, train_cost: str | None = None) -> dict[str, Any]:
    """Row fields a submission declares (``entry_kind``, training cost, ``card``); empty for
    the registry's controllers, exported policies and the references, unless given here."""
    from addedinertia_env.bench.runner import REFERENCES  # noqa: PLC0415

    if controller in REFERENCES and (kind or train_cost):
        raise SubmissionError(f"--controller {controller}: a reference row takes no --entry-kind or --train-cost")
    entry: dict[str, Any] = {}
    path = card_path(controller)
    if path is not None:
        entry.update(read_card(path))
        entry["card"] = str(path)
    if kind is not None:
        entry["entry_kind"] = kind
    if train_cost is not None:
        entry.update(parse_train_cost(train_cost))
    if entry.get("entry_kind") == "classical" and any(k in entry for k in ("train_env_steps", "train_cpu_minutes")):
        raise SubmissionError(f"--controller {controller}: a training cost is declared but the entry kind is "
                              "classical; declare --entry-kind learned (or drop the cost)")
    if any(k in entry for k in ("train_env_steps", "train_cpu_minutes")):
        entry.setdefault("entry_kind", "learned")
    return entry
