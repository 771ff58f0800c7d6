"""Benchmark rows that survive a kill: appended one flushed JSON line at a time, resumed by scenario.

``addedinertia bench run`` writes each episode's row the moment it lands (one JSON line,
flushed and synced), so a killed run loses at most the episodes still running. Run the
same command again and it resumes: the rows already in the file for this controller,
suite and split are kept, their scenarios are skipped, and the rest are appended. Rows of
episodes that failed (``rel_error: null``, the reason in ``failure``) are not kept: they are
removed from the file and their episodes run again (:func:`drop_failed`). A last
line cut short by the kill is removed first (and said so). A file holding rows of
another controller, suite or split, or of another score version (bench/versions.py), is
never mixed with or overwritten unless ``force`` (then the file starts over). See docs/RELIABILITY.md.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.foundation.jsonable import plain

KEY_FIELDS = ("controller", "suite", "split")


class RowsFileError(ValueError):
    """An output file that cannot be resumed or must not be overwritten; the message says what to do."""


def read_rows_tolerant(path: Path) -> tuple[list[dict[str, Any]], str | None]:
    """Complete rows of ``path`` and, if its last line was cut short by a kill, that fragment."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise RowsFileError(f"{path}: not UTF-8 text; expected the JSON lines of `addedinertia bench run`") from None
    lines = text.split("\n")
    torn = lines.pop() or None  # text after the last newline: an unfinished line
    rows = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as e:
            raise RowsFileError(f"{path}: line {n}: not a JSON line ({e.msg}); expected the rows of "
                                "`addedinertia bench run` (use another --out, or --force to replace the file)") from None
        if not isinstance(row, dict) or not all(k in row for k in KEY_FIELDS + ("scenario",)):
            raise RowsFileError(f"{path}: line {n}: not a benchmark row (needs {list(KEY_FIELDS + ('scenario',))}); "
                                "use another --out, or --force to replace the file")
        rows.append(row)
    if torn is not None:
        try:
            row = json.loads(torn)  # a complete row whose newline was lost
            if isinstance(row, dict) and all(k in row for k in KEY_FIELDS + ("scenario",)):
                rows.append(row)
                torn = None
        except json.JSONDecodeError:
            pass
    return rows, torn


def prepare_output(path: str | Path, key: dict[str, Any], force: bool = False,
                   version: str | None = None) -> tuple[list[dict], list[str]]:
    """Rows already in ``path`` for this run's ``key`` (controller, suite, split) and messages for the user.
    ``version``: the score version this run writes (bench/versions.py; default ``SCORE_VERSION``): rows of
    any other are refused, never resumed.

    ``force``: start the file over whatever it holds. Otherwise a file holding rows of
    another run is refused (:class:`RowsFileError`), and a torn last line is cut off. ``version``: the
    score version this run writes (default ``SCORE_VERSION``; a suite's ``ranked`` may name another).
    """
    path = Path(path)
    notes: list[str] = []
    stale = path.with_name(path.name + ".tmp")  # left by the writer of earlier versions
    if stale.exists():
        stale.unlink()
        notes.append(f"removed the stale temporary file {stale}")
    if not path.exists():
        return [], notes
    if force:
        atomic_write_text(path, "")
        notes.append(f"--force: started {path} over")
        return [], notes
    rows, torn = read_rows_tolerant(path)
    others = sorted({tuple(str(r.get(k)) for k in KEY_FIELDS) for r in rows
                     if any(r.get(k) != key[k] for k in KEY_FIELDS)})
    if others:
        desc = "; ".join(f"controller {c}, suite {s}, split {p}" for c, s, p in others[:3])
        raise RowsFileError(f"{path}: holds rows of another run ({desc}); refusing to mix or overwrite them. "
                            "Use another --out, or --force to replace the file")
    from addedinertia_env.bench.versions import SCORE_VERSION, row_version  # noqa: PLC0415

    version = version or SCORE_VERSION
    older = sorted({row_version(r) for r in rows} - {version})
    if older:  # a row of another score version is another truth or score: never resumed beside this run's
        raise RowsFileError(f"{path}: holds rows of score version(s) {older}; this run writes {version!r}; "
                            "refusing to mix them. Use another --out, or --force to replace the file")
    if torn is not None:
        atomic_write_text(path, "".join(json.dumps(r, allow_nan=False) + "\n" for r in rows))
        notes.append(f"{path}: removed an unfinished last line ({len(torn)} characters) left by an interrupted run")
    return rows, notes


def is_failed(row: dict[str, Any]) -> bool:
    """Whether a benchmark row is a failed episode (no error measured; the reason is in ``failure``)."""
    return row.get("rel_error") is None


def drop_failed(path: str | Path, rows: list[dict[str, Any]]) -> tuple[list[dict], list[dict]]:
    """Remove the failed episodes' rows from ``path`` (atomically) so that a resumed run retries them.

    ``rows`` are the rows of this run already in ``path`` (:func:`prepare_output`); returns
    (the rows kept, the rows removed). The file is left untouched when none failed.
    """
    kept = [r for r in rows if not is_failed(r)]
    failed = [r for r in rows if is_failed(r)]
    if failed:
        atomic_write_text(Path(path), "".join(json.dumps(plain(r), allow_nan=False) + "\n" for r in kept))
    return kept, failed


def failure_reason(row: dict[str, Any]) -> str:
    """One line saying why a failed row failed: its scenario and its ``failure`` text."""
    reason = row.get("failure") or "no estimate (no failure text in the row)"
    return f"{row.get('scenario')}: {reason}"


class RowAppender:
    """Append rows to a JSON-lines file, each flushed and synced as it lands (context manager)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "a", encoding="utf-8")
        self.written = 0

    def append(self, row: dict[str, Any]) -> None:
        """Append ``row`` as one JSON line (non-finite numbers as null), flushed and synced to disk."""
        self._f.write(json.dumps(plain(row), allow_nan=False) + "\n")
        self._f.flush()
        os.fsync(self._f.fileno())
        self.written += 1

    def close(self) -> None:
        """Close the file; every appended row is already on disk."""
        self._f.close()

    def __enter__(self) -> "RowAppender":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


RowCallback = Callable[[dict[str, Any]], None]
