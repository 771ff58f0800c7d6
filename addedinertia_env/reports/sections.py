"""A generated block inside a hand-written doc: replaced between its marker comments.

Several generators own one part of a page (``docs/DISCOVERY.md`` holds the detection
table and the foreign-lab table, ``docs/LEARNING.md`` a section per algorithm). Each
block starts with its ``begin`` marker and ends with its ``end`` marker (HTML comments,
invisible in the rendered page); everything outside the markers is left as it is.
"""

from __future__ import annotations

from pathlib import Path

from addedinertia_env.foundation.atomic import atomic_write_text


def replace_section(path: str | Path, block: str, begin: str, end: str, heading: str | None = None) -> Path:
    """Put ``block`` (which starts with ``begin`` and ends with ``end``) into the doc at ``path``.

    The old block between the markers is replaced; a doc without them (or no doc yet)
    gets the block appended at its end, under ``heading`` if that heading is not there
    yet. The file is written atomically. Returns the path. Raises ValueError if
    ``block`` is not enclosed by its own markers (it could not be found again).
    """
    if not (block.startswith(begin) and block.rstrip("\n").endswith(end)):
        raise ValueError(f"generated block must start with {begin!r} and end with {end!r}")
    path = Path(path)
    text = path.read_text() if path.exists() else ""
    if begin in text and end in text.split(begin, 1)[1]:
        head, rest = text.split(begin, 1)
        text = head + block.rstrip("\n") + rest.split(end, 1)[1]
    else:
        parts = [text.rstrip("\n")] if text.strip() else []
        if heading and heading not in text:
            parts.append(heading)
        text = "\n\n".join(parts + [block.rstrip("\n")]) + "\n"
    atomic_write_text(path, text)
    return path
