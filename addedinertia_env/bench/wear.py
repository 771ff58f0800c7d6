"""Wear of an episode: how often the motor current changes sign and how much it chatters.

A lab pays for a controller's plan in its drive too: every reversal of the current crosses
a gearbox's backlash and loads the bearings both ways, and a command that swings from
sample to sample (chatter) heats the winding and rattles the mesh. Both are counted on
the commanded current ``i_cmd`` (what the controller asked for, free of sensor noise)
over the controlled samples (hold and reverse stroke, :func:`~..metrics.controlled`):

* ``current_sign_changes``: the number of times the command crosses from above ``+band``
  to below ``-band`` or back (a Schmitt trigger; ``band`` = :data:`SIGN_BAND_FRACTION` of
  the current limit, so quantisation and dithering around zero are not counted);
* ``chatter_A``: the RMS of the command's sample-to-sample change, A; a smooth plan
  (feed-forward with slow feedback) has about ``i_peak / samples per stroke``, a command
  that swings by +-5 A at the sample rate about 10 A.

An episode of several cycles reports the mean per cycle.
"""

from __future__ import annotations

import math

import numpy as np

from addedinertia_env.experiment.metrics import controlled

SIGN_BAND_FRACTION = 0.02  # of i_max: the hysteresis band of a sign change


def sign_changes(i: np.ndarray, band: float) -> int:
    """Sign changes of ``i`` (A) with hysteresis ``band`` (A): crossings from above ``+band`` to
    below ``-band`` or back; samples inside the band keep the last sign."""
    s = np.where(i > band, 1, np.where(i < -band, -1, 0))
    s = s[s != 0]
    return int(np.count_nonzero(s[1:] != s[:-1])) if s.size > 1 else 0


def record_wear(rec, i_max: float | None) -> tuple[int, float]:
    """``(current_sign_changes, chatter_A)`` of one record (module doc); ``i_max`` in A (None:
    the band is 2 % of the largest commanded current)."""
    mask = controlled(rec)
    i = np.asarray(rec["i_cmd"] if "i_cmd" in rec.samples else rec["i"], float)[mask]
    if i.size < 2:
        return 0, 0.0
    limit = i_max if i_max is not None and math.isfinite(i_max) else float(np.max(np.abs(i)))
    return sign_changes(i, SIGN_BAND_FRACTION * limit), float(np.sqrt(np.mean(np.square(np.diff(i)))))


def episode_wear(records: list, i_max: float | None) -> dict[str, float]:
    """The row fields ``current_sign_changes`` and ``chatter_A`` of an episode: means over its cycles."""
    pairs = [record_wear(r, i_max) for r in records]
    return {"current_sign_changes": float(np.mean([p[0] for p in pairs])),
            "chatter_A": float(np.mean([p[1] for p in pairs]))}
