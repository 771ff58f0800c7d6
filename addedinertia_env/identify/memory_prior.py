"""The hull's BEM cache as a prior on the water's memory model (``identify --prior bem``).

By default the memory is identified from the records alone (``prior: "none"``,
:func:`~addedinertia_env.identify.memory.identify_memory`). Asked for, the BEM's own memory
model (the cache's ``memory_model`` block, ``addedinertia hull PRESET --fit-memory``) lends
the kernel's *shape*: its poles are fitted as one more family, fixed, with the coefficients
(so A66(inf), A66(0) and A66 at the swing) from the records, and without an instantaneous
part (a potential-flow kernel). Where the records accept that shape (passive, within the
families' residual tolerance) it is the reported model and its interval is its own; where
they do not, the records alone decide and the JSON says why (``memory_model.prior_note``).
The result states ``prior: "bem"`` either way.

Which cache: ``bem_cache`` (a path), else the preset the records name
(``experiment.simulate.rig``, or ``experiment.hull``) in ``configs/rigs``; a missing one is
refused by name (IdentificationError).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from addedinertia_env.identify.common import IdentificationError
from addedinertia_env.identify.memory import MemoryIdentification, PriorKernel, identify_memory
from addedinertia_env.records.record import RunRecord


def _preset_named(records: list[RunRecord]) -> str | None:
    for rec in records:
        exp = rec.experiment or {}
        name = (exp.get("simulate") or {}).get("rig") or exp.get("hull")
        if name:
            return str(name)
    return None


def bem_prior(records: list[RunRecord], bem_cache: str | Path | None = None) -> PriorKernel:
    """The BEM cache's memory poles as a :class:`PriorKernel` (see the module doc for which cache)."""
    from addedinertia_env.hydro.radiation import CumminsModel, HydrodynamicsError  # noqa: PLC0415
    from addedinertia_env.hydro.study import cache_path  # noqa: PLC0415

    names = ", ".join(r.name for r in records)
    if bem_cache is None:
        preset = _preset_named(records)
        if preset is None:
            raise IdentificationError(f"--prior bem on {names}: no BEM cache given and the records name no hull "
                                      "(experiment.simulate.rig or experiment.hull); expected --bem-cache PATH.bem.json")
        bem_cache = cache_path(preset)
        named = f" (the cache of the hull the records name, {preset!r})"
    else:
        named = ""
    path = Path(bem_cache)
    try:
        block = json.loads(path.read_text()).get("memory_model")
    except (OSError, ValueError) as e:
        raise IdentificationError(f"--prior bem on {names}: {path}{named}: {type(e).__name__}: "
                                  f"{getattr(e, 'strerror', None) or e}; expected a BEM cache written by "
                                  "'addedinertia hull PRESET' (or --bem-cache PATH.bem.json)") from None
    if not isinstance(block, dict):
        raise IdentificationError(f"--prior bem: {path}: field 'memory_model' missing; expected the block written "
                                  "by 'addedinertia hull PRESET --fit-memory'")
    try:
        model = CumminsModel.from_block(block, str(path))
    except HydrodynamicsError as e:
        raise IdentificationError(f"--prior bem: {e}") from None
    poles = np.linalg.eigvals(np.asarray(model.A))
    sections: list[tuple] = []
    for p in sorted(poles, key=lambda z: (abs(z), -z.imag)):
        if abs(p.imag) < 1e-9 * max(abs(p), 1.0):
            sections.append(("r", float(-p.real)))
        elif p.imag > 0:
            wn = float(abs(p))
            sections.append(("c", wn, float(-p.real / wn)))
    # a potential-flow kernel: no instantaneous part beyond the cache's rounding-size feedthrough
    strict = model.d * 1.0 < 1e-3 * max(float(np.max(np.abs(model.c))), 1e-12) or not math.isfinite(model.d)
    return PriorKernel("bem", tuple(sections), bool(strict), str(path))


def identify_memory_with_prior(records: list[RunRecord], prior: str = "none",
                               bem_cache: str | Path | None = None) -> MemoryIdentification:
    """:func:`~addedinertia_env.identify.memory.identify_memory` with ``prior`` ``"none"`` (the records
    alone) or ``"bem"`` (the hull's BEM cache, :func:`bem_prior`)."""
    if prior == "none":
        return identify_memory(records)
    if prior != "bem":
        raise ValueError(f"prior={prior!r}; expected 'none' or 'bem'")
    kernel = bem_prior(records, bem_cache)
    mem = identify_memory(records, prior=kernel)
    if mem.prior != "bem":  # the records could not be read for memory at all: say the prior was asked for
        mem.prior, mem.prior_note = "bem", f"{kernel.source}: not used ({mem.status})"
    return mem
