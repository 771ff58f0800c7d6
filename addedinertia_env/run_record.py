"""A run record in memory: :class:`RunRecord` (samples + metadata) and :class:`RecordError`.

The file format (``addedinertia-run/1``), its reader and its writer are in
:mod:`addedinertia_env.record`, which re-exports both names; this module is apart so that
:mod:`addedinertia_env.plausibility` (which the reader calls) can use them without
importing the reader.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .rig.known import KnownRig


class RecordError(ValueError):
    """A run record that cannot be used; the message names file, place, value, expectation."""


@dataclass
class RunRecord:
    """Samples (column name -> array; ``phase`` is an array of str) and metadata."""

    samples: dict[str, np.ndarray]
    meta: dict[str, Any]
    path: Path | None = None
    gaps: list[tuple[float, float]] = field(default_factory=list)  # (t_before, gap_s) beyond 5 periods

    # Convenience views -------------------------------------------------------------
    def __getitem__(self, column: str) -> np.ndarray:
        return self.samples[column]

    @property
    def t(self) -> np.ndarray:
        """Sample times, s."""
        return self.samples["t"]

    @property
    def phase(self) -> np.ndarray:
        """Phase of each sample (str array)."""
        return self.samples["phase"]

    @property
    def rig(self) -> dict[str, Any]:
        """The raw ``rig`` block as stored (kept on round trip); read constants from :attr:`known`."""
        return self.meta["rig"]

    @property
    def known(self) -> KnownRig:
        """The ``rig`` block, typed: what the experimenter knows (SI units)."""
        return KnownRig.from_block(self.meta["rig"])

    @property
    def experiment(self) -> dict[str, Any]:
        """The ``experiment`` block (kind, plan, what the tool recorded)."""
        return self.meta["experiment"]

    @property
    def run_id(self) -> str:
        """The record's ``run_id`` ('' if absent)."""
        return str(self.meta.get("run_id", ""))

    @property
    def name(self) -> str:
        """The file path, else the run id: how messages name this record."""
        return str(self.path) if self.path is not None else self.run_id or "<record>"

    def phase_mask(self, name: str) -> np.ndarray:
        """Boolean mask of the samples in phase ``name``."""
        return self.phase == name

    def truth_lambda66(self) -> float | None:
        """For scoring simulated runs only. Estimators must not call this."""
        truth = self.meta.get("truth")
        return None if not truth else float(truth["lambda66"])

    def without_truth(self) -> "RunRecord":
        """A copy whose metadata has no ``truth``: what estimators are given."""
        meta = {k: v for k, v in self.meta.items() if k != "truth"}
        return RunRecord(samples=self.samples, meta=meta, path=self.path, gaps=self.gaps)

    def __len__(self) -> int:
        return int(self.t.size)
