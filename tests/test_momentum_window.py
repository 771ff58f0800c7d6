"""The momentum consistency check (records/consistency.py) bounds the change of two windowed rates by the
impulse over both windows: an honest episode whose current steps up at the reverse stroke's start (the
shipped 100 Hz policy's zero-order hold) is not refused. Before, the impulse ran from the last held
sample to the sample judged only, while that sample's centred rate already saw the current of the next
10 ms: 4 of standard-v0's 30 test episodes of this policy were refused (up to 15 x the bound)."""

from __future__ import annotations

from pathlib import Path

import pytest

from addedinertia_env.bench import runner
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.records.consistency import momentum_account

POLICY = Path(__file__).resolve().parents[1] / "agents" / "policies" / "reverse_stroke_100hz.onnx"


def test_a_current_step_at_the_strokes_start_is_within_the_bound(monkeypatch):
    if not POLICY.exists():
        pytest.skip("the shipped 100 Hz policy is absent")
    kept = []
    score = runner.score_episode

    def keep(records, *a, **k):
        kept.append(list(records))
        return score(records, *a, **k)

    monkeypatch.setattr(runner, "score_episode", keep)
    suite = load_suite("standard-v0")
    scenario = next(s for s in suite.scenarios("test") if s.seed == 200011)
    row = runner.run_episode(suite.task(scenario, f"onnx:{POLICY}"))
    assert row.get("failure") is None, row.get("failure")
    account = momentum_account(kept[0][0])
    assert account["used"] < 1.0  # degrees are still refused: tests/test_bad_inputs.py
