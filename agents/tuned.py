"""The tuned gains a classical controller loads by default (``configs/controllers/tuned.yaml``,
written by ``addedinertia bench tune``: addedinertia_env/bench/tuning.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

TUNED_PATH = Path(__file__).resolve().parents[1] / "configs" / "controllers" / "tuned.yaml"


def load_tuned(name: str, path: Path | None = None) -> dict[str, Any]:
    """Tuned parameters of controller ``name`` (empty when none were stored)."""
    path = path or TUNED_PATH
    if not path.exists():
        return {}
    data = yaml.safe_load(path.read_text()) or {}
    entry = data.get(name) or {}
    return dict(entry.get("params") or {})


def resolve_params(name: str | None, defaults: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``defaults`` < tuned values of ``name`` (if given) < ``overrides``; unknown keys refused."""
    unknown = sorted(set(overrides) - set(defaults))
    if unknown:
        raise TypeError(f"unknown controller parameter(s) {unknown}; allowed: {sorted(defaults)}")
    tuned = load_tuned(name) if name else {}
    stale = sorted(set(tuned) - set(defaults))
    if stale:
        raise TypeError(f"{TUNED_PATH}: {name}: unknown parameter(s) {stale}; allowed: {sorted(defaults)}; "
                        f"re-run `addedinertia bench tune --controller {name}`")
    return {**defaults, **tuned, **overrides}
