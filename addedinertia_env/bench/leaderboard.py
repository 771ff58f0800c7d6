"""Rank controllers from benchmark rows: median |error|, IQM, bootstrap interval, failures, energy.

Statistics per controller, over its episodes (rows), on ``|rel_error|``:

* a failed episode (``rel_error`` null) counts as an infinite error, so failures rank
  a controller down rather than vanish from its median;
* ``median`` and its 95 % bootstrap interval: percentile interval of the medians of
  ``n_boot`` resamples with replacement (fixed seed; order statistics, no interpolation);
* ``iqm``: mean of the middle 50 % of the sorted errors (interquartile mean, as in
  Agarwal et al. 2021, "Deep RL at the edge of the statistical precipice");
* ``failure_rate``, median ``energy_J`` and median ``tracking_rms_rad``.

Controllers are ranked by median, then IQM, then failure rate.
"""

from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .runner import REQUIRED_FIELDS


class RowsError(ValueError):
    """A benchmark rows file that cannot be used."""


def load_rows(paths: list[str | Path]) -> list[dict[str, Any]]:
    rows = []
    for path in paths:
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such rows file (make it with `addedinertia bench run --out {path}`)")
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError as e:
                raise RowsError(f"{path}:{n}: not a JSON line ({e})") from None
            missing = [k for k in REQUIRED_FIELDS if k not in row]
            if missing:
                raise RowsError(f"{path}:{n}: missing field(s) {missing}; a bench row needs {list(REQUIRED_FIELDS)}")
            rows.append(row)
    if not rows:
        raise RowsError(f"no rows in {[str(p) for p in paths]}")
    return rows


def abs_errors(rows: list[dict]) -> np.ndarray:
    """``|rel_error|`` per row; failures are ``inf``."""
    return np.array([abs(r["rel_error"]) if r.get("rel_error") is not None else math.inf for r in rows])


def iqm(x: np.ndarray) -> float:
    """Interquartile mean: mean of the sorted values from n/4 to 3n/4 (fractional ends weighted)."""
    x = np.sort(np.asarray(x, float))
    n = len(x)
    if n == 0:
        return math.nan
    lo, hi = n / 4.0, 3.0 * n / 4.0
    total, weight = 0.0, 0.0
    for k in range(n):
        w = max(0.0, min(k + 1, hi) - max(k, lo))
        if w > 0:
            total += w * x[k]
            weight += w
    return float(total / weight)


def bootstrap_median_ci(x: np.ndarray, n_boot: int = 2000, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the median (works with ``inf`` entries)."""
    x = np.asarray(x, float)
    rng = np.random.default_rng(seed)
    samples = x[rng.integers(0, len(x), size=(n_boot, len(x)))]
    samples.sort(axis=1)
    n = len(x)
    meds = np.where(n % 2 == 1, samples[:, n // 2],
                    0.5 * samples[:, (n - 1) // 2] + 0.5 * samples[:, n // 2]) if n > 1 else samples[:, 0]
    a = (1.0 - level) / 2.0
    return (float(np.quantile(meds, a, method="inverted_cdf")),
            float(np.quantile(meds, 1.0 - a, method="inverted_cdf")))


def summarise(rows: list[dict], n_boot: int = 2000, seed: int = 0) -> list[dict[str, Any]]:
    """One ranked entry per controller (see module doc)."""
    by: dict[str, list[dict]] = {}
    for r in rows:
        by.setdefault(r["controller"], []).append(r)
    out = []
    for name, rs in by.items():
        err = abs_errors(rs)
        lo, hi = bootstrap_median_ci(err, n_boot=n_boot, seed=seed)
        energy = [r["energy_J"] for r in rs if r.get("energy_J") is not None]
        track = [r["tracking_rms_rad"] for r in rs if r.get("tracking_rms_rad") is not None]
        out.append({
            "controller": name, "episodes": len(rs), "median_abs_error": float(np.median(err)),
            "ci95_median": [lo, hi], "iqm_abs_error": iqm(err), "failure_rate": float(np.mean(~np.isfinite(err))),
            "median_energy_J": float(np.median(energy)) if energy else math.nan,
            "median_tracking_rms_rad": float(np.median(track)) if track else math.nan,
            "median_wall_s": float(np.median([r["wall_s"] for r in rs])),
            # learned policies only (rows carry what OnnxPolicy read from its card); None for classical ones
            "train_env_steps": next((r["train_env_steps"] for r in rs if r.get("train_env_steps") is not None), None),
            "train_cpu_minutes": next((r["train_cpu_minutes"] for r in rs if r.get("train_cpu_minutes") is not None),
                                      None),
            "suites": sorted({str(r["suite"]) for r in rs}), "splits": sorted({str(r.get("split", "?")) for r in rs}),
            "version": ",".join(sorted({str(r["version"]) for r in rs})),
            "commit": ",".join(sorted({str(r.get("commit", "unknown")) for r in rs})),
        })
    out.sort(key=lambda e: (e["median_abs_error"], e["iqm_abs_error"], e["failure_rate"], e["controller"]))
    for k, e in enumerate(out, 1):
        e["rank"] = k
    return out


def _pct(x: float) -> str:
    return "fail" if not math.isfinite(x) else f"{100 * x:.3f} %"


COLUMNS = ("rank", "controller", "median |error|", "95 % CI of median", "IQM |error|", "failures", "median energy",
           "median tracking RMS", "episodes", "training cost", "version", "commit")


def _cells(e: dict) -> list[str]:
    lo, hi = e["ci95_median"]
    return [str(e["rank"]), e["controller"], _pct(e["median_abs_error"]), f"{_pct(lo)} .. {_pct(hi)}",
            _pct(e["iqm_abs_error"]), f"{100 * e['failure_rate']:.0f} %", f"{e['median_energy_J']:.2f} J",
            f"{1e3 * e['median_tracking_rms_rad']:.3f} mrad", str(e["episodes"]), _training_cost(e), e["version"],
            e["commit"]]


def _training_cost(e: dict) -> str:
    """Environment steps and CPU minutes that trained a learned policy; '-' for classical controllers."""
    steps, minutes = e.get("train_env_steps"), e.get("train_cpu_minutes")
    if steps is None and minutes is None:
        return "-"
    parts = [f"{steps} env steps" if steps is not None else "", f"{minutes:.1f} CPU min" if minutes is not None else ""]
    return ", ".join(p for p in parts if p)


def verdict(entries: list[dict], baseline: str = "pd", target: float = 0.01) -> list[str]:
    """Sentences computed from the table: the best classical controller against the target
    and the baseline, and whether any learned policy beats it (non-overlapping 95 % CIs of
    the median count as a difference; overlapping ones do not)."""
    classical = [e for e in entries if e.get("train_env_steps") is None and e.get("train_cpu_minutes") is None]
    learned = [e for e in entries if e not in classical]
    out: list[str] = []
    if classical:
        best = min(classical, key=lambda e: (e["median_abs_error"], e["iqm_abs_error"]))
        meets = "meets" if best["median_abs_error"] <= target else "does not meet"
        out.append(f"- Best classical controller: `{best['controller']}`, median |error| "
                   f"{_pct(best['median_abs_error'])}; it {meets} the {100 * target:.0f} % target. "
                   + ("Every classical controller meets it." if all(e["median_abs_error"] <= target for e in classical)
                      else "Not every classical controller meets it."))
        base = next((e for e in entries if e["controller"] == baseline), None)
        if base is not None and base is not best:
            out.append(f"- Against the bare `{baseline}` baseline ({_pct(base['median_abs_error'])}): "
                       + _compare(best, base) + ".")
        for e in learned:
            out.append(f"- Learned `{e['controller']}` ({_pct(e['median_abs_error'])}, trained with "
                       f"{_training_cost(e)}) against `{best['controller']}`: " + _compare(e, best) + ".")
    return out


def _compare(a: dict, b: dict) -> str:
    (alo, ahi), (blo, bhi) = a["ci95_median"], b["ci95_median"]
    if ahi < blo:
        return f"`{a['controller']}` is better, the 95 % intervals of the medians do not overlap"
    if bhi < alo:
        return f"`{a['controller']}` is worse, the 95 % intervals of the medians do not overlap"
    return ("no difference can be claimed: the 95 % intervals of the medians overlap "
            f"({_pct(alo)} .. {_pct(ahi)} against {_pct(blo)} .. {_pct(bhi)})")


def render_markdown(entries: list[dict], figures: dict[str, Path] | None = None, relative_to: Path | None = None,
                    preamble: str = "") -> str:
    lines = [preamble.rstrip(), ""] if preamble else []
    lines += ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(_cells(e)) + " |" for e in entries]
    said = verdict(entries)
    if said:
        lines += ["", "## Verdict (computed from the table above)", ""] + said
    for title, path in (figures or {}).items():
        rel = path.relative_to(relative_to) if relative_to else path
        lines += ["", f"![{title}]({rel.as_posix()})"]
    return "\n".join(lines) + "\n"


def render_html(entries: list[dict], figures: dict[str, Path] | None = None, title: str = "Leaderboard",
                preamble: str = "") -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in COLUMNS)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in _cells(e)) + "</tr>" for e in entries)
    imgs = "".join(
        f'<figure><img alt="{html.escape(t)}" src="data:image/png;base64,{base64.b64encode(p.read_bytes()).decode()}">'
        f"<figcaption>{html.escape(t)}</figcaption></figure>" for t, p in (figures or {}).items())
    pre = f"<pre>{html.escape(preamble)}</pre>" if preamble else ""
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            "<style>body{font-family:sans-serif}table{border-collapse:collapse}td,th{border:1px solid #999;"
            "padding:3px 8px;text-align:right}</style></head>"
            f"<body><h1>{html.escape(title)}</h1>{pre}<table><tr>{head}</tr>{body}</table>{imgs}</body></html>\n")
