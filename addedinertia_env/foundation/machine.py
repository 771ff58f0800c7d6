"""What machine a measurement ran on: every figure in docs/ names it."""

from __future__ import annotations

import os
import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU model from /proc/cpuinfo (Linux), else the platform's processor string."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_info() -> dict[str, object]:
    """This machine as a dict: CPU count ``nproc``, ``cpu`` model, ``os`` and ``python`` versions."""
    return {"nproc": os.cpu_count(), "cpu": cpu_model(), "os": f"{platform.system()} {platform.release()}",
            "python": platform.python_version()}


def machine_line() -> str:
    """One line for a doc: cores, CPU, OS, Python."""
    m = machine_info()
    return f"{m['nproc']} CPU cores (nproc), {m['cpu']}, {m['os']}, Python {m['python']}"
