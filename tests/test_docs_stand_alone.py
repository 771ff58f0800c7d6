"""The project stands alone (issue 31): README.md, docs/*.md, the shipped data's README, the
configs, the Makefile and the CLI's help texts name no path outside the repository (no
``../shared``, no path of the machine a doc was made on), and every repository path they
name exists in the clone."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "addedinertia_env" / "data").glob("*/README.md"))]
USER_FACING = [*DOCS, ROOT / "Makefile", *sorted((ROOT / "configs").rglob("*.yaml"))]
# Outside the repository: the developers' shared folder, home and work folders of a machine.
OUTSIDE = re.compile(r"\.\./shared|(?<![\w.])/(?:work|home|Users|root|mnt|scratch|tmp|var|opt)/|[A-Za-z]:\\\\")
# The repository's own top-level folders and files: a path that starts with one must exist.
TOP = ("addedinertia_env/", "agents/", "configs/", "docs/", "hw_adapter/", "tests/", "firmware/")
# Not checked: what commands write (out/, runs), placeholders, globs and templates.
SKIP = re.compile(r"^(?:out/|runs/)|[*{}<>$]|PATH|PRESET|SUITE|NAME|FILE|STEM|DIR|CONTROLLER|\.\.\.")
TOKEN = re.compile(r"(?:`([^`\n]+)`)|(?:\]\(([^)#\s]+)(?:#[^)]*)?\))")


def _paths_in(text: str) -> list[str]:
    """Repository-looking paths named in ``text``: markdown link targets and backticked tokens."""
    found = []
    for code, link in TOKEN.findall(text):
        for word in (code.split() if code else [link]):
            word = word.lstrip("'\"([").rstrip("'\",;:.)]")
            if "://" in word or SKIP.search(word):
                continue
            if word.startswith(TOP) or link:
                found.append(word)
    return found


@pytest.mark.parametrize("path", USER_FACING, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_path_outside_the_repository(path):
    lines = [f"{path.name}:{n}: {line.strip()}" for n, line in enumerate(path.read_text().splitlines(), 1)
             if OUTSIDE.search(line)]
    assert not lines, "paths outside the repository (a user's clone has none of them):\n" + "\n".join(lines)


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_named_repository_path_exists(path):
    missing = []
    for word in _paths_in(path.read_text()):
        file, _, test = word.partition("::")  # tests/test_x.py::test_name: the file, and the test in it
        here = path.parent / file  # a link or path relative to the document ...
        there = ROOT / file  # ... or to the repository root, as the docs write commands
        found = next((p for p in (here, there) if p.exists()), None)
        if found is None or (test and f"def {test.split('[')[0]}(" not in found.read_text()):
            missing.append(word)
    assert not missing, f"{path.relative_to(ROOT)} names paths this clone does not have: {sorted(set(missing))}"


def test_the_checks_can_fail(tmp_path):
    assert OUTSIDE.search("see ../shared/design/physics.md") and OUTSIDE.search("data in /work/shared/data/x.csv")
    assert not OUTSIDE.search("docs/PHYSICS.md and out/bench/x.jsonl")
    assert _paths_in("run `addedinertia_env/no_such.py` and [x](NOPE.md)") == ["addedinertia_env/no_such.py", "NOPE.md"]


def test_cli_help_texts_name_no_outside_path():
    from addedinertia_env.cli import build_parser  # noqa: PLC0415

    texts = []

    def walk(parser):
        texts.append(parser.format_help())
        for action in parser._actions:  # argparse keeps subparsers here
            for sub in (getattr(action, "choices", None) or {}).values() if hasattr(action, "_name_parser_map") else ():
                walk(sub)

    walk(build_parser())
    assert len(texts) > 10
    bad = [t for t in texts if OUTSIDE.search(t)]
    assert not bad, bad[:1]


def test_the_textbook_record_ships_with_the_package():
    from addedinertia_env.cli.decay import TEXTBOOK_IN_REPO, textbook_path  # noqa: PLC0415

    assert Path(textbook_path()).is_file() and (ROOT / TEXTBOOK_IN_REPO).is_file()
    assert Path(textbook_path()).with_name("textbook_roll_decay_processing.csv").is_file()
