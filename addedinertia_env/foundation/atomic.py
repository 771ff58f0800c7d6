"""Atomic file writes: a temporary file beside the target, then ``os.replace``.

A crash while writing (disk full, a killed process) never leaves a half-written file
under the final name, and an older file there stays intact. Files get the usual
permissions (0666 less the umask), not the 0600 of a bare temporary file.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any


def _default_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


_STALE = re.compile(r"^\.(?P<target>.+)\.pid(?P<pid>\d+)\.[A-Za-z0-9_]+\.[A-Za-z0-9]+$")


def _temp_prefix(path: Path) -> str:
    """Hidden temporary name beside ``path`` carrying the writer's process id (see :func:`remove_stale_temps`)."""
    return f".{path.name}.pid{os.getpid()}."


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def remove_stale_temps(folder: str | os.PathLike) -> list[Path]:
    """Remove temporary files in ``folder`` left by writers that were killed (their process is gone).

    A writer killed with SIGKILL cannot clean up; its temporary file names its process id,
    so a later run removes it without touching a live writer's. Returns what was removed.
    """
    folder = Path(folder)
    removed = []
    if not folder.is_dir():
        return removed
    for p in folder.iterdir():
        m = _STALE.match(p.name)
        if m and p.is_file() and int(m["pid"]) != os.getpid() and not _alive(int(m["pid"])):
            try:
                p.unlink()
                removed.append(p)
            except OSError:
                pass
    return removed


def atomic_write_texts(files: list[tuple[Path, str]]) -> None:
    """Write every ``(path, text)`` to a temporary file beside it, then rename them all.

    Nothing under a final name changes until every temporary file is complete and on
    disk, so a set of files (a run record's CSV and JSON) is replaced together; only the
    renames, which write no data, come after.
    """
    temps: list[tuple[str, Path]] = []
    mode = _default_mode()
    try:
        for path, text in files:
            path = Path(path)
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=".tmp", dir=path.parent)
            temps.append((tmp, path))
            with os.fdopen(fd, "w", newline="") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, mode)
        while temps:
            tmp, path = temps[0]
            os.replace(tmp, path)
            temps.pop(0)
    finally:
        for tmp, _ in temps:  # only left over after an error
            if os.path.exists(tmp):
                os.unlink(tmp)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (a temporary file beside it, then ``os.replace``)."""
    atomic_write_texts([(Path(path), text)])


@contextmanager
def atomic_target(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """Yield a temporary path beside ``path`` to write to (e.g. ``savefig``); rename on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, _default_mode())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def save_figure(fig: Any, path: str | os.PathLike, dpi: int = 110) -> Path:
    """Write the matplotlib figure ``fig`` to ``path`` atomically (its folder made; the format from
    the suffix, PNG by default) at ``dpi`` dots per inch, then close it; returns the path."""
    path = Path(path)
    try:
        with atomic_target(path, suffix=path.suffix or ".png") as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        import matplotlib.pyplot as plt  # noqa: PLC0415 - only those who draw need matplotlib

        plt.close(fig)
    return path
