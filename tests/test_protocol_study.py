"""The protocol study's report (addedinertia_env/reports/protocol_study.py): its block names the
command that made it, summarises the rows it is given, and refuses bad arguments."""

from __future__ import annotations

import json

import pytest

from addedinertia_env.reports.protocol_study import BEGIN, COMMAND, END, _read_rows, main, render


def _row(preset, seed, factor, level, before, after, covered=True):
    return {"key": f"{preset}|{seed}|{factor}|{level}", "preset": preset, "seed": seed, "factor": factor,
            "level": level, "tank_s": 3.3, "err_before": before, "err_after": after, "covered": covered,
            "half_width": 0.05, "memory": "c2", "cpu_s": 5.0}


def test_render_summarises_the_rows_by_median():
    rows = [_row("wigley-2m-memory", s, "hold", "0.1 s", b, a, c)
            for s, b, a, c in ((1, 3.0, -0.01, True), (2, 4.0, -0.03, False), (3, 3.5, -0.02, True))]
    block = render(rows, 3, free_seeds=8)
    assert block.startswith(BEGIN) and block.rstrip().endswith(END)
    assert f"{COMMAND} --seeds 3 --free-seeds 8 --out docs/RADIATION_MEMORY.md" in block
    line = next(x for x in block.splitlines() if x.startswith("| wigley-2m-memory | hold | 0.1 s |"))
    assert "+3.500 % (+4.000 %)" in line and "-0.020 % (-0.030 %)" in line and "| 2/3 | 3/3 |" in line
    assert "| spheroid-7-memory |" not in block  # no rows, no line


def test_bad_arguments_and_bad_rows_are_refused(tmp_path):
    with pytest.raises(SystemExit) as e:
        main(["--seeds", "0"])
    assert e.value.code == 2
    bad = tmp_path / "rows.jsonl"
    bad.write_text(json.dumps(_row("wigley-2m", 1, "plan", "x", 0.0, 0.0)) + "\n{not json\n")
    with pytest.raises(SystemExit, match="line 2 is not JSON"):
        _read_rows(bad)
