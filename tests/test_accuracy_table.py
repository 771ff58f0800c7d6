"""The accuracy-table builder: hull spread, statistics, Markdown, atomic write."""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.reports import accuracy_table as at


def _row(k: int, errors: dict[str, float | None], covered: bool = True) -> at.HullRow:
    row = at.HullRow(index=k, seed=100 + k, lambda_ratio=1.0, lambda66=5.8, J_hull=5.8, period_s=4.0, b2=60.0,
                     alpha=0.1, hold_s=2.0)
    for m, e in errors.items():
        row.scores[m] = at.Score(failure="IdentificationError: x") if e is None else \
            at.Score(lambda66=5.8 * (1 + e), rel_error=e, rel_half_width=0.01, covered=covered)
    return row


def test_hulls_spread_evenly_over_the_issue_range():
    r = at.lambda_ratios(24)
    assert r[0] == pytest.approx(0.5) and r[-1] == pytest.approx(2.5)
    assert np.allclose(np.diff(r), 2.0 / 23)


def test_score_and_summary():
    s = at.score(10.2, (9.9, 10.3), truth=10.0)
    assert s.rel_error == pytest.approx(0.02) and s.rel_half_width == pytest.approx(0.02) and s.covered
    assert not at.score(10.4, (10.35, 10.45), truth=10.0).covered
    errors = [0.001 * k for k in range(1, 11)]  # 0.1 % .. 1 %
    rows = [_row(k, {"energy": e}, covered=(k % 5 != 0)) for k, e in enumerate(errors)]
    rows.append(_row(10, {"energy": None}))  # a failure counts against coverage
    s = at.summary(rows, "energy")
    assert s["median_abs_error"] == pytest.approx(np.median(errors))
    assert s["p90_abs_error"] == pytest.approx(np.percentile(errors, 90))
    assert s["failures"] == 1 and s["n"] == 11
    assert s["covered"] == 8 and s["coverage"] == pytest.approx(8 / 11)


def test_render_names_command_machine_and_every_hull(tmp_path):
    rows = [_row(k, {"energy": 0.01, "free-decay": -0.002, "forced": None}) for k in range(3)]
    text = at.render(rows, {"command": "python -m addedinertia_env.reports.accuracy_table --hulls 3 --out X.md",
                            "date": "today", "machine": machine_line(), "wall_s": 1.0, "cpu_s": 1.0, "seed": 100,
                            "controller": "feedforward-pd"})
    assert "--hulls 3 --out X.md" in text and "nproc" in text
    assert "| energy | 1.00 % | 1.00 % | 3/3 (100 %)" in text
    assert "| forced | n/a | n/a | 0/3 (0 %)" in text
    assert sum(line.startswith("| 2 | 102 |") for line in text.splitlines()) == 1
    out = tmp_path / "docs" / "ACC.md"
    atomic_write_text(out, text)
    assert out.read_text() == text and [p.name for p in out.parent.iterdir()] == ["ACC.md"]


@pytest.mark.slow
def test_two_hulls_end_to_end(tmp_path):
    out = tmp_path / "ACCURACY.md"
    assert at.main(["--hulls", "2", "--out", str(out)]) == 0
    text = out.read_text()
    for m in at.METHODS:
        assert f"| {m} |" in text
    assert "failed" not in text
