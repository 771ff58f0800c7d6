"""Discovery's ``radiation_memory`` candidate: the water's inertia depends on frequency.

The gray-box model of :mod:`.model` carries one added inertia; water that remembers (a
radiation kernel, physics.md section 6) leaves residuals it cannot explain, which it calls
``unexplained`` or misnames. This candidate fits the hull's own equation with a low-order
passive memory (:mod:`addedinertia_env.identify.memory`) and names ``radiation_memory``
when, on the same records,

* a passive memory model leaves less than :data:`MAX_RSS_RATIO` of the memory-free
  model's residual (the memory-free model *includes* a free lambda66, so a plain change of
  lambda66 is not memory), and
* the memory is large: ``(A66(0) - A66(inf)) / A66(0)`` at least :data:`MIN_SIZE` with
  its interval clear of it (a surface hull's is about 0.5; physics.md section 6), and
* its time scale is the water's radiation (every pole faster than :data:`MIN_POLE` rad/s):
  ``fluid_memory``, the lag of the viscous drag, lives at seconds to tens of seconds.

Memory-free records (``none``, or any other single effect) leave the memory model
nothing to explain and are left to the gray-box candidates. Never reads ``truth``.

For model selection over effect combinations (issue 27): :func:`candidate` returns the
evidence as a dict (``named``, ``size``, ``rss_ratio``, ``family``, ``why``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from addedinertia_env.records.record import RunRecord

NAME = "radiation_memory"
MAX_RSS_RATIO = 0.05  # as identify.memory.MEMORY_RSS_RATIO
MIN_SIZE = 0.10
MIN_POLE = 1.0  # rad/s: the free surface's kernel dies within about 2 s (physics.md section 6)


def candidate(records: list[RunRecord], memory=None) -> dict[str, Any]:
    """The ``radiation_memory`` evidence from ``records`` (``memory``: an identification already made)."""
    from addedinertia_env.identify.memory import identify_memory  # noqa: PLC0415

    mem = memory if memory is not None else identify_memory([r.without_truth() for r in records])
    out: dict[str, Any] = {"cause": NAME, "named": False, "status": mem.status, "rss_memory_free": mem.rss_none}
    if not mem.identified:
        out["why"] = f"memory {mem.status}"
        return out
    best = mem.best
    size = (best.A_zero - best.A_inf) / best.A_zero
    size_lo = (best.A_zero - mem.ci95["A66_inf"][1]) / best.A_zero
    ratio = best.rss / mem.rss_none if mem.rss_none > 0 else 1.0
    slowest = min(sec[1] for sec in best.sections)
    out.update({"family": best.family, "size": size, "size_low": size_lo, "rss_ratio": ratio,
                "slowest_pole_rad_s": slowest, "A66_zero": best.A_zero, "A66_inf": best.A_inf,
                "A66_swing": best.A_swing})
    if ratio > MAX_RSS_RATIO:
        out["why"] = f"the memory explains too little ({ratio:.2f} of the memory-free residual left)"
    elif size_lo < MIN_SIZE:
        out["why"] = f"(A66(0) - A66(inf))/A66(0) = {size:.3f}, not clear of {MIN_SIZE}"
    elif slowest < MIN_POLE:
        out["why"] = f"a pole at {slowest:.2f} rad/s: a slow lag, not the free surface's radiation"
    else:
        out["named"] = True
        out["flywheel_effects"], out["flywheel_balance"] = flywheel_effects(records)
        out["why"] = (f"a passive memory ({best.family}) leaves {ratio:.3f} of the memory-free residual; "
                      f"A66(inf)/A66(0) = {best.A_inf / best.A_zero:.3f}")
    return out


def merge(cause: str, causes: list[str], evidence: dict[str, Any]) -> tuple[str, list[str]]:
    """The verdict with ``radiation_memory`` added where its evidence names it: it becomes the
    cause (the effect that matters most: several per cent of lambda66); a second effect the
    gray-box model accepted is kept beside it, except ``fluid_memory``, which is how the
    gray-box model reads water whose inertia lags (one memory, not two)."""
    if not evidence.get("named"):
        return cause, causes
    others = [c for c in causes if c not in (NAME, "fluid_memory")]
    others += [w for w in evidence.get("flywheel_effects", []) if w not in others]
    return NAME, [NAME] + others[:1]


def flywheel_effects(records: list[RunRecord]) -> tuple[list[str], dict[str, Any]]:
    """Effects of the drive that the flywheel's own balance ``J_f theta'' = s k_t i(t - lag) - M_f``
    shows, judged on it alone: no water enters it, so water that remembers (whose misfit swamps the
    gray-box model's hull residuals) cannot hide them (PHYSICS.md section 8). ``torque_constant``
    where every reverse run's torque scale ``s`` is off 1 by the effect's smallest size (the
    registry's ``min_size``) on the same side, ``sensor_delay`` likewise for the lag; returns the
    words and the per-run scales and lags (the energy method's calibration,
    :func:`addedinertia_env.identify.energy_calibration.flywheel_calibration`)."""
    from addedinertia_env.identify.common import IdentificationError  # noqa: PLC0415
    from addedinertia_env.identify.energy_balance import RunBalance  # noqa: PLC0415
    from addedinertia_env.sim.effects import registry  # noqa: PLC0415

    scales, lags = [], []
    for rec in records:
        if rec.experiment.get("kind") == "free-decay":
            continue
        try:
            balance = RunBalance(rec.without_truth(), "reaction", False)
        except (IdentificationError, ValueError):
            continue
        # (1, 0): no calibration was possible; a scale fitted alone at the current's sampling rule (scale_sigma) is
        # not the lag-and-scale calibration these words judge
        if getattr(balance, "scale_sigma", None) is None and (balance.torque_scale, balance.current_lag) != (1.0, 0.0):
            scales.append(balance.torque_scale)
            lags.append(balance.current_lag)
    words = []
    for word, values, neutral in (("torque_constant", scales, 1.0), ("sensor_delay", lags, 0.0)):
        if word not in registry.effect_names() or not values:
            continue
        off = np.asarray(values) - neutral
        if np.all(np.abs(off) >= registry.get(word).min_size) and (np.all(off > 0) or np.all(off < 0)):
            words.append(word)
    return words, {"torque_scales": scales, "current_lags_s": lags}
