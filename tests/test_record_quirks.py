"""Records from other DAQs (issue 11, Build 1-2): everything run-record.md allows is read.

``L`` 0 or absent, columns in any order, extra columns kept, CRLF and a byte-order mark,
250 Hz to 10 kHz, dropped samples and a jittered clock (measured, not assumed away),
long gaps reported, and segmentation by ``phase`` and ``brake`` together.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from addedinertia_env.records.record import (
    FORMAT,
    RecordError,
    RunRecord,
    braked,
    current_sampling,
    motion_phase,
    read_record,
    rig_inductance,
    sampling,
    write_record,
)
from addedinertia_env.sim.params import RigParams


def _record(rate: float = 1000.0, n: int = 400, t: np.ndarray | None = None, brake_tail: bool = True) -> RunRecord:
    """idle (braked) > free > hold > reverse > idle (braked tail), ``n`` samples at ``rate``."""
    t = np.arange(n) / rate if t is None else t
    n = len(t)
    k = np.arange(n)
    phase = np.where(k < n // 8, "idle", np.where(k < n // 2, "free", np.where(k < 5 * n // 8, "hold", "reverse")))
    brake = ((k < n // 8) | ((k >= n // 2) & (k < 5 * n // 8))).astype(float)
    if brake_tail:
        brake[k >= 7 * n // 8] = 1.0  # the brake set while the phase still says 'reverse'
    samples = {"t": t, "phase": phase.astype(str), "phi": -0.08 * np.cos(2 * np.pi * t / 4.0), "psi": 0.3 * t,
               "u": 0.1 + 0.01 * np.sin(t), "i": 0.002 * np.cos(t), "brake": brake}
    rig = RigParams().known().to_block()
    meta = {"format": FORMAT, "run_id": "q", "source": "bench", "rig": dict(rig, sample_rate=rate),
            "experiment": {"kind": "reverse-symmetric", "alpha": 0.08, "hold_s": 0.0}}
    return RunRecord(samples=samples, meta=meta)


def _write(tmp_path, rec: RunRecord, name: str = "run.csv"):
    return write_record(rec, tmp_path / name)


@pytest.mark.parametrize("value", [0.0, None])
def test_inductance_zero_or_absent_is_read(tmp_path, value):
    rec = _record()
    if value is None:
        del rec.meta["rig"]["L"]
    else:
        rec.meta["rig"]["L"] = value
    back = read_record(_write(tmp_path, rec))
    assert rig_inductance(back.rig) == value


def test_negative_inductance_is_refused(tmp_path):
    rec = _record()
    rec.meta["rig"]["L"] = -1e-3
    with pytest.raises(RecordError, match=r"rig\.L.*expected a finite number >= 0"):
        read_record(_write(tmp_path, rec))


def test_current_sampling_key_is_validated_with_a_documented_default(tmp_path):
    rec = _record()
    assert current_sampling(rec.rig) == ("instant", False)
    rec.meta["rig"]["current_sampling"] = "held-previous"
    assert current_sampling(read_record(_write(tmp_path, rec)).rig) == ("held-previous", True)
    rec.meta["rig"]["current_sampling"] = "zoh"
    with pytest.raises(RecordError, match="current_sampling"):
        read_record(_write(tmp_path, rec, "bad.csv"))


def test_any_column_order_extra_columns_crlf_and_bom(tmp_path):
    rec = _record()
    path = _write(tmp_path, rec)
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    order = list(reversed(range(len(header))))
    rows = [",".join([row.split(",")[j] for j in order] + [extra]) for row, extra in
            zip(lines, ["daq_temp"] + [f"{20 + 0.01 * k:.2f}" for k in range(len(lines) - 1)])]
    path.write_bytes(("\ufeff" + "\r\n".join(rows) + "\r\n").encode("utf-8"))
    back = read_record(path)
    for col in ("t", "phi", "psi", "u", "i", "brake"):
        np.testing.assert_allclose(back[col], rec[col], rtol=0, atol=1e-12)
    assert list(back.phase) == list(rec.phase)
    assert "daq_temp" in back.samples and len(back["daq_temp"]) == len(rec)
    again = read_record(write_record(back, tmp_path / "again.csv"))
    assert "daq_temp" in again.samples  # kept on round trip


@pytest.mark.parametrize("rate", [250.0, 10_000.0])
def test_sample_rates_across_the_spec_range(tmp_path, rate):
    back = read_record(_write(tmp_path, _record(rate=rate, n=int(rate))))
    s = sampling(back)
    assert s.uniform and s.dropped == 0 and s.in_spec_range
    assert s.median_interval == pytest.approx(1 / rate, rel=1e-6)


def test_dropped_samples_and_jitter_are_measured_not_refused(tmp_path):
    rng = np.random.default_rng(3)
    rate = 500.0
    t = np.arange(1000) / rate
    t = t + rng.normal(0.0, 0.02 / rate, t.size)  # 2 % clock jitter
    keep = np.ones(t.size, bool)
    keep[[100, 101, 400, 777]] = False  # three drops: two together (one interval of 3 periods), two single
    rec = _record(rate=rate, t=t[keep])
    back = read_record(_write(tmp_path, rec))
    s = sampling(back)
    assert s.dropped == 4
    assert not s.uniform
    assert 0.01 / rate < s.jitter_rms < 0.04 / rate
    assert s.gaps == ()  # nothing beyond five periods
    json.dumps(s.to_json())


def test_a_gap_over_five_periods_is_reported_not_fatal(tmp_path):
    t = np.arange(400) / 1000.0
    t[200:] += 0.0075  # 7.5 ms missing at t = 0.199 s
    back = read_record(_write(tmp_path, _record(t=t)))
    s = sampling(back)
    assert len(s.gaps) == 1 and s.gaps[0][1] == pytest.approx(0.0085, abs=1e-9)


def test_a_braked_sample_is_never_free_motion():
    rec = _record()
    mp = motion_phase(rec)
    held = braked(rec)
    assert not np.any(held & np.isin(mp, ("free", "reverse")))
    n = len(rec)
    # the braked tail that still says 'reverse' is idle; the reversal hold stays hold
    assert set(mp[7 * n // 8:]) == {"idle"}
    assert set(mp[n // 2: 5 * n // 8]) == {"hold"}
    assert set(mp[n // 8: n // 2]) == {"free"}
    # a braked 'reverse' sample at the start of the stroke (brake released late) is hold
    rec.samples["brake"][5 * n // 8: 5 * n // 8 + 3] = 1.0
    assert set(motion_phase(rec)[5 * n // 8: 5 * n // 8 + 3]) == {"hold"}


def test_without_a_brake_column_the_phase_is_taken_as_is():
    rec = _record()
    del rec.samples["brake"]
    assert list(motion_phase(rec)) == list(rec.phase)
