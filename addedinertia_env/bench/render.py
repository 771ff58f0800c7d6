"""A leaderboard as Markdown, or as one self-contained HTML page (data, script, figures inline).

The HTML page needs no network at view time: the table, the per-scenario rows (as JSON in
a ``<script type="application/json">`` block), the sorting and drill-down script and the
Pareto figure (inline SVG) are all in the file.
"""

from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path

from addedinertia_env.bench import ranking
from addedinertia_env.bench.plots import pareto_front
from addedinertia_env.bench.verdict import pct, rank_text, training_cost, verdict

COLUMNS = ("rank", "controller", "kind", "score: mean min(|error|, cap)", "95 % CI of score",
           "median |control error| vs oracle", "95 % CI (paired)",
           "median |error| (as written)", "95 % CI of median", "median |error| corrected", "IQM |error|", "failures",
           "median energy", "median tracking RMS", "current sign changes", "chatter", "episodes", "training cost",
           "score version", "version", "commit")


def cells(e: dict) -> list[str]:
    """The table row of entry ``e`` as text."""
    lo, hi = e["ci95_median"]
    cci = e.get("ci95_control_error")
    rank = rank_text(e)
    sci = e.get("ci95_score")
    return [rank, e["controller"], e.get("kind", "?"), pct(e.get("mean_score")),
            f"{pct(sci[0])} .. {pct(sci[1])}" if sci else "-", pct(e.get("median_abs_control_error")),
            f"{pct(cci[0])} .. {pct(cci[1])}" if cci else "-", pct(e["median_abs_error"]),
            f"{pct(lo)} .. {pct(hi)}", pct(e.get("median_abs_error_corrected")), pct(e["iqm_abs_error"]),
            f"{100 * e['failure_rate']:.0f} %", _num(e["median_energy_J"], "J", 2),
            _num(1e3 * e["median_tracking_rms_rad"], "mrad", 3), _num(e.get("mean_current_sign_changes"), "", 1),
            _num(e.get("mean_chatter_A"), "A", 3), str(e["episodes"]), training_cost(e),
            e.get("score_version", "-"), e["version"], e["commit"]]


def md_cell(text: str) -> str:
    """``text`` safe inside a Markdown table cell (a literal ``|`` would split the cell)."""
    return text.replace("|", "\\|")


def _num(x: float, unit: str, digits: int) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}f} {unit}"


def tie_note(entries: list[dict]) -> str:
    """Which ranked entries are tied on accuracy (the tie rule of :mod:`.ranking`)."""
    groups: dict[int, list[str]] = {}
    for e in entries:
        if e.get("tie_group") is not None:
            groups.setdefault(e["tie_group"], []).append(e["controller"])
    tied = [g for g in groups.values() if len(g) > 1]
    if not tied:
        return "No two ranked entries are tied on accuracy."
    return ("Tied on accuracy (paired 95 % interval of the difference includes zero), sharing a rank and listed by "
            "energy: " + "; ".join(", ".join(f"`{n}`" for n in g) for g in tied) + ".")


def _row_minus_column(rows: list[dict], cell) -> str:
    """A Markdown table of ``cell(row_entry, column_entry)`` between every two of ``rows``
    (``-`` on the diagonal), headed by the entries' controllers."""
    lines = ["| row minus column | " + " | ".join(f"`{e['controller']}`" for e in rows) + " |",
             "|" + "---|" * (len(rows) + 1)]
    for a in rows:
        cells = ["-" if a is b else cell(a, b) for b in rows]
        lines.append(f"| `{a['controller']}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def pairwise_table(entries: list[dict]) -> str:
    """Paired tests between every two rows (Markdown): the median of ``|c_row| - |c_column|``
    over their common scenarios; ``*`` when its 95 % bootstrap interval excludes zero (the row
    is clearly worse: positive, or clearly better: negative). Empty without oracle rows."""
    from addedinertia_env.bench import paired  # noqa: PLC0415

    rows = [e for e in entries if e.get("control_errors") is not None and e["controller"] != paired.ORACLE]
    if len(rows) < 2:
        return ""

    def cell(a: dict, b: dict) -> str:
        d = paired.difference(a["control_errors"], b["control_errors"])
        mark = "*" if paired.clearly(d) else ""
        return f"{100 * d['median']:+.3f} %{mark}" if math.isfinite(d["median"]) else "fail"

    return _row_minus_column(rows, cell)


def score_pairwise_table(entries: list[dict]) -> str:
    """Paired tests between every two rows on the ranked score (Markdown): the mean of
    ``s_row - s_column`` over their common scenarios (:func:`.score.difference`); ``*`` when its
    95 % bootstrap interval excludes zero. Empty with fewer than two entries that have scores."""
    from addedinertia_env.bench import score  # noqa: PLC0415

    rows = [e for e in entries if e.get("scenario_scores")]
    if len(rows) < 2:
        return ""

    def cell(a: dict, b: dict) -> str:
        d = score.difference(a["scenario_scores"], b["scenario_scores"])
        return f"{100 * d['mean']:+.3f} %{'*' if score.clearly(d) else ''}"

    return _row_minus_column(rows, cell)


def render_markdown(entries: list[dict], figures: dict[str, Path] | None = None, relative_to: Path | None = None,
                    preamble: str = "") -> str:
    """The leaderboard as Markdown: ``preamble``, the table of ``entries``, the tie rule, the verdict, the paired tests and the figures (linked relative to ``relative_to``)."""
    lines = [preamble.rstrip(), ""] if preamble else []
    lines += ["| " + " | ".join(md_cell(c) for c in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(md_cell(c) for c in cells(e)) + " |" for e in entries]
    lines += ["", "Rows marked `ref` are references, not entries: `oracle` tracks on the simulator's truth (the "
              "floor), `zero` commands 0 A (no control). " + tie_note(entries)]
    said = verdict(entries)
    if said:
        lines += ["", "## Verdict (computed from the table above)", ""] + said
    score_pairs = score_pairwise_table(entries)
    if score_pairs:
        lines += ["", "## Paired tests on the ranked score", "",
                  "Mean over the common scenarios of s_row - s_column (s = min(|e|, cap), a failure at the cap); "
                  "`*`: its paired 95 % bootstrap interval excludes zero (positive: the row is clearly worse).", "",
                  score_pairs]
    pairs = pairwise_table(entries)
    if pairs:
        lines += ["", "## Paired tests on the control error", "",
                  "Median over the common scenarios of |c_row| - |c_column| (c = e - e_oracle); `*`: its paired "
                  "95 % bootstrap interval excludes zero (positive: the row is clearly worse).", "", pairs]
    for title, path in (figures or {}).items():
        rel = path.relative_to(relative_to) if relative_to else path
        lines += ["", f"![{title}]({rel.as_posix()})"]
    return "\n".join(lines) + "\n"


# --- HTML -----------------------------------------------------------------------------
_STYLE = """body{font-family:sans-serif;margin:1.5em;max-width:80em}table{border-collapse:collapse;margin:1em 0}
td,th{border:1px solid #999;padding:3px 8px;text-align:right}th{background:#eee;cursor:pointer}
tr.ref td{font-style:italic;background:#f6f6ff}pre{background:#f4f4f4;padding:.5em;white-space:pre-wrap}
.verdict li{margin:.3em 0}svg text{font-size:11px}"""

_SCRIPT = """
(function(){
  function cellValue(td){var v=td.getAttribute('data-v');return v===null?td.textContent:v;}
  document.querySelectorAll('table.sortable').forEach(function(table){
    table.querySelectorAll('th').forEach(function(th,col){
      th.addEventListener('click',function(){
        var body=table.tBodies[0],rows=Array.prototype.slice.call(body.rows);
        var asc=th.getAttribute('data-asc')!=='1';th.setAttribute('data-asc',asc?'1':'0');
        rows.sort(function(a,b){
          var x=cellValue(a.cells[col]),y=cellValue(b.cells[col]),fx=parseFloat(x),fy=parseFloat(y);
          var c=(!isNaN(fx)&&!isNaN(fy))?fx-fy:String(x).localeCompare(String(y));
          return asc?c:-c;});
        rows.forEach(function(r){body.appendChild(r);});
      });
    });
  });
  var data=JSON.parse(document.getElementById('episodes').textContent);
  var pick=document.getElementById('scenario'),out=document.getElementById('drill');
  function pctText(x){return x===null?'fail':(100*x).toFixed(3)+' %';}
  function show(){
    var key=pick.value,rows=data.filter(function(r){return r.scenario===key;});
    var h='<table class="sortable"><thead><tr><th>controller</th><th>error (as written)</th>'+
          '<th>control error vs oracle</th><th>error corrected</th><th>energy</th><th>failure</th></tr></thead><tbody>';
    rows.forEach(function(r){
      h+='<tr><td>'+r.controller+'</td><td>'+pctText(r.rel_error)+'</td><td>'+
         (r.control_error===undefined?'-':pctText(r.control_error))+'</td><td>'+pctText(r.rel_error_corrected)+
         '</td><td>'+(r.energy_J===null?'-':r.energy_J.toFixed(2)+' J')+'</td><td>'+(r.failure||'')+'</td></tr>';});
    out.innerHTML=h+'</tbody></table>';
  }
  if(pick){pick.addEventListener('change',show);show();}
})();
"""


def _sort_value(col: str, e: dict) -> str | None:
    """Numeric value for sorting a column (failures sort last)."""
    def num(x):
        return "1e300" if x is None or not math.isfinite(x) else repr(float(x))
    return {"rank": num(e["rank"]) if e.get("rank") is not None else "1e301",
            "score: mean min(|error|, cap)": num(e.get("mean_score")),
            "median |control error| vs oracle": num(e.get("median_abs_control_error")),
            "median |error| (as written)": num(e["median_abs_error"]),
            "median |error| corrected": num(e.get("median_abs_error_corrected")),
            "IQM |error|": num(e["iqm_abs_error"]), "median energy": num(e["median_energy_J"]),
            "episodes": num(e["episodes"])}.get(col)


def pareto_svg(entries: list[dict], width: int = 640, height: int = 380) -> str:
    """The Pareto figure as inline SVG: log energy against log score, one point per entry."""
    pts = [(e, e["median_energy_J"], e["score"]) for e in entries
           if math.isfinite(e["median_energy_J"]) and math.isfinite(e["score"])]
    if not pts:
        return "<p>(no finite points to plot)</p>"
    xs = [math.log10(max(x, 1e-3)) for _, x, _ in pts]
    ys = [math.log10(max(y, 1e-5) * 100) for _, _, y in pts]
    x0, x1 = min(xs) - 0.2, max(xs) + 0.2
    y0, y1 = min(ys) - 0.2, max(ys) + 0.2
    m = 50

    def X(v):
        return m + (v - x0) / (x1 - x0) * (width - 2 * m)

    def Y(v):
        return height - m - (v - y0) / (y1 - y0) * (height - 2 * m)

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img" '
             'aria-label="Pareto figure: accuracy against energy">',
             f'<rect x="{m}" y="{m}" width="{width - 2 * m}" height="{height - 2 * m}" fill="none" stroke="#999"/>',
             f'<text x="{width / 2}" y="{height - 12}" text-anchor="middle">median energy, J (log)</text>',
             f'<text x="14" y="{height / 2}" transform="rotate(-90 14 {height / 2})" text-anchor="middle">'
             'median score, % (log)</text>']
    for v in range(math.floor(x0), math.ceil(x1) + 1):
        if x0 <= v <= x1:
            parts.append(f'<text x="{X(v):.1f}" y="{height - m + 14}" text-anchor="middle">{10.0 ** v:g}</text>')
    for v in range(math.floor(y0), math.ceil(y1) + 1):
        if y0 <= v <= y1:
            parts.append(f'<text x="{m - 4}" y="{Y(v):.1f}" text-anchor="end">{10.0 ** v:g}</text>')
    ranked = [(k, p) for k, p in enumerate(pts) if p[0].get("rank") is not None]
    front = pareto_front([(p[1], p[2]) for _, p in ranked])
    if len(front) > 1:
        line = " ".join(f"{X(xs[ranked[k][0]]):.1f},{Y(ys[ranked[k][0]]):.1f}" for k in front)
        parts.append(f'<polyline points="{line}" fill="none" stroke="#000" stroke-dasharray="4 3"/>')
    for (e, _, _), xv, yv in zip(pts, xs, ys):
        ref = e.get("rank") is None
        fill = "none" if ref else "#1f77b4"
        parts.append(f'<circle cx="{X(xv):.1f}" cy="{Y(yv):.1f}" r="5" fill="{fill}" stroke="#1f77b4"/>'
                     f'<text x="{X(xv) + 7:.1f}" y="{Y(yv) - 5:.1f}">{html.escape(e["controller"])}'
                     f'{" (reference)" if ref else ""}</text>')
    parts.append("</svg>")
    return "".join(parts)


def render_html(entries: list[dict], rows: list[dict], title: str = "Leaderboard", preamble: str = "",
                figures: dict[str, Path] | None = None) -> str:
    """One self-contained page (module doc)."""
    head = "".join(f"<th>{html.escape(c)}</th>" for c in COLUMNS)
    body = []
    for e in entries:
        tds = []
        for col, text in zip(COLUMNS, cells(e)):
            v = _sort_value(col, e)
            tds.append(f'<td data-v="{v}">{html.escape(text)}</td>' if v is not None else f"<td>{html.escape(text)}</td>")
        cls = ' class="ref"' if e.get("rank") is None else ""
        body.append(f"<tr{cls}>" + "".join(tds) + "</tr>")
    verdict_items = "".join(f"<li>{html.escape(s.lstrip('- ').replace('**', '').replace('`', ''))}</li>"
                            for s in verdict(entries))
    control = {e["controller"]: e.get("control_errors") or {} for e in entries}
    episodes = []
    for r in rows:
        item = {k: r.get(k) for k in ("controller", "scenario", "seed", "rel_error", "rel_error_corrected", "energy_J",
                                      "failure")}
        key = (str(r["suite"]), str(r.get("split", "?")), int(r["seed"]))
        if key in control.get(r["controller"], {}):
            c = control[r["controller"]][key]
            item["control_error"] = c if math.isfinite(c) else None
        episodes.append(item)
    scenarios = sorted({r["scenario"] for r in rows})
    options = "".join(f'<option value="{html.escape(s)}">{html.escape(s)}</option>' for s in scenarios)
    data = json.dumps(episodes, allow_nan=False).replace("</", "<\\/")
    imgs = "".join(
        f'<figure><img alt="{html.escape(t)}" src="data:image/png;base64,{base64.b64encode(p.read_bytes()).decode()}">'
        f"<figcaption>{html.escape(t)}</figcaption></figure>" for t, p in (figures or {}).items())
    score_name = ("median |control error| vs oracle" if any(e.get("median_abs_control_error") is not None
                                                              for e in entries) else "median |error|")
    return (f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head><body><h1>{html.escape(title)}</h1>"
            f"<pre id='how'>{html.escape(preamble)}</pre>"
            f"<h2>Ranking</h2><p>Click a column heading to sort. Score: {html.escape(score_name)}. "
            "Rows in italics are references (oracle: truth-based tracking; zero: no control), not entries. "
            f"{html.escape(tie_note(entries).replace('`', ''))}</p>"
            f"<table id='leaderboard' class='sortable'><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody>"
            f"</table><h2>Verdict</h2><ul class='verdict'>{verdict_items}</ul>"
            f"<h2>Pareto figure</h2>{pareto_svg(entries)}{imgs}"
            f"<h2>Per-scenario drill-down</h2><label>scenario <select id='scenario'>{options}</select></label>"
            f"<div id='drill'></div><script type='application/json' id='episodes'>{data}</script>"
            f"<script>{_SCRIPT}</script></body></html>\n")


__all__ = ["COLUMNS", "cells", "render_html", "render_markdown", "ranking"]
