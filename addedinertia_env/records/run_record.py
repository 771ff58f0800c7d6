"""A run record in memory: :class:`RunRecord` (samples + metadata) and its typed views
(:class:`RecordViews`: the known rig, the phase blocks, the sampling, the plausibility limits,
each computed once).

The file format (``addedinertia-run/1``), its reader and its writer are in
:mod:`addedinertia_env.records.record`, which re-exports :class:`RunRecord`, :class:`Sampling` and
:class:`~addedinertia_env.records.record_error.RecordError`; the views call
:mod:`addedinertia_env.records.plausibility`, which therefore knows the record only by what it reads.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.records import plausibility
from addedinertia_env.records.plausibility import Limits
from addedinertia_env.records.record_error import RecordError  # noqa: F401 - re-exported
from addedinertia_env.rig.known import KnownRig
from addedinertia_env.records.scan_kernels import block_starts

# Spec range of DAQ sample rates (Hz); outside it a record is still read, with a note.
SAMPLE_RATE_RANGE = (250.0, 10_000.0)


@dataclass(frozen=True)
class Sampling:
    """How a record was sampled, measured from its ``t`` column (s, Hz).

    ``uniform``: every interval within 1 % of the nominal period ``1 / rig.sample_rate``;
    methods that need a uniform grid must check it (or resample and say so).
    """

    nominal_rate: float  # Hz, rig.sample_rate
    median_interval: float  # s
    jitter_rms: float  # s, RMS of (interval - its nearest whole number of periods)
    dropped: int  # samples missing, estimated as sum(round(interval / period) - 1)
    gaps: tuple[tuple[float, float], ...]  # (t before, length s) of intervals over five periods
    uniform: bool
    in_spec_range: bool  # nominal rate within 250 Hz .. 10 kHz (run-record.md)

    def to_json(self) -> dict[str, Any]:
        """The sampling summary as a JSON-ready dict."""
        return {"nominal_rate_hz": self.nominal_rate, "median_interval_s": self.median_interval,
                "jitter_rms_s": self.jitter_rms, "dropped_samples": self.dropped,
                "gaps": [{"after_t": a, "length_s": g} for a, g in self.gaps], "uniform": self.uniform,
                "rate_in_spec_range": self.in_spec_range}


@dataclass(frozen=True, eq=False)
class PhaseBlocks:
    """The record's contiguous blocks of one ``phase`` label (as logged; :func:`~addedinertia_env.records.record.motion_phase`
    says how the brake changes them): the first sample and the label of each, and the first block of each label."""

    starts: np.ndarray
    """First sample of each block (int64, read-only); block ``j`` is ``starts[j]:starts[j + 1]`` (the last ends at ``n``)."""
    labels: tuple[str, ...]
    """The label of each block."""
    n: int
    """Samples in the record."""
    firsts: dict[str, slice] = field(compare=False)
    """The first block of each label present (a label's later blocks, if any, are not in it)."""

    @classmethod
    def of(cls, phase) -> "PhaseBlocks":
        """The blocks of a ``phase`` column."""
        phase = np.asarray(phase)
        starts = block_starts(phase)
        starts.flags.writeable = False
        labels = tuple(str(label) for label in phase[starts].tolist())
        firsts: dict[str, slice] = {}
        bounds = starts.tolist() + [len(phase)]
        for a, b, label in zip(bounds, bounds[1:], labels):
            firsts.setdefault(label, slice(a, b))
        return cls(starts=starts, labels=labels, n=len(phase), firsts=firsts)

    def first(self, label: str) -> slice | None:
        """The first contiguous block of samples labelled ``label``, or None."""
        return self.firsts.get(label)


class RecordViews:
    """The typed views of one run record, each computed on first use and then kept.

    * :attr:`known`: the ``rig`` block as a :class:`~addedinertia_env.rig.known.KnownRig`;
    * :attr:`phase_blocks`: the contiguous blocks of one phase (:class:`PhaseBlocks`);
    * :attr:`sampling`: how the record was sampled (:class:`Sampling`: rate,
      jitter, dropped samples, gaps);
    * :attr:`limits`: the plausibility check's limits (:class:`~addedinertia_env.records.plausibility.Limits`);
      the first use runs the check, which raises :class:`RecordError` for a record its own rig could
      not have produced (a refusal is not kept: the next use checks again).

    A record read from a file has had its limits computed by the reader; estimators and
    :func:`~addedinertia_env.identify.identify` read the same views instead of deriving them again.
    The views belong to the record's data as they were when first taken: :attr:`RunRecord.views` makes
    new ones when a column or the metadata's ``rig`` block, ``experiment.kind``, the path or the gaps were
    replaced or changed since; a column changed in place (``rec["i"][k] = ...``) is not noticed: replace
    the array instead.
    """

    def __init__(self, record: "RunRecord") -> None:
        self._record = record
        # what the views depend on: the columns (the arrays themselves), a copy of the rig block, the
        # experiment's kind, the path and the gaps
        self._samples, self._columns = record.samples, tuple(record.samples.items())
        self._rig, self._kind = copy.deepcopy(record.meta.get("rig")), _kind(record.meta)
        self._path, self._gaps = record.path, tuple(record.gaps)

    def matches(self, record: "RunRecord") -> bool:
        """Whether these views still describe ``record``'s data."""
        samples = record.samples
        if samples is not self._samples or len(samples) != len(self._columns):
            return False
        if any(name != was or array is not array_was
               for (name, array), (was, array_was) in zip(samples.items(), self._columns)):
            return False
        return (record.meta.get("rig") == self._rig and _kind(record.meta) == self._kind
                and record.path == self._path and tuple(record.gaps) == self._gaps)

    @cached_property
    def known(self) -> KnownRig:
        """The ``rig`` block, typed: what the experimenter knows (SI units)."""
        return KnownRig.from_block(self._record.meta["rig"])

    @cached_property
    def phase_blocks(self) -> PhaseBlocks:
        """The contiguous blocks of one ``phase`` label."""
        return PhaseBlocks.of(self._record.phase)

    @cached_property
    def sampling(self) -> Sampling:
        """How the record was sampled, measured from its ``t`` column."""
        return measure_sampling(self._record)

    @cached_property
    def limits(self) -> Limits:
        """The plausibility check's limits (the check runs on first use; raises :class:`RecordError`)."""
        return plausibility.check_plausible(self._record)


def _kind(meta: dict[str, Any]) -> Any:
    experiment = meta.get("experiment")
    return experiment.get("kind") if isinstance(experiment, dict) else None


@dataclass
class RunRecord:
    """Samples (column name -> array; ``phase`` is an array of str) and metadata; typed views of
    them in :attr:`views` (computed once)."""

    samples: dict[str, np.ndarray]
    meta: dict[str, Any]
    path: Path | None = None
    gaps: list[tuple[float, float]] = field(default_factory=list)  # (t_before, gap_s) beyond 5 periods
    _views: RecordViews | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def views(self) -> RecordViews:
        """The record's typed views (:class:`RecordViews`), computed once and kept while the data stand."""
        views = self._views
        if views is None or not views.matches(self):
            views = self._views = RecordViews(self)
        return views

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
        """The ``rig`` block, typed: what the experimenter knows (SI units); ``views.known``."""
        return self.views.known

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
        copy_ = RunRecord(samples=self.samples, meta=meta, path=self.path, gaps=self.gaps)
        copy_._views = self.views  # the same data: the views (none of which reads truth) are shared
        return copy_

    def __len__(self) -> int:
        return int(self.t.size)


def measure_sampling(record: RunRecord) -> Sampling:
    """Measure how ``record`` was sampled (what :func:`sampling` keeps in the record's views)."""
    t = np.asarray(record.t, dtype=float)
    rate = record.known.sample_rate
    period = 1.0 / rate
    dt = np.diff(t)
    if dt.size == 0:
        return Sampling(rate, period, 0.0, 0, tuple(record.gaps), True,
                        SAMPLE_RATE_RANGE[0] <= rate <= SAMPLE_RATE_RANGE[1])
    whole = np.maximum(np.round(dt / period), 1.0)
    jitter = dt - whole * period
    return Sampling(nominal_rate=rate, median_interval=float(np.median(dt)),
                    jitter_rms=float(np.sqrt(np.mean(jitter**2))), dropped=int(np.sum(whole - 1.0)),
                    gaps=tuple(record.gaps), uniform=bool(np.all(np.abs(dt - period) <= 0.01 * period)),
                    in_spec_range=SAMPLE_RATE_RANGE[0] <= rate <= SAMPLE_RATE_RANGE[1])
