"""`make docs` (issue 31): one command regenerates every generated reference table of docs/,
and ENVIRONMENT.md's reference returns match a fresh run within the tolerance it states."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from addedinertia_env.envs.baselines import BEGIN, END
from addedinertia_env.reports.environment_returns import main as returns_main

ROOT = Path(__file__).resolve().parents[1]
# Commands in the docs that regenerate one of their tables or figures.
GENERATOR = re.compile(r"(?:\.venv/bin/)?(python -m addedinertia_env\.(?:reports\.\w+|envs\.baselines)[^`\n]*"
                       r"|addedinertia perf [^`\n]*--out docs/[^`\n]*)")
# Generators named in docs that `make docs` does not run, and why.
NOT_IN_MAKE_DOCS = {
    "addedinertia_env.reports.memory_identification": "its rows pool the project's presets with the developers' "
                                                      "foreign-lab-2 archive (a run/render pair over a rows log); "
                                                      "the commands are in docs/RADIATION_MEMORY.md",
    "addedinertia_env.reports.momentum_check": "reads the developers' foreign-lab archives (--data PATH), which are "
                                               "not part of the project: a clone has none to read",
    "addedinertia_env.reports.coulomb_scale": "the measurement behind the energy method's Coulomb smoothing rate "
                                              "(docs/RELIABILITY.md section 2b), with the developers' foreign-lab "
                                              "archives (--data), which a clone has none of",
    "addedinertia_env.reports.release_rest": "a measurement in the prose (the rest after the release against the "
                                             "simulator's true angle, docs/ENERGY_METHOD.md item 4), not a table",
    "addedinertia_env.reports.lab_requantise": "reads the developers' foreign-lab archives (a lab's own records, "
                                               "re-read at random encoder offsets: docs/INTERVALS.md), which a "
                                               "clone has none of",
    "addedinertia_env.reports.digests": "a check that numbers are unchanged across a refactoring "
                                        "(docs/ARCHITECTURE.md), not a table of the docs",
    "addedinertia_env.reports.ars_curves": "needs the training runs of `make hard-policy` (it exports a shipped policy)",
    "addedinertia_env.reports.dagger_curves": "needs the training runs of `make hard-policy-dagger` (it exports a "
                                              "shipped policy)",
}

# Variants the docs mention beside the command that regenerates their table, and why they are not it.
VARIANTS = {
    "python -m addedinertia_env.reports.hydrodynamics --solve": "re-solves the BEM first (the [hull] extra, 10 min); "
                                                                 "make docs regenerates from the cached solves",
    "python -m addedinertia_env.reports.radiation_memory --seeds 1 --controller lqr": "a one-seed comparison in the "
                                                                                      "text, not the table's command",
}
PLACEHOLDER = ("NAME", "FILE", "ROWS.jsonl", "SETS")  # words a reader replaces (a file of theirs)


def _dry_run() -> str:
    if shutil.which("make") is None:
        pytest.skip("no make on this machine")
    proc = subprocess.run(["make", "-n", "docs", "FOREIGN_LAB=PATH/foreign-lab.tar.xz", "FOREIGN_LAB_2=PATH/foreign-lab-2.tar.xz", "STAMP="], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return re.sub(r"\S*/\.venv/bin/|\.venv/bin/", "", proc.stdout)


def _normalise(command: str) -> str:
    return " ".join(command.replace("\\", " ").split())


def test_make_docs_runs_every_generator_the_docs_name():
    planned = _normalise(_dry_run())
    named = set()
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for command in GENERATOR.findall(doc.read_text()):
            command = _normalise(command.split("` ")[0].rstrip(".,;)"))
            module = command.split()[2] if command.startswith("python -m") else "perf"
            if module in NOT_IN_MAKE_DOCS or command in VARIANTS or any(w in command.split() or w + ")" in command
                                                                         for w in PLACEHOLDER):
                continue
            named.add(command)
    assert len(named) >= 10, named
    missing = sorted(c for c in named if c not in planned)
    assert not missing, "commands the docs give for their tables that `make docs` does not run:\n" + "\n".join(missing)


def test_the_dry_run_lists_the_whole_chain():
    planned = _dry_run()
    for needle in ("reports.environment_returns --episodes 5 --out docs/ENVIRONMENT.md", "reports.foreign_lab --data "
                   "PATH/foreign-lab.tar.xz", "--out docs/LEADERBOARD_hard.md", "reports.learning_curves --algo ppo",
                   "decay --textbook --plot docs/figures/textbook_decay.png"):
        assert needle in planned, needle


def _doc_row(policy: str) -> dict[str, float]:
    text = (ROOT / "docs" / "ENVIRONMENT.md").read_text()
    block = text.split(BEGIN, 1)[1].split(END, 1)[0]
    row = next(line for line in block.splitlines() if line.startswith(f"| {policy} |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    return {"mean_return": float(cells[2]), "mean_abs_rel_error": float(cells[7].rstrip(" %")) / 100,
            "max_abs_rel_error": float(cells[8].rstrip(" %")) / 100, "failed": int(cells[9].split("/")[0])}


def test_environment_reference_returns_match_a_fresh_run(capsys, tmp_path):
    """The zero policy's row (5 episodes, env seeds 0-4) rerun now, against the doc, within the
    tolerance ENVIRONMENT.md states: return 0.05, |rel_error| 0.005 percentage points."""
    shown = _doc_row("zero")
    doc = tmp_path / "ENV.md"
    assert returns_main(["--episodes", "5", "--policies", "zero", "--out", str(doc)]) == 0
    fresh = json.loads(capsys.readouterr().out)["zero"]
    assert abs(fresh["mean_return"] - shown["mean_return"]) <= 0.05, (fresh, shown)
    assert abs(fresh["mean_abs_rel_error"] - shown["mean_abs_rel_error"]) <= 5e-5, (fresh, shown)
    assert abs(fresh["max_abs_rel_error"] - shown["max_abs_rel_error"]) <= 5e-5, (fresh, shown)
    assert fresh["failed"] == shown["failed"]
    written = doc.read_text()  # the generator writes the block it is checked against
    assert written.startswith(BEGIN) and "| zero | 10 |" in written and "environment_returns" in written
