"""The ranking of a leaderboard: the score, and the stated rule for ties.

Score (:mod:`.score`, version ``score.SCORE_VERSION``). An entry's ranked score is the
mean over the split's scenarios of the capped error ``min(|e|, CAP)``, a failure counting
``CAP`` (10 %): ``e`` is the relative lambda66 error of the energy method as written, the
error a lab would publish. The paired control error ``|e_entry - e_oracle|``
(:mod:`.paired`) is reported beside it, not ranked: where the drive's flaws bias the
method, a plan that avoids the bias beats perfect tracking. Rows older than the score
(entries without ``mean_score``) are ranked as before: median control error with
``oracle`` rows, else median ``|e|``.

Tie rule. Entries are sorted by score (then IQM, failure rate, name). Walking down that
order, an entry whose paired 95 % interval of ``s_entry - s_leader`` (mean over the
common scenarios, :func:`.score.difference`) includes zero is tied with the leader of the
current group and joins it; otherwise it leads a new group. The entries of
a group share its rank (shown as ``1=``) and are listed by median energy
``integral |u i| dt`` (less first): between controllers that cannot be told apart on
accuracy, the one that spends less is listed first. The group's leader (its lowest score)
is the one the verdict tests against the oracle and ``zero``.

References (``oracle``, ``zero``) are shown in score order among the entries but take no
rank (``rank`` is None).
"""

from __future__ import annotations

import math
from typing import Any

from addedinertia_env.bench import paired
from addedinertia_env.bench import score as capped


def score(e: dict[str, Any]) -> float:
    """The ranked score of an entry (module doc)."""
    if e.get("mean_score") is not None:
        return float(e["mean_score"])
    if e.get("median_abs_control_error") is not None:
        return float(e["median_abs_control_error"])
    return float(e["median_abs_error"])


def tied(a: dict[str, Any], b: dict[str, Any], n_boot: int = 2000, seed: int = 0) -> bool:
    """True when ``a`` and ``b`` cannot be told apart on accuracy (module doc)."""
    if a.get("scenario_scores") is not None and b.get("scenario_scores") is not None:
        d = capped.difference(b["scenario_scores"], a["scenario_scores"], n_boot=n_boot, seed=seed)
        return d["n"] > 0 and capped.clearly(d) == 0
    if a.get("control_errors") is not None and b.get("control_errors") is not None:
        d = paired.difference(b["control_errors"], a["control_errors"], n_boot=n_boot, seed=seed)
        return d["n"] > 0 and paired.clearly(d) == 0
    (alo, ahi), (blo, bhi) = a["ci95_median"], b["ci95_median"]
    return not (ahi < blo or bhi < alo)


def rank(entries: list[dict[str, Any]], n_boot: int = 2000, seed: int = 0) -> list[dict[str, Any]]:
    """``entries`` in display order with ``rank`` (shared within a tie group), ``tied``,
    ``group_leader`` and ``score`` set (module doc)."""
    def key(e):
        return (score(e), e["iqm_abs_error"], e["failure_rate"], e["controller"])

    for e in entries:
        e["score"] = score(e)
    refs = sorted((e for e in entries if e["kind"] == "reference"), key=key)
    ranked = sorted((e for e in entries if e["kind"] != "reference"), key=key)
    groups: list[list[dict]] = []
    for e in ranked:
        if groups and tied(groups[-1][0], e, n_boot=n_boot, seed=seed):
            groups[-1].append(e)
        else:
            groups.append([e])
    ordered = []
    for g, members in enumerate(groups, 1):
        for e in members:
            e["rank"], e["tie_group"], e["tied"], e["group_leader"] = g, g, len(members) > 1, e is members[0]
        members.sort(key=lambda e: (_energy(e), key(e)))
        ordered += members
    for e in refs:
        e["rank"], e["tie_group"], e["tied"], e["group_leader"] = None, None, False, False
    # references merged in by score, for display
    out: list[dict] = []
    pending = list(refs)
    for e in ordered:
        while pending and score(pending[0]) <= (score(e) if not e["tied"] else _group_score(ordered, e)):
            out.append(pending.pop(0))
        out.append(e)
    return out + pending


def _group_score(ordered: list[dict], e: dict) -> float:
    return min(score(x) for x in ordered if x["tie_group"] == e["tie_group"])


def best(entries: list[dict[str, Any]], kind: str | None = None) -> dict[str, Any] | None:
    """The best ranked entry (of ``kind`` if given): lowest rank, then lowest score."""
    pool = [e for e in entries if e.get("rank") is not None and (kind is None or e.get("kind") == kind)]
    return min(pool, key=lambda e: (e["rank"], score(e))) if pool else None


def _energy(e: dict[str, Any]) -> float:
    v = e.get("median_energy_J")
    return v if v is not None and math.isfinite(v) else math.inf
