"""The standard discovery dataset: a few simulated runs that show every fingerprint.

physics.md section 8 says what separates the candidate effects: fluid memory shows as a
reverse stroke that depends on the hold time, spring stiffening as a period that
depends on the amplitude, dry friction as a decrement that does not scale with the
amplitude. So the standard dataset crosses two twists with two hold times:

    alpha (rad)  0.05, 0.10     (about 3 and 6 degrees: mirrorable within 15 A)
    hold (s)     0.5, 5.0

One hidden effect (or none) is drawn with :func:`addedinertia_env.sim.effects.draw_effect`
from a seed, on the default rig (``wigley-2m``, realistic sensors), driven by the default
controller. The truth stays in the records' ``truth`` block for scoring only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from addedinertia_env.records.record import RunRecord, write_record
from addedinertia_env.sim.effects import Effects, draw_effect
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.experiment.protocol import plan_from_preset

STANDARD_ALPHAS = (0.05, 0.10)  # rad
STANDARD_HOLDS = (0.5, 5.0)  # s


@dataclass(frozen=True)
class DatasetSpec:
    """Which runs make up a discovery dataset."""

    alphas: tuple[float, ...] = STANDARD_ALPHAS
    holds: tuple[float, ...] = STANDARD_HOLDS
    rig: str = "wigley-2m"
    controller: str = "feedforward-pd"
    hydrodynamics: str | None = None  # None: the preset's model; "cummins": radiation memory (hydro/radiation.py)

    @property
    def runs(self) -> list[tuple[float, float]]:
        """Every (twist ``alpha`` in rad, hold in s) pair of the dataset, one run each."""
        return [(a, h) for a in self.alphas for h in self.holds]


def hidden_effect(effect: str, seed: int) -> Effects:
    """The hidden effect of dataset ``(effect, seed)``: a realistic size drawn from the seed."""
    return draw_effect(effect, np.random.default_rng(np.random.SeedSequence([seed, 4, 0])))


def simulate_dataset(effect: str, seed: int, spec: DatasetSpec | None = None,
                     out: str | Path | None = None, effects: Effects | None = None) -> list[RunRecord]:
    """The runs of the standard dataset with ``effect`` (or ``"none"``) hidden, seeded.

    ``effects``: hide exactly these instead (e.g. two at once; ``effect`` is then only a label).
    With ``out``, the records are also written there as ``run-a{alpha}-h{hold}.csv``.
    """
    from addedinertia_env.apps.simulate import simulate_run  # noqa: PLC0415 - heavy import (MuJoCo, agents)

    spec = spec or DatasetSpec()
    data = load_preset(spec.rig)
    rig = rig_from_mapping(data, effects=effects if effects is not None else hidden_effect(effect, seed),
                           hydrodynamics=spec.hydrodynamics)
    records = []
    noise_seeds = np.random.SeedSequence([seed, 4, 1]).spawn(len(spec.runs))
    for (alpha, hold), ss in zip(spec.runs, noise_seeds):
        plan = plan_from_preset(data, alpha=alpha, hold_s=hold)
        run_id = f"run-a{alpha:.3f}-h{hold:.1f}"
        rec = simulate_run(rig, spec.controller, plan, seed=ss, run_id=run_id)
        rec.meta["experiment"]["seed"] = seed
        if out is not None:
            write_record(rec, Path(out) / f"{run_id}.csv")
        records.append(rec)
    return records


def simulate_pair_dataset(pair: tuple[str, str], seed: int, spec: DatasetSpec | None = None,
                          out: str | Path | None = None) -> list[RunRecord]:
    """The standard dataset with both effects of ``pair`` hidden (:func:`.pairs.hidden_pair`: sizes drawn from ``seed``)."""
    from addedinertia_env.discover.pairs import hidden_pair  # noqa: PLC0415

    return simulate_dataset("+".join(pair), seed, spec, out=out, effects=hidden_pair(pair, seed))
