"""The leaderboard's verdict: sentences computed from the ranked entries, never written by hand.

With reference rows (simulated suites) the verdict first says whether the suite can judge
controllers at all. It is *discriminating* when both hold:

* ``zero`` is clearly worse than the best entry on the ranked score (the error a lab would
  publish, :mod:`.score`): the paired 95 % interval of the mean score difference lies above
  zero (rows without per-scenario scores: the paired interval of ``|c_zero| - |c_best|`` in
  control error). Not on control error alone: where the method is biased (a memory, a drive's
  losses) the oracle is no floor, and no control can read closer to the truth than tracking;
* the best entry is clearly above the oracle: the paired 95 % interval of its median
  control error ``|c_best|`` excludes zero, i.e. there is measured headroom for a better
  controller.

Otherwise it is labelled NON-DISCRIMINATING, with the numbers. The size of the headroom is
stated beside it, and called small when the median control error is below
:data:`SMALL_HEADROOM` (0.1 % of lambda66, a tenth of the 1 % target): statistically
clear, but a better controller could then gain the measurement little. Then: the best classical
entry against the 1 % target and the bare ``pd`` baseline, every learned entry against the
best classical one (paired tests), and a warning for any interval that rests on fewer
than :data:`MIN_EPISODES` episodes.
"""

from __future__ import annotations

import math
from typing import Any

from addedinertia_env.bench import paired, ranking

SMALL_HEADROOM = 0.001  # relative lambda66: a tenth of the target; headroom below it is called small
MIN_EPISODES = 10  # a bootstrap interval on fewer episodes is flagged
TARGET = 0.01  # relative lambda66: the accuracy the experiment is for


def pct(x: float | None) -> str:
    """A fraction as a percentage for the tables: ``-`` for none or NaN, ``fail`` for infinite, never a non-zero shown as 0.000 %."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if not math.isfinite(x):
        return "fail"
    return f"{100 * x:.1e} %" if 0 < abs(x) < 5e-6 else f"{100 * x:.3f} %"  # never print a non-zero as 0.000


def _ci(ci) -> str:
    return f"{pct(ci[0])} .. {pct(ci[1])}" if ci else "-"


def _diff_text(d: dict[str, Any]) -> str:
    p = d["p_wilcoxon"]
    return (f"median paired difference {pct(d['median'])} (95 % CI {_ci(d['ci95'])}, n = {d['n']}, "
            f"Wilcoxon p = {p:.2g})" if math.isfinite(p) else
            f"median paired difference {pct(d['median'])} (95 % CI {_ci(d['ci95'])}, n = {d['n']})")


def discrimination(entries: list[dict]) -> dict[str, Any] | None:
    """The two tests of the module doc, with their numbers; None without reference rows."""
    by = {e["controller"]: e for e in entries}
    best = ranking.best(entries)
    if "oracle" not in by or best is None or best.get("control_errors") is None:
        return None
    out: dict[str, Any] = {"best": best["controller"], "best_control_error": best["median_abs_control_error"],
                           "best_ci95": best["ci95_control_error"], "small_headroom": SMALL_HEADROOM}
    out["above_oracle"] = best["ci95_control_error"][0] > 0.0
    out["headroom_small"] = best["median_abs_control_error"] < SMALL_HEADROOM
    zero = by.get("zero")
    if zero is not None and zero.get("control_errors") is not None:
        d = paired.difference(zero["control_errors"], best["control_errors"])
        out["zero_vs_best"] = d
        if zero.get("scenario_scores") is not None and best.get("scenario_scores") is not None:
            from addedinertia_env.bench import score  # noqa: PLC0415

            on_score = score.difference(zero["scenario_scores"], best["scenario_scores"])
            out["zero_vs_best_score"] = on_score
            out["zero_worse"] = score.clearly(on_score) > 0
        else:
            out["zero_worse"] = paired.clearly(d) > 0
    else:
        out["zero_vs_best"], out["zero_worse"] = None, None
    out["discriminating"] = bool(out["above_oracle"] and out["zero_worse"])
    return out


def verdict(entries: list[dict], baseline: str = "pd", target: float = TARGET) -> list[str]:
    """Markdown bullet sentences (module doc)."""
    out: list[str] = []
    disc = discrimination(entries)
    if disc is not None:
        best = disc["best"]
        z = disc["zero_vs_best"]
        size = (f"a small headroom: below {pct(SMALL_HEADROOM)}, a tenth of the {pct(TARGET)} target, so a better "
                "controller could gain the measurement little" if disc["headroom_small"] else
                f"a headroom of at least a tenth of the {pct(TARGET)} target")
        above = (f"`{best}` sits clearly above the oracle: median control error {pct(disc['best_control_error'])}, "
                 f"paired 95 % CI {_ci(disc['best_ci95'])}, excluding zero ({size})"
                 if disc["above_oracle"] else
                 f"`{best}` is NOT clearly above the oracle: median control error {pct(disc['best_control_error'])}, "
                 f"paired 95 % CI {_ci(disc['best_ci95'])}, includes zero (no measured headroom for a better "
                 "controller)")
        zs = disc.get("zero_vs_best_score")
        how = (f"on the ranked score, mean paired difference {pct(zs['mean'])} (95 % CI {_ci(zs['ci95'])}, n = {zs['n']})"
               if zs is not None else (_diff_text(z) if z is not None else ""))
        if z is None:
            zero = "no `zero` rows, so no-control cannot be compared"
        elif disc["zero_worse"]:
            zero = f"`zero` (no control) is clearly worse than `{best}`: {how}"
        else:
            zero = f"`zero` (no control) is NOT clearly worse than `{best}`: {how}"
        label = ("**NON-DISCRIMINATING**" if not disc["discriminating"] else
                 "**Discriminating, small headroom**" if disc["headroom_small"] else "**Discriminating**")
        out.append(f"- {label}: {above}; {zero}.")
        zero_e, best_e = next((e for e in entries if e["controller"] == "zero"), None), ranking.best(entries)
        if zero_e is not None and best_e is not None and zero_e.get("scenario_scores") and best_e.get("scenario_scores"):
            out.append(f"- `zero` against `{best_e['controller']}`: " + compare(zero_e, best_e) + ".")
    best = ranking.best(entries, "classical")
    learned = [e for e in entries if e.get("kind") == "learned" and e.get("rank") is not None]
    if best is not None:
        meets = "meets" if best["median_abs_error"] <= target else "does not meet"
        out.append(f"- Best classical entry: `{best['controller']}` (rank {rank_text(best)}); its median |error| "
                   f"(method as written) is {pct(best['median_abs_error'])}, so it {meets} the "
                   f"{100 * target:.0f} % target.")
        base = next((e for e in entries if e["controller"] == baseline), None)
        if base is not None and base is not best:
            out.append(f"- Against the bare `{baseline}` baseline: " + compare(best, base) + ".")
        for e in learned:
            cost = training_cost(e)
            out.append(f"- Learned `{e['controller']}` (trained with {cost}) against `{best['controller']}`: "
                       + compare(e, best) + ".")
    few = [e for e in entries if min(e["episodes"], e.get("n_paired") or e["episodes"]) < MIN_EPISODES]
    if few:
        names = ", ".join(f"`{e['controller']}` ({min(e['episodes'], e.get('n_paired') or e['episodes'])})"
                          for e in few)
        out.append(f"- **Warning**: intervals resting on fewer than {MIN_EPISODES} episodes: {names}; "
                   "they are wide and unreliable.")
    return out


def rank_text(e: dict) -> str:
    """``ref``, ``3`` or ``1=`` (shared by a tie group)."""
    if e.get("rank") is None:
        return "ref"
    return f"{e['rank']}=" if e.get("tied") else str(e["rank"])


def compare(a: dict, b: dict) -> str:
    """``a`` against ``b``: on the ranked score (paired mean difference of capped errors, :mod:`.score`)
    when both have it, with the paired control-error test beside it; else on control errors, else
    overlap of the intervals."""
    if a.get("scenario_scores") is not None and b.get("scenario_scores") is not None:
        from addedinertia_env.bench import score  # noqa: PLC0415

        d = score.difference(a["scenario_scores"], b["scenario_scores"])
        side = score.clearly(d)
        head = {1: f"`{a['controller']}` is clearly worse", -1: f"`{a['controller']}` is clearly better",
                0: "no difference can be claimed"}[side]
        text = (f"{head} on the ranked score (mean paired difference {pct(d['mean'])}, 95 % CI {_ci(d['ci95'])}, "
                f"n = {d['n']})")
        if a.get("control_errors") is not None and b.get("control_errors") is not None:
            text += f"; beside it, {_diff_text(paired.difference(a['control_errors'], b['control_errors']))} in |control error|"
        return text
    if a.get("control_errors") is not None and b.get("control_errors") is not None:
        d = paired.difference(a["control_errors"], b["control_errors"])
        side = paired.clearly(d)
        head = {1: f"`{a['controller']}` is clearly worse", -1: f"`{a['controller']}` is clearly better",
                0: "no difference can be claimed"}[side]
        return f"{head} ({_diff_text(d)} in |control error|)"
    (alo, ahi), (blo, bhi) = a["ci95_median"], b["ci95_median"]
    if ahi < blo:
        return f"`{a['controller']}` is better, the 95 % intervals of the medians do not overlap"
    if bhi < alo:
        return f"`{a['controller']}` is worse, the 95 % intervals of the medians do not overlap"
    return ("no difference can be claimed: the 95 % intervals of the medians overlap "
            f"({pct(alo)} .. {pct(ahi)} against {pct(blo)} .. {pct(bhi)})")


def training_cost(e: dict) -> str:
    """Environment steps and CPU minutes that trained a learned entry; '-' when none declared."""
    steps, minutes = e.get("train_env_steps"), e.get("train_cpu_minutes")
    if steps is None and minutes is None:
        return "-"
    parts = [f"{steps} env steps" if steps is not None else "", f"{minutes:.1f} CPU min" if minutes is not None else ""]
    return ", ".join(p for p in parts if p)
