"""One tuning procedure for every classical controller (the gains they load: agents/tuned.py).

Procedure (docs/CONTROLLERS.md): a seeded random search over the controller's
``KNOBS`` (log-uniform or uniform in each documented range). Candidate 0 is the
controller's hand-set ``DEFAULTS``; every candidate is scored on the same scenarios of
the suite's *tuning* split (never the test split), and the score is the benchmark's
ranked one (:mod:`.score`): the mean over the scenarios of ``min(|e|, CAP)`` (``e`` the
relative lambda66 error of the energy method as written), a failed run or
identification counting ``CAP``. Every controller
gets the same budget: the same number of candidates times the same scenarios (ILC runs
its learning cycles inside each scenario, as in the benchmark; only the scored last
cycle differs from the others). The winner is written to ``configs/controllers/tuned.yaml``
(or to the suite's own file, its ``tuned:`` key) with the command that produced it;
controllers read it by default.

Command: ``addedinertia bench tune --suite standard-v0 --controller NAME``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agents.registry import CLASSICAL, controller_class
from agents.tuned import TUNED_PATH, load_tuned, resolve_params  # noqa: F401 - the gains this module writes

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.bench.runner import run_tasks
from addedinertia_env.bench.score import SCORE_VERSION, episode_score
from addedinertia_env.bench.suites import load_suite


def sample_candidates(knobs: dict[str, tuple[float, float, str]], n: int, seed: int) -> list[dict[str, float]]:
    """``n`` candidates: ``{}`` (the defaults) then ``n - 1`` random draws over ``knobs``."""
    rng = np.random.default_rng(seed)
    out: list[dict[str, float]] = [{}]
    for _ in range(n - 1):
        cand = {}
        for key, (lo, hi, scale) in sorted(knobs.items()):
            if scale == "log":
                cand[key] = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
            else:
                cand[key] = float(rng.uniform(lo, hi))
        out.append(cand)
    return out


def score(errors: list[float | None]) -> float:
    """The ranked score of :mod:`.score` over relative lambda66 errors: the mean of ``min(|e|, CAP)``,
    a failure (None or not finite) counting ``CAP``; ``inf`` for no errors."""
    vals = [episode_score({"rel_error": e}) for e in errors]
    return float(np.mean(vals)) if vals else math.inf


def tune(controller: str, suite: str = "standard-v0", candidates: int = 8, scenarios: int = 8,
         seed: int = 0, jobs: int = 2, progress: bool = True) -> dict[str, Any]:
    """Random search (see module doc); returns ``{"params", "score", "trials"}``."""
    if controller not in CLASSICAL:
        raise ValueError(f"tuning is for the classical controllers {sorted(CLASSICAL)}, not {controller!r}")
    cls = controller_class(controller)
    knobs = getattr(cls, "KNOBS", {})
    if not knobs:
        raise ValueError(f"controller {controller!r} has no KNOBS to tune")
    s = load_suite(suite)
    scen = s.scenarios("tuning")[:scenarios]
    cands = sample_candidates(knobs, candidates, seed)
    defaults = {k: v for k, v in cls.DEFAULTS.items() if k in knobs}
    tasks = [s.task(sc, controller, {**defaults, **cand}, tuned=False) for cand in cands for sc in scen]
    rows = run_tasks(tasks, jobs=jobs, progress=progress, desc=f"tune {controller}")
    trials = []
    for k, cand in enumerate(cands):
        chunk = rows[k * len(scen):(k + 1) * len(scen)]
        full = {**defaults, **cand}
        trials.append({"params": full, "score": score([r.get("rel_error") for r in chunk]),
                       "median_energy_J": float(np.median([r["energy_J"] or 0.0 for r in chunk]))})
    best = min(trials, key=lambda t: (t["score"], t["median_energy_J"]))
    return {"params": best["params"], "score": best["score"], "trials": trials,
            "budget": {"candidates": candidates, "scenarios": len(scen), "episodes": len(tasks)},
            "score_version": str(rows[0].get("score_version", SCORE_VERSION)) if rows else SCORE_VERSION,
            "tuned_path": str(s.tuned_path or TUNED_PATH)}


def write_tuned(name: str, result: dict[str, Any], command: str, path: Path | None = None) -> Path:
    """Store ``result['params']`` for ``name`` in the tuned-gains YAML (atomic write)."""
    path = path or TUNED_PATH
    data = (yaml.safe_load(path.read_text()) or {}) if path.exists() else {}
    data[name] = {"params": {k: (round(v, 6) if isinstance(v, float) else v) for k, v in result["params"].items()},
                  "tuning_score": round(float(result["score"]), 6), "score_version": result.get("score_version", SCORE_VERSION),
                  "budget": result.get("budget", {}), "command": command}
    header = ("# Tuned controller gains, written by `addedinertia bench tune` (addedinertia_env/bench/tuning.py).\n"
              "# Each entry: the parameters, the tuning-split score, the budget and the command.\n")
    atomic_write_text(path, header + yaml.safe_dump(data, sort_keys=True))
    return path
