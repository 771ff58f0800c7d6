"""Episode metrics, computed once, from the run record: what the environment reports at
the end of an episode, what ``bench run`` writes per row and what the identification
checks. One definition of "at the limit" (saturation) serves them all and the reward.

* ``energy_J``: integral of ``|u i|`` over the controlled samples (hold and reverse), J,
  from the measured channels;
* ``tracking_rms_rad``: RMS of ``phi_ref - phi`` on the reverse stroke, rad, with the
  mirrored reference re-fitted from the record's free stroke exactly as the experiment
  fitted it (:func:`stroke_reference`);
* ``saturated_frac``: fraction of the controlled samples whose command was at its limit
  (:func:`current_at_limit`, :func:`voltage_at_limit`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addedinertia_env.experiment.reference import MirroredReference, fit_stroke
from addedinertia_env.records.record import RunRecord
from addedinertia_env.records.record_kernels import masked_limit_count, masked_power_steps, phase_mask

# A command at 99.9 % of its limit or more counts as at the limit (saturated).
SATURATION_FRACTION = 0.999
CONTROLLED_PHASES = ("hold", "reverse")
DEFAULT_LEAD_S = 0.05  # s, ExperimentPlan.lead_s, for records that do not state it


def current_at_limit(i_cmd, i_max):
    """Whether a current command (A; float or array) is at the drive's limit ``i_max`` (A)."""
    return np.abs(i_cmd) >= SATURATION_FRACTION * i_max


def voltage_at_limit(u_cmd, i_measured, u_max, i_max):
    """Whether a voltage command (V) is at the supply ``u_max`` (V), or the measured current
    (A) at or over the drive's limit ``i_max`` (A); floats or arrays."""
    return (np.abs(u_cmd) >= SATURATION_FRACTION * u_max) | (np.abs(i_measured) >= i_max)


@dataclass(frozen=True)
class EpisodeMetrics:
    """The benchmark numbers of one reverse-symmetric run (besides the estimate)."""

    energy_J: float  # J, integral of |u i| over hold and reverse
    tracking_rms_rad: float  # rad, RMS reverse-stroke tracking error; nan without reverse samples
    saturated_frac: float  # -, controlled samples at a limit; 0 without controlled samples


def episode_metrics(rec: RunRecord, reference: MirroredReference | None = None) -> EpisodeMetrics:
    """:class:`EpisodeMetrics` of a reverse-symmetric run record. ``reference``: the mirrored
    reference the experiment drove, when the caller holds it (else it is refitted from the
    record, :func:`stroke_reference`, which gives the same law)."""
    return cycles_metrics([rec], None if reference is None else [reference])


def cycles_metrics(records: list[RunRecord], references: list[MirroredReference] | None = None) -> EpisodeMetrics:
    """:class:`EpisodeMetrics` of an episode of several cycles (one record each): the mean
    energy and saturated fraction per cycle, the tracking RMS over all their samples
    (``references``: each record's reference, as for :func:`episode_metrics`)."""
    if not records:
        raise ValueError("episode metrics of no record")
    refs = references if references is not None else [None] * len(records)
    masks = [controlled(r) for r in records]  # computed once per record
    errors = np.concatenate([tracking_errors(r, ref, m) for r, ref, m in zip(records, refs, masks)])
    return EpisodeMetrics(energy_J=float(np.mean([electric_energy(r, m) for r, m in zip(records, masks)])),
                          tracking_rms_rad=float(np.sqrt(np.mean(np.square(errors)))) if errors.size else math.nan,
                          saturated_frac=float(np.mean([saturated_fraction(r, m) for r, m in zip(records, masks)])))


def controlled(rec: RunRecord) -> np.ndarray:
    """Mask of the controlled samples (hold and reverse): ``phase == "hold"`` or ``"reverse"``
    (:func:`~addedinertia_env.records.record_kernels.phase_mask`)."""
    return phase_mask(rec.phase, CONTROLLED_PHASES)


def electric_energy(rec: RunRecord, mask: np.ndarray | None = None) -> float:
    """Integral of ``|u i|`` over the hold and the reverse stroke, J (measured channels);
    ``mask``: :func:`controlled` of ``rec`` if the caller has it."""
    t, u, i = rec.t, rec["u"], rec["i"]
    mask = controlled(rec) if mask is None else mask
    if (len(t) and all(isinstance(a, np.ndarray) and a.dtype == np.float64 and a.shape == t.shape for a in (t, u, i))
            and t.ndim == 1 and isinstance(mask, np.ndarray) and mask.dtype == bool and mask.shape == t.shape):
        terms = np.empty(np.count_nonzero(mask))  # the terms below, in one compiled pass
        masked_power_steps(t, u, i, mask, terms)
        return float(np.sum(terms))
    dt = np.diff(t, prepend=t[0])
    return float(np.sum(np.abs(u * i)[mask] * dt[mask]))


def samples_at_limit(rec: RunRecord) -> np.ndarray:
    """Per sample: the command at its limit (a current command, or a voltage command)."""
    known = rec.known
    n = len(rec)
    i_cmd = rec.samples.get("i_cmd", np.zeros(n))
    at = current_at_limit(i_cmd, known.current_limit)
    if "u_cmd" in rec.samples:
        u_cmd = rec["u_cmd"]
        u_max = known.u_max if known.u_max is not None else math.inf
        at = at | ((u_cmd != 0.0) & voltage_at_limit(u_cmd, rec["i"], u_max, known.current_limit))
    return at


def saturated_fraction(rec: RunRecord, mask: np.ndarray | None = None) -> float:
    """Fraction of the controlled samples whose command was at its limit; 0 if there are none
    (``mask``: :func:`controlled` of ``rec`` if the caller has it)."""
    mask = controlled(rec) if mask is None else mask
    if not mask.any():
        return 0.0
    counted = _limit_count(rec, mask)
    if counted is not None:  # np.mean of the mask's booleans: their count (exact) over the mask's
        return counted / int(np.count_nonzero(mask))
    return float(np.mean(samples_at_limit(rec)[mask]))


def _limit_count(rec: RunRecord, mask: np.ndarray) -> int | None:
    """``np.count_nonzero(samples_at_limit(rec)[mask])`` in one compiled pass
    (:func:`~addedinertia_env.records.record_kernels.masked_limit_count`) when the columns are 1-D float64 arrays
    of the mask's length and the limits floats; None otherwise (the numpy expressions then run)."""
    n = len(mask)
    columns = [rec.samples.get(name) for name in ("i_cmd", "u_cmd", "i")]
    voltage = columns[1] is not None
    if not voltage:
        columns[1] = columns[2] = columns[0]
    if not (isinstance(mask, np.ndarray) and mask.dtype == bool and mask.ndim == 1 and all(
            isinstance(c, np.ndarray) and c.dtype == np.float64 and c.shape == (n,) for c in columns)):
        return None
    known = rec.known
    i_max = known.current_limit
    u_max = (known.u_max if known.u_max is not None else math.inf) if voltage else math.inf
    if not all(isinstance(x, float) for x in (i_max, u_max)):
        return None
    return int(masked_limit_count(mask, columns[0], SATURATION_FRACTION * i_max, columns[1], columns[2],
                                  SATURATION_FRACTION * u_max, i_max, voltage))


def stroke_reference(rec: RunRecord) -> MirroredReference:
    """The mirrored reference the experiment drove: the free stroke's law fitted, as the
    experiment fits it, from a little before the neutral crossing to the brake."""
    exp, known = rec.experiment, rec.known
    sign = 1.0 if float(exp["alpha"]) > 0 else -1.0
    free = rec.phase == "free"
    crossed = free & (sign * (rec["phi"] - known.phi_neutral) >= 0)
    if not crossed.any():
        raise ValueError(f"{rec.name}: the free stroke never crosses the calibrated neutral")
    t_cross = float(rec.t[np.argmax(crossed)])
    t_brake = float(exp["t_brake"])
    law = fit_stroke(rec.t, rec["phi"], t_cross - float(exp.get("lead_s", DEFAULT_LEAD_S)), t_brake)
    return MirroredReference(law, t_begin=t_brake + float(exp["hold_s"]))


def tracking_errors(rec: RunRecord, reference: MirroredReference | None = None,
                    mask: np.ndarray | None = None) -> np.ndarray:
    """``phi_ref - phi`` (rad) at the controlled samples inside the reverse stroke (``mask``:
    :func:`controlled` of ``rec`` if the caller has it)."""
    ref = reference if reference is not None else stroke_reference(rec)
    t = rec.t
    window = (controlled(rec) if mask is None else mask) & (t > ref.t_begin) & (t <= ref.t_end + 0.5 * rec.known.dt)
    return np.asarray(ref.phi(t[window]), dtype=float) - rec["phi"][window]
