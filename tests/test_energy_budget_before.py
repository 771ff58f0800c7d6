"""docs/ENERGY_METHOD.md's "before" column: the estimator of an old git revision, run on today's records.

The old revision's modules import each other by the layout they had (``..record``), so it runs in its
own process on its own package tree (``git archive``); a record it cannot read comes back as a refusal
with its reason, never as a number.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from addedinertia_env.apps import energy_budget as eb
from addedinertia_env.identify.common import IdentificationError
from addedinertia_env.reports import energy_budget as report

REPO = Path(__file__).resolve().parents[1]


def _has_revision(rev: str) -> bool:
    try:
        return subprocess.run(["git", "-C", str(REPO), "cat-file", "-e", f"{rev}^{{commit}}"],
                              capture_output=True).returncode == 0
    except OSError:
        return False


@pytest.mark.slow
def test_the_estimator_before_runs_on_todays_records(tmp_path):
    if not _has_revision(report.BEFORE_REV):
        pytest.skip(f"git revision {report.BEFORE_REV} not in this checkout (a shallow clone?)")
    legacy = report.load_legacy_estimator(report.BEFORE_REV, tmp_path / "tree")
    try:
        assert (legacy.tree / "addedinertia_env" / "record.py").exists()  # the old layout, not today's
        rig = eb.preset_rig("wigley-2m", "calibrated")
        run = eb.simulate_with_truth(rig, "lqr", eb.seeded_plan("wigley-2m", 1), seed=1)
        budget = report.legacy_budget(run, legacy)
        assert set(budget) == set(report.LEGACY_LINES)
        assert 0.0 < abs(budget["estimate"]) < 5.0  # percent: an estimate of this hull, not a stray number
        # the old estimator's own answer, not today's: the two differ on the same record
        from addedinertia_env.identify import identify

        today = 100.0 * (identify([run.record], "energy", memory="off").lambda66 / run.truth - 1.0)
        assert budget["estimate"] != pytest.approx(today, abs=1e-6)
        # a record it cannot read is a refusal naming the revision
        bad = run.record.without_truth()
        bad.meta["format"] = "addedinertia-run/99"
        with pytest.raises(IdentificationError, match=report.BEFORE_REV):
            legacy.identify_energy([bad])
    finally:
        shutil.rmtree(legacy.tree, ignore_errors=True)


def test_a_rerun_keeps_the_sections_added_by_hand(tmp_path):
    old = tmp_path / "ENERGY_METHOD.md"
    old.write_text("# t\n\n## spheroid-7\n\nold numbers\n\n## The drive's flaws in the budget (issue 28)\n\nby hand\n")
    new = "# t\n\n## spheroid-7\n\nnew numbers\n"
    got = report.keep_added_sections(new, old)
    assert "new numbers" in got and "old numbers" not in got
    assert got.endswith("## The drive's flaws in the budget (issue 28)\n\nby hand\n")
    assert report.keep_added_sections(new, tmp_path / "absent.md") == new
