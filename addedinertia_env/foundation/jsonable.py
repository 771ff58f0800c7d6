"""Values made ready for strict JSON: numpy scalars and arrays to Python, non-finite numbers to ``null``."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def plain(x: Any) -> Any:
    """``x`` with dict keys as str, tuples and arrays as lists, numpy numbers as Python numbers,
    and NaN or infinite floats as ``None`` (JSON ``null``), recursively."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    return x
