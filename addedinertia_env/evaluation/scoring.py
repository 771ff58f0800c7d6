"""The one scoring of an episode: which estimate, which truth, which metrics.

Every caller that turns a finished episode into numbers goes through :func:`score_episode`:
the environment's reward (``envs/reverse_stroke.py``), the vector env (``vector/env.py``,
whose workers compute the estimate with :func:`estimate`), the benchmark's rows
(``bench/runner.py``), the trainers' batched episodes (``learning/paired_batch.py``, used by
``ars_residual.py`` and ``dagger.py``) and ``addedinertia demo``. ``tests/test_scoring.py``
fails if one of them calls ``identify()`` or divides by a true lambda66 itself.

Two scores, both from here, named:

* ``"as-written"`` (:data:`AS_WRITTEN`, the benchmark's ranked score and the trainers'): the
  patent's energy method as written, ``identify(records, "energy", asymmetry_correction=False,
  memory="off")``, so that what the controller fails to retrace shows in the estimate;
* ``"corrected"`` (:data:`CORRECTED`, the environment's reward, the vector env, the demo,
  and the benchmark's ``rel_error_corrected``): the project's default identification,
  ``identify(records, "energy")`` (the water's memory identified and corrected for where the
  records show it: A66(0) in memory water; memory-free records unchanged).

The truth is the run records' ``truth`` block's ``lambda66`` (kg m^2), read by
:func:`truth_lambda66` only (run-record.md: A66(0), the zero-frequency added inertia);
records without a truth block (a real bench) have no true value and no error (nan). The
relative error is ``(estimate - truth) / truth``. The metrics are
:func:`~addedinertia_env.experiment.metrics.cycles_metrics` of the records (energy J, tracking RMS rad,
saturated fraction).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from addedinertia_env.identify import IdentificationError, identify
from addedinertia_env.experiment.metrics import cycles_metrics
from addedinertia_env.records.run_record import RecordError, RunRecord

AS_WRITTEN = "as-written"  # the benchmark's ranked score: the energy method as written
CORRECTED = "corrected"  # the project's default identification: the energy method, asymmetry corrected
# the energy method as written, its balance corrected for the work of the water's memory (the memory identified
# from the records): the method as a lab would use it in water that remembers, while what the controller fails
# to retrace still shows (memory-v1). Not identify()'s lambda66 with memory, which is the memory fit's A66(0)
# (the free swing's equation, the same whichever controller drove the stroke): the balance's own value,
# ``lambda66_energy_corrected`` (identify/memory_energy.py), or the balance alone where no memory was found.
MEMORY_CORRECTED = "memory-corrected"
VALUE_KEYS = {MEMORY_CORRECTED: "lambda66_energy_corrected"}  # a score's value from identify()'s details
SCORES: dict[str, dict[str, bool | str]] = {  # name -> identify()'s options of the energy method
    # as written: the patent's balance alone, without the water's memory correction
    AS_WRITTEN: {"asymmetry_correction": False, "memory": "off"},
    CORRECTED: {"asymmetry_correction": True, "memory": "auto"},  # identify()'s default, stated
    MEMORY_CORRECTED: {"asymmetry_correction": False, "memory": "auto"},
}
RANKED = AS_WRITTEN  # what the leaderboard ranks (bench/runner.py SCORE_METHOD)
REWARD = CORRECTED  # what the environment's accuracy term rewards (outside a benchmark suite)
SUITE_REWARD = RANKED  # on a benchmark suite's scenarios it rewards what the leaderboard ranks (issue 28)


def reward_score(suite) -> str:
    """The score whose error the environment's accuracy term rewards: on a benchmark suite
    (``suite`` not None) the ranked one (:data:`RANKED`, so that the terminal reward is the
    episode's leaderboard score, bench/score.py), else :data:`REWARD`."""
    return SUITE_REWARD if suite is not None else REWARD


def _check_score(score: str) -> dict[str, bool | str]:
    if score not in SCORES:
        raise ValueError(f"score {score!r}: expected one of {', '.join(SCORES)}")
    return SCORES[score]


@dataclass(frozen=True)
class Estimate:
    """One score's lambda66 estimate of an episode (kg m^2, with its 95 % interval), or why there is none.

    ``failure``: the identification's refusal (``str`` of the error), ``failure_type`` its class
    name; ``None`` when it succeeded."""

    score: str
    lambda66: float = math.nan
    ci95: tuple[float, float] = (math.nan, math.nan)
    n_intervals: int | None = None
    failure: str | None = None
    failure_type: str | None = None

    @property
    def failed(self) -> bool:
        """True when the identification refused the episode."""
        return self.failure is not None


def estimate(records: Sequence[RunRecord], score: str = CORRECTED) -> Estimate:
    """The ``score`` estimate of lambda66 (kg m^2) from an episode's ``records`` (one or more
    reverse-symmetric cycles, identified jointly). A refusal of the identification or of the
    plausibility check, or a non-finite value, is a failed :class:`Estimate`; other errors raise."""
    options = _check_score(score)
    try:
        result = identify(list(records), "energy", interval_details=False, **options)  # the numbers only
    except (IdentificationError, RecordError) as e:
        return Estimate(score, failure=str(e), failure_type=type(e).__name__)
    value, ci = float(result.lambda66), result.ci95
    key = VALUE_KEYS.get(score)
    if key is not None and key in result.details:
        value, ci = float(result.details[key]), result.details[f"{key}_ci95"]
    if not math.isfinite(value):
        return Estimate(score, failure="identification returned a non-finite lambda66", failure_type="ValueError")
    return Estimate(score, value, (float(ci[0]), float(ci[1])), int(result.n_intervals))


def truth_lambda66(records: Sequence[RunRecord]) -> float:
    """The episode's true lambda66 (kg m^2): its records' ``truth`` block's ``lambda66`` (scoring
    only); nan when they carry no truth (a real bench). Raises ``ValueError`` if the records
    of one episode disagree."""
    values = {rec.truth_lambda66() for rec in records}
    if len(values) != 1:
        raise ValueError(f"episode records {', '.join(r.name for r in records)}: truth lambda66 values {values}; "
                         "expected one episode of one rig (the same truth in every record)")
    value = values.pop()
    return math.nan if value is None else float(value)


def relative_error(lambda66_est: float, lambda66_true: float) -> float:
    """``(estimate - truth) / truth``; nan when either is unknown (not finite)."""
    if not (math.isfinite(lambda66_est) and math.isfinite(lambda66_true)):
        return math.nan
    return (lambda66_est - lambda66_true) / lambda66_true


@dataclass(frozen=True)
class EpisodeScore:
    """An episode's numbers under one score (module doc): estimate and interval (kg m^2), truth
    (kg m^2, nan on a bench), relative error (nan when failed or no truth), the failure, and
    the metrics (J, rad, fraction; nan when not asked for)."""

    score: str
    lambda66_est: float
    ci95: tuple[float, float]
    lambda66_true: float
    rel_error: float
    failure: str | None
    failure_type: str | None
    energy_J: float = math.nan
    tracking_rms_rad: float = math.nan
    saturated_frac: float = math.nan

    @property
    def failed(self) -> bool:
        """True when the identification refused the episode."""
        return self.failure is not None

    def info(self) -> dict:
        """The environment's end-of-episode info keys (``failed``, ``failure``, ``lambda66_est``,
        ``ci95`` as a list, ``lambda66_true``, ``rel_error``, ``energy_J``, ``tracking_rms_rad``,
        ``saturated_frac``)."""
        return {"failed": self.failed, "failure": self.failure or "", "lambda66_est": self.lambda66_est,
                "ci95": list(self.ci95), "lambda66_true": self.lambda66_true, "rel_error": self.rel_error,
                "energy_J": self.energy_J, "tracking_rms_rad": self.tracking_rms_rad,
                "saturated_frac": self.saturated_frac}


def score_episode(records: Sequence[RunRecord], score: str = CORRECTED, *, references=None,
                  metrics: bool = True, estimated: Estimate | None = None) -> EpisodeScore:
    """The ``score`` (``"as-written"`` or ``"corrected"``) of the episode made of ``records``.

    ``references``: each record's mirrored reference, when the caller holds them (metrics;
    else refitted from the records). ``metrics=False`` skips the metrics (nan). ``estimated``:
    the :func:`estimate` of these records under this score, when already computed (the vector
    env computes it in a worker process)."""
    records = list(records)
    if not records:
        raise ValueError("score_episode: no record; expected the episode's run records")
    _check_score(score)
    if estimated is None:
        estimated = estimate(records, score)
    elif estimated.score != score:
        raise ValueError(f"score_episode: an estimate of score {estimated.score!r} given for score {score!r}")
    true = truth_lambda66(records)
    m = cycles_metrics(records, references) if metrics else None
    return EpisodeScore(score=score, lambda66_est=estimated.lambda66, ci95=estimated.ci95, lambda66_true=true,
                        rel_error=relative_error(estimated.lambda66, true), failure=estimated.failure,
                        failure_type=estimated.failure_type,
                        energy_J=m.energy_J if m else math.nan, tracking_rms_rad=m.tracking_rms_rad if m else math.nan,
                        saturated_frac=m.saturated_frac if m else math.nan)
