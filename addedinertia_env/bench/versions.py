"""What a benchmark row's numbers mean, as a version: every row carries ``score_version``,
and rows of different versions are never ranked together.

A score is the estimate (the energy method as written), the truth it is divided by, and the
ranking built on them. When one of them changes, the version changes, so that a board
never puts an old error beside a new one:

* ``v0`` (rows without ``score_version``, written before 2026-11-27): with radiation memory
  on, the truth was A66 at the natural swing frequency, 1.7-2.0 % above A66(0) on the
  shipped hulls; in memory-free water it was the hull's lambda66.
* ``capped-mean-v1`` (a former version, :data:`~.score.FORMER_VERSIONS`): the truth is
  lambda66 = A66(0), the zero-frequency added inertia, in every water (``docs/RUN_RECORD.md``);
  the ranked score is the mean of capped |error| with a failure at the cap (:mod:`.score`).
* ``capped-mean-memory-corrected-v1`` (former): the same score on the memory-corrected estimate
  (the method as written with the water's memory identified from the records and corrected
  for), ranked by a suite that says ``ranked: memory-corrected`` (memory-v1).
* ``capped-mean-v2`` (former): ``capped-mean-v1`` on a rig with a gearbox (``gear_ratio`` > 1:
  drive-v0, drive-v1), once the energy method booked the gearhead's loss identified on the
  flywheel's own balance (``identify/energy_gear.py``).
* 2026-11-28, the energy method revised on every rig: the rest after the brake's release read
  from the hull's law of motion (``identify/energy_rest.py``), the torque scale of a smooth
  current fitted at the current's sampling rule (``identify/energy_calibration.py``), the
  rotor's dry friction near rest read from the flywheel's coast (``identify/rotor_friction.py``)
  (docs/INTERVALS.md). So every version moved on:

  - :data:`SCORE_VERSION` (``capped-mean-v4``): rigs without a gearbox;
  - :data:`GEARED_SCORE_VERSION` (``capped-mean-v3``): rigs with a gearbox, where the energy
    method also books the motor's cogging seen on the flywheel's balance, with the gearhead's
    loss fitted beside it (``identify/energy_cogging.py``);
  - :data:`~.score.MEMORY_SCORE_VERSION` (``capped-mean-memory-corrected-v2``): the
    memory-corrected estimate, its memory families averaged by their evidence.

  Former versions' rows keep their version: a board of one former version alone is still
  ranked (the boards in docs/ say which version they are); never beside another version, and a
  new run does not resume them (rerun them with ``addedinertia bench run --force``).

A suite whose truth changed takes a new name too (``memory-v1``: the memory presets, truth
A66(0)); memory-free suites kept their names, their truth being the same number.

:func:`check_versions` is what the leaderboard runs on the files it is given
(:func:`.leaderboard.load_rows`): one version (rows without one count as ``v0``) is ranked;
several, or a version this code does not write, are refused naming each file and its
version(s) (exit status 2 from ``addedinertia bench leaderboard``). ``bench run`` never
appends rows of this version to a file holding another (:func:`.resume.prepare_output`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from addedinertia_env.bench.score import (  # bench/score.py
    FORMER_VERSIONS,
    GEARED_SCORE_VERSION,
    MEMORY_SCORE_VERSION,
    SCORE_VERSION,
)

FIELD = "score_version"  # the rows' field
LEGACY = "v0"  # rows without the field: written before the truth was A66(0) with memory on
# a board of any one alone is ranked
RANKABLE = (SCORE_VERSION, GEARED_SCORE_VERSION, MEMORY_SCORE_VERSION, *FORMER_VERSIONS, LEGACY)


class ScoreVersionError(ValueError):
    """Rows of several score versions, or of a version this code does not rank."""


def row_version(row: Mapping[str, Any]) -> str:
    """The row's ``score_version``; :data:`LEGACY` for a row written before rows carried one."""
    value = row.get(FIELD)
    return LEGACY if value is None else str(value)


def row_fields(geared: bool = False, ranked: str = "as-written") -> dict[str, str]:
    """The version fields a new benchmark row carries (bench/runner.py): the suite's ``ranked`` estimate
    (``memory-corrected``: :data:`MEMORY_SCORE_VERSION`), else ``geared`` (its rig has a gearbox:
    :data:`GEARED_SCORE_VERSION`), else :data:`SCORE_VERSION`."""
    if ranked == "memory-corrected":
        return {FIELD: MEMORY_SCORE_VERSION}
    return {FIELD: GEARED_SCORE_VERSION if geared else SCORE_VERSION}


def check_versions(rows_by_file: Mapping[str, Sequence[Mapping[str, Any]]]) -> str:
    """The one score version of the rows of every file in ``rows_by_file`` (file -> its rows);
    :class:`ScoreVersionError` naming each file with its version(s) when they differ or when the
    one version is not one this code ranks (:data:`RANKABLE`)."""
    per_file = {str(f): sorted({row_version(r) for r in rows}) for f, rows in rows_by_file.items() if rows}
    found = sorted({v for versions in per_file.values() for v in versions})
    listing = "; ".join(f"{f}: {', '.join(v)}" for f, v in per_file.items())
    if len(found) > 1:
        raise ScoreVersionError(f"rows of different score versions cannot be ranked together ({listing}); "
                                f"rerun the older rows with `addedinertia bench run --force` (this code writes "
                                f"{SCORE_VERSION!r}; docs/SUBMITTING.md, 'Score versions')")
    if found and found[0] not in RANKABLE:
        raise ScoreVersionError(f"score version {found[0]!r} ({listing}) is not one this code ranks; expected "
                                f"{' or '.join(repr(v) for v in RANKABLE)} (rows without '{FIELD}' are {LEGACY!r})")
    return found[0] if found else SCORE_VERSION
