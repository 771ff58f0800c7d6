"""Identification of lambda66 from run records.

Methods: ``energy`` (the patent's), ``free-decay`` (the textbook's), ``forced`` (the
Chinese patent's), ``whole-record`` (gray-box fit). :func:`identify` dispatches by name.
"""

from __future__ import annotations

import importlib

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.identify.common import IdentificationError, Result, check_physical

METHODS = {
    "energy": "addedinertia_env.identify.energy:identify_energy",
    "free-decay": "addedinertia_env.identify.free_decay:identify_free_decay",
    "forced": "addedinertia_env.identify.forced:identify_forced",
    "whole-record": "addedinertia_env.discover.whole_record:identify_whole_record",
}


PRIORS = ("none", "bem")  # what the memory model may lean on besides the records (identify --prior)


def identify(records: list[RunRecord], method: str = "energy", **options) -> Result:
    """lambda66 by ``method`` from ``records``: each record is first checked against its own rig
    (:mod:`addedinertia_env.records.plausibility`, once per record: ``record.views.limits``; the methods read
    the same views), and a physically impossible result is refused
    (:func:`~addedinertia_env.identify.common.check_physical`); both raise with the file names.

    ``memory`` (energy and whole-record methods): ``"auto"`` (or True; the CLI's default ``--memory auto``)
    identifies the water's radiation memory from the records and corrects for it, so that lambda66 is A66(0)
    (docs/RADIATION_MEMORY.md); memory-free records give ``memory: "none"`` and unchanged numbers. The default,
    as on the command line (it was ``"off"`` in Python while a stiffening spring could be taken for memory and the
    result then moved by 6.8e-7 between BLAS kernels; tests/test_same_numbers_any_cpu.py runs memory auto).
    ``"off"`` (or False): the method alone (the method as written, the "before" of the docs' tables). ``prior``: ``"none"`` (the default: the records alone) or ``"bem"``: the
    hull's BEM cache (``bem_cache``, a path; default the cache of the preset the records name) as a prior on
    the memory model (:mod:`~addedinertia_env.identify.memory_prior`); stated in the result as ``prior``."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    # The plausibility check, once per record: the reader ran it, or it runs here for a record made
    # in memory (a benchmark episode); a refusal raises RecordError.
    for rec in records:
        rec.views.limits  # noqa: B018
    from addedinertia_env.records.consistency import check_momentum_consistent  # noqa: PLC0415

    for rec in records:  # the angles against the current: a record in degrees is refused here
        check_momentum_consistent(rec)
    module, _, func = METHODS[method].partition(":")
    estimator = getattr(importlib.import_module(module), func)
    memory = options.pop("memory", "auto")
    if memory not in (False, True, "auto", "off"):
        raise ValueError(f"identify(): memory={memory!r}; expected 'auto' (the default), 'off', True or False")
    memory = memory in (True, "auto")
    prior = options.pop("prior", "none")
    if prior not in PRIORS:
        raise ValueError(f"identify(): prior={prior!r}; expected one of {', '.join(map(repr, PRIORS))}")
    bem_cache = options.pop("bem_cache", None)
    if method == "whole-record" and memory:  # the gray-box model carries the identified memory's state
        from addedinertia_env.identify.memory_prior import identify_memory_with_prior  # noqa: PLC0415

        options["memory"] = identify_memory_with_prior([r.without_truth() for r in records], prior, bem_cache)
    forced = []
    if method == "energy" and memory:
        # forced runs beside reverse runs: A66 at their frequencies, evidence about the memory (forced_memory.py)
        forced = [r for r in records if r.experiment.get("kind") == "forced-oscillation"]
        if forced and len(forced) < len(records):
            records = [r for r in records if r.experiment.get("kind") != "forced-oscillation"]
        else:
            forced = []
    all_records, used = records, list(range(len(records)))
    if method == "energy":  # free decays beside reverse runs: read for the water's memory, not refused
        decays = [k for k, r in enumerate(records) if r.experiment.get("kind") == "free-decay"]
        if decays and len(decays) < len(records):
            used = [k for k in used if k not in decays]
            records = [records[k] for k in used]
    try:
        result = estimator([r.without_truth() for r in records], **options)
    except IdentificationError as e:  # every refusal names the records it is about
        names = [r.name for r in records]
        if not any(n in str(e) for n in names):
            raise IdentificationError(f"{method} method on {', '.join(names)}: {e}") from None
        raise
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeWarning) as e:  # warnings: when made errors
        # A numerical failure on data the checks let through (a fit whose residuals are not
        # finite, a singular system): the method cannot use these records, which is a refusal.
        names = ", ".join(r.name for r in records)
        raise IdentificationError(f"{method} method on {names}: the records could not be analysed "
                                  f"({type(e).__name__}: {' '.join(str(e).split())[:200]}); expected records "
                                  "sampled evenly enough for the method, without long gaps in the strokes") from None
    result = check_physical(result, records)
    if method == "energy":
        if len(used) < len(all_records):
            result.details["records_for_memory_only"] = [r.name for k, r in enumerate(all_records) if k not in used]
        if memory:
            from addedinertia_env.identify.memory_energy import FRACTIONS, with_memory  # noqa: PLC0415

            result = with_memory(result, [r.without_truth() for r in all_records], [r.without_truth() for r in records],
                                 prior=prior, bem_cache=bem_cache, fractions=options.get("fractions", FRACTIONS))
        if forced:
            from addedinertia_env.identify.forced_memory import with_forced  # noqa: PLC0415

            result = with_forced(result, [r.without_truth() for r in forced])
    return result


__all__ = ["IdentificationError", "METHODS", "Result", "identify"]
