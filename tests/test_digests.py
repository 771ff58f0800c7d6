"""The digest harness (addedinertia_env/reports/digests.py) tells equal numbers from moved ones."""

from __future__ import annotations

import math

from addedinertia_env.reports.digests import _sha, compare

import numpy as np


def test_compare_says_identical_within_tolerance_or_different():
    base = {"bench": {"a": {"rel_error": 0.001, "ci95": [1.0, 2.0], "failure": None}}, "env": {"x": {"sha": "ab"}}}
    assert compare(base, base) == (True, ["bench: identical bit for bit", "env: identical bit for bit"])
    moved = {"bench": {"a": {"rel_error": 0.001 * (1 + 1e-15), "ci95": [1.0, 2.0], "failure": None}},
             "env": {"x": {"sha": "ab"}}}
    ok, lines = compare(base, moved)
    assert not ok and "largest relative" in lines[0]
    assert compare(base, moved, rtol=1e-12)[0]
    changed_hash = {**base, "env": {"x": {"sha": "cd"}}}
    ok, lines = compare(base, changed_hash, rtol=1.0)
    assert not ok and any("'ab' -> 'cd'" in line for line in lines)
    assert compare({"s": {"v": math.nan}}, {"s": {"v": math.nan}})[0]


def test_float_hash_sees_the_last_bit():
    x = np.array([0.1, 0.2])
    assert _sha(x) == _sha(x.copy())
    assert _sha(x) != _sha(np.nextafter(x, 1.0))
