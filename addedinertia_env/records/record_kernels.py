"""Compiled loops over a run record's columns (numba): phase names as text, and masked sums' terms.

A record's ``phase`` column is a numpy array of fixed-width text (``<U7``: each name as
UCS-4 code points padded with zeros). :func:`phase_mask` compares it with names as numpy's
``phase == name`` does (trailing zeros are padding), one pass for several names;
:func:`masked_power_steps`
gives the terms of the electric energy integral in numpy's order. Each is the numpy
expression its docstring names, value for value (tests/test_metrics.py holds them equal).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def rows_matching(codes, patterns, out):  # pragma: no cover - compiled
    """``out[j]``: whether row ``j`` of ``codes`` (n x width, uint32, C-contiguous) equals a row of
    ``patterns``."""
    n, width = codes.shape
    flat = codes.reshape(-1)
    for j in range(n):
        base = j * width
        hit = False
        for p in range(patterns.shape[0]):
            if flat[base] != patterns[p, 0]:  # most rows differ at the first character
                continue
            c = 1
            while c < width and flat[base + c] == patterns[p, c]:
                c += 1
            if c == width:
                hit = True
                break
        out[j] = hit


@njit(cache=True)
def masked_power_steps(t, u, i, mask, out):  # pragma: no cover - compiled
    """``np.abs(u * i)[mask] * np.diff(t, prepend=t[0])[mask]`` into ``out`` (as long as ``mask``'s count)."""
    m = 0
    for j in range(len(t)):
        if mask[j]:
            dt = t[j] - t[j - 1] if j > 0 else t[0] - t[0]
            out[m] = abs(u[j] * i[j]) * dt
            m += 1


@njit(cache=True)
def masked_limit_count(mask, i_cmd, i_threshold, u_cmd, i, u_threshold, i_max, voltage):  # pragma: no cover
    """How many samples ``j`` with ``mask[j]`` have their command at its limit: ``np.count_nonzero(at[mask])``
    with ``at = np.abs(i_cmd) >= i_threshold``, or'ed (when ``voltage``) with ``(u_cmd != 0.0) &
    ((np.abs(u_cmd) >= u_threshold) | (np.abs(i) >= i_max))`` (:func:`~addedinertia_env.experiment.metrics.samples_at_limit`)."""
    count = 0
    for j in range(len(mask)):
        if mask[j]:
            if abs(i_cmd[j]) >= i_threshold:
                count += 1
            elif voltage and u_cmd[j] != 0.0 and (abs(u_cmd[j]) >= u_threshold or abs(i[j]) >= i_max):
                count += 1
    return count


def _codes(names, width: int) -> np.ndarray:
    """``names`` as rows of UCS-4 code points, zero-padded to ``width`` (uint32)."""
    rows = np.zeros((len(names), width), dtype=np.uint32)
    for p, name in enumerate(names):
        rows[p, :len(name)] = [ord(ch) for ch in name]
    return rows


def phase_mask(phase, names: tuple[str, ...]) -> np.ndarray:
    """``(phase == names[0]) | (phase == names[1]) | ...`` (bool per sample) for a text array ``phase``."""
    phase = np.asarray(phase)
    width = phase.dtype.itemsize // 4
    if phase.dtype.kind != "U" or phase.ndim != 1 or width == 0:
        mask = phase == names[0]
        for name in names[1:]:
            mask = mask | (phase == name)
        return np.asarray(mask, dtype=bool)
    codes = np.ascontiguousarray(phase).view(np.uint32).reshape(len(phase), width)
    fits = tuple(name for name in names if len(name) <= width)  # a longer name equals no entry
    out = np.empty(len(phase), dtype=bool)
    rows_matching(codes, _codes(fits, width), out)
    return out
