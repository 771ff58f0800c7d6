"""The bench wire protocol: framing, messages, the link over pyserial, faults, the envelope."""

from __future__ import annotations

import math
import struct
import time
import zlib

import pytest

from addedinertia_env.sim.motor import MotorCommand
from hw_adapter import messages as m
from hw_adapter.faults import FaultSpecError, parse_faults
from hw_adapter.framing import (HEADER, MAX_FRAME, MAX_PAYLOAD, MAX_PAYLOAD_V2, ClockUnwrapper, FrameError, FrameParser, encode_frame,
                                seq_gap)
from hw_adapter.link import Link
from hw_adapter.safety import SafetyEnvelope, SafetyLimits, SafetyTrip
from hw_adapter.watchdog import Watchdog

SAMPLE = m.Sample(phi_count=-13107, psi_count=2**31 - 5, current=1.5, voltage=-3.25, brake=True,
                  status=m.ST_ARMED | m.ST_BRAKE_REQUESTED, faults=0, cmd_seq=41, step=7)


def frame_of(msg, seq=3, time_us=123456) -> bytes:
    return encode_frame(msg.type, seq, time_us, msg.pack())


def test_frame_layout_matches_the_documented_offsets():
    data = frame_of(m.Empty(m.HEARTBEAT, 0x0102), seq=0x0A0B, time_us=0x01020304)
    assert data[:2] == b"\xa5\x5a"
    assert data[2] == 1 and data[3] == m.HEARTBEAT
    assert struct.unpack_from("<HHI", data, 4) == (0x0A0B, 2, 0x01020304)
    assert data[12:14] == b"\x02\x01"
    assert struct.unpack_from("<I", data, 14)[0] == zlib.crc32(data[:14])
    assert len(data) == HEADER.size + 2 + 4


def test_documented_example_frame_decodes():
    """The HEARTBEAT example in docs/PROTOCOL.md, byte for byte."""
    example = bytes.fromhex("a55a0109050002000a0000000000724ca5cd")
    frames = FrameParser().feed(example)
    assert len(frames) == 1 and frames[0].type == m.HEARTBEAT and frames[0].seq == 5 and frames[0].time_us == 10
    assert example == encode_frame(m.HEARTBEAT, 5, 10, m.Empty(m.HEARTBEAT).pack())


def test_every_hex_example_in_protocol_md_is_a_valid_frame():
    import re
    from pathlib import Path

    doc = Path(__file__).resolve().parents[1] / "docs" / "PROTOCOL.md"
    examples = re.findall(r"\b(a55a[0-9a-f]{28,})\b", doc.read_text())
    assert len(examples) >= 4, "docs/PROTOCOL.md should show example frames in hex"
    for text in examples:
        frames = FrameParser().feed(bytes.fromhex(text))
        assert len(frames) == 1, text
        m.decode(frames[0])


@pytest.mark.parametrize("msg", [
    m.Hello(3),
    m.Caps(1, m.CAP_EMULATOR, 1000, 131072, 16384, 15.0, 48.0, 50, 20, "bench-7"),
    m.Reset(-0.125, 0.5, 2.0, True),
    m.Empty(m.ARM), m.Empty(m.DISARM, 8), m.Empty(m.QUERY),
    m.Command("current", -7.5, False, 65535),
    SAMPLE,
    m.Fault(m.F_WATCHDOG, m.F_WATCHDOG | m.F_BRAKE, 51.0),
])
def test_every_message_round_trips_through_a_frame(msg):
    frames = FrameParser().feed(frame_of(msg))
    assert len(frames) == 1
    back = m.decode(frames[0])
    assert back == msg
    assert len(msg.pack()) <= MAX_PAYLOAD


def test_parser_takes_bytes_in_any_chunks_and_skips_garbage():
    stream = b"\x00garbage\xa5" + frame_of(SAMPLE, seq=1) + b"\xa5\x5a\xff" + frame_of(m.Empty(m.ARM), seq=2)
    parser = FrameParser()
    frames = []
    for k in range(len(stream)):
        frames += parser.feed(stream[k:k + 1])
    assert [f.seq for f in frames] == [1, 2]
    assert parser.stats.skipped_bytes > 0
    assert parser.buffered == 0


def test_parser_rejects_bad_crc_version_and_length():
    good = bytearray(frame_of(SAMPLE))
    bad_crc = bytearray(good)
    bad_crc[20] ^= 0x10
    bad_version = bytearray(good)
    bad_version[2] = 3
    bad_length = bytearray(good)
    bad_length[6:8] = struct.pack("<H", MAX_PAYLOAD + 1)
    parser = FrameParser()
    assert parser.feed(bytes(bad_crc) + bytes(bad_version) + bytes(bad_length)) == []
    assert (parser.stats.bad_crc, parser.stats.bad_version, parser.stats.bad_length) == (1, 1, 1)
    assert [f.seq for f in parser.feed(bytes(good))] == [3]  # and it recovers at once


def test_decode_refuses_unknown_types_and_wrong_sizes():
    with pytest.raises(m.MessageError, match="unknown message type"):
        m.decode(FrameParser().feed(encode_frame(0x7F, 0, 0, b""))[0])
    with pytest.raises(m.MessageError, match="expected 24"):
        m.decode(FrameParser().feed(encode_frame(m.SAMPLE, 0, 0, b"\x00" * 23))[0])
    with pytest.raises(m.MessageError, match="mode"):
        m.decode(FrameParser().feed(encode_frame(m.COMMAND, 0, 0, struct.pack("<BBHf", 9, 0, 0, 1.0)))[0])
    with pytest.raises(m.MessageError, match="finite"):
        m.decode(FrameParser().feed(encode_frame(m.COMMAND, 0, 0, struct.pack("<BBHf", 1, 0, 0, math.nan)))[0])
    with pytest.raises(FrameError):
        encode_frame(m.SAMPLE, 0, 0, b"\x00" * (MAX_PAYLOAD + 1))


def test_sequence_gaps_and_clock_wrap():
    assert seq_gap(None, 5) == 0
    assert seq_gap(5, 6) == 0
    assert seq_gap(65535, 0) == 0
    assert seq_gap(65534, 2) == 3
    clock = ClockUnwrapper()
    assert [clock(t) for t in (2**32 - 1000, 2**32 - 1, 5, 1005)] == [2**32 - 1000, 2**32 - 1, 2**32 + 5, 2**32 + 1005]


def test_fault_names():
    assert m.fault_names(m.F_WATCHDOG | m.F_BRAKE) == ["watchdog", "brake"]
    assert m.fault_names(0) == []


def test_link_over_pyserial_loop_url_round_trips_messages():
    link = Link("loop://")
    try:
        seqs = [link.send(msg) for msg in (SAMPLE, m.Empty(m.HEARTBEAT, 9))]
        got = [link.recv(0.5) for _ in seqs]
        assert [f.seq for f, _ in got] == seqs == [0, 1]
        assert got[0][1] == SAMPLE and got[1][1] == m.Empty(m.HEARTBEAT, 9)
        assert link.recv(0.01) is None
        link.port.write(b"\xa5\x5a\x01\x07" + b"\x00" * 30)  # a frame with a bad CRC
        link.send(m.Empty(m.QUERY))
        frame, msg = link.recv(0.5)
        assert msg == m.Empty(m.QUERY)
        assert link.parser.stats.bad_crc >= 1 and link.errors >= 1
    finally:
        link.close()


def test_link_reports_a_port_that_cannot_open():
    from hw_adapter.link import LinkError

    with pytest.raises(LinkError, match="cannot open bench link"):
        Link("socket://127.0.0.1:1", open_timeout_s=0.2)


def test_fault_spec_grammar():
    plan = parse_faults("drop=0.5@1.0, latency=5,jitter=2,stuck_brake@0.5,glitch,seed=7")
    assert plan.seed == 7
    assert plan.active("drop", 0.99) == 0.0 and plan.active("drop", 1.0) == 0.5
    assert plan.active("latency", 0.0) == 5.0
    assert plan.active("glitch", 0.0) == 0.2
    assert plan.active("stuck_brake", 0.4) == 0.0 and plan.active("stuck_brake", 0.5) > 0
    assert parse_faults("").empty and parse_faults("none").empty
    for bad, why in [("boom", "unknown fault"), ("drop=2", "0..1"), ("drop", "needs a value"),
                     ("drop=0.1,drop=0.2", "twice"), ("latency=x", "not a number"), ("glitch@-1", ">= 0")]:
        with pytest.raises(FaultSpecError, match=why):
            parse_faults(bad)


def test_envelope_clamps_commands_to_the_limits():
    env = SafetyEnvelope(SafetyLimits(i_max=10.0, u_max=24.0), phi_neutral=0.0)
    assert env.clamp(MotorCommand("current", 25.0)).value == 10.0
    assert env.clamp(MotorCommand("current", -25.0)).value == -10.0
    assert env.clamp(MotorCommand("voltage", 30.0)).value == 24.0
    assert env.clamp(MotorCommand("current", 3.0)).value == 3.0
    assert env.clamp(MotorCommand("passive", 0.0)) == MotorCommand("passive", 0.0)
    assert env.clamped == 3 and env.max_abs_current_sent == 10.0


@pytest.mark.parametrize("sample, kind", [
    ((0.001, 0.5, 0.0, 0.0, 0.0), "angle"),
    ((0.001, 0.0011, 0.0, 0.0, 0.0), "rate"),  # 1.1 rad/s
    ((0.001, 0.0, 0.5, 0.0, 0.0), "flywheel_rate"),  # 500 rad/s
    ((0.001, 0.0, 0.0, 12.5, 0.0), "current"),
    ((0.001, 0.0, 0.0, 0.0, 60.0), "voltage"),
    ((0.001, math.nan, 0.0, 0.0, 0.0), "sensor"),
    ((0.0, 0.0, 0.0, 0.0, 0.0), "sensor"),  # time did not advance
])
def test_envelope_trips_on_each_limit(sample, kind):
    env = SafetyEnvelope(SafetyLimits(i_max=10.0, u_max=48.0, phi_max=0.35, rate_max=1.0, flywheel_rate_max=400.0),
                         phi_neutral=0.0)
    env.check(0.0, 0.0, 0.0, 0.0, 0.0)
    with pytest.raises(SafetyTrip) as e:
        env.check(*sample)
    assert e.value.kind == kind


def test_envelope_passes_a_normal_sample_and_refuses_bad_limits():
    env = SafetyEnvelope(SafetyLimits(), phi_neutral=0.0)
    env.check(0.0, -0.1, 0.0, 0.0, 0.0)
    env.check(0.001, -0.0999, 0.05, 14.0, 30.0)
    with pytest.raises(ValueError, match="phi_max"):
        SafetyLimits(phi_max=-1.0)


class FakeClock:
    """Seconds that move only when the test says so."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_watchdog_fires_once_when_not_kicked_and_never_when_kicked_or_paused():
    """The watchdog's rule on a fake clock, so machine load cannot change the answer."""
    clock, fired = FakeClock(), []
    dog = Watchdog(0.02, fired.append, clock=clock, start=False)
    dog.arm(True)
    for _ in range(100):  # kicked every 5 ms for half a second: never fires
        clock.now += 0.005
        dog.kick()
        assert not dog.poll()
    clock.now += 0.019  # quiet, but not yet longer than the timeout
    assert not dog.poll() and not fired
    clock.now += 0.002
    assert dog.poll() and len(fired) == 1 and "no sample for 21.0 ms (watchdog 20 ms)" in fired[0]
    assert dog.expired and dog.expired_at == clock.now
    clock.now += 1.0
    assert not dog.poll() and len(fired) == 1  # once only
    calls = []
    paused = Watchdog(0.01, calls.append, clock=clock, start=False)
    paused.arm(False)
    clock.now += 10.0
    assert not paused.poll() and not calls
    paused.arm(True)  # arming starts the quiet time afresh: the 10 s paused do not count
    assert not paused.poll()
    clock.now += 0.011
    assert paused.poll() and len(calls) == 1


def test_watchdog_thread_fires_once_on_its_own_and_never_while_paused():
    """The real thread and clock: it fires by itself (once) when nobody kicks it, and a paused
    one stays silent. Only bounds that a loaded machine cannot break are asserted; the timing
    rule itself is the fake-clock test above."""
    fired = []
    dog = Watchdog(0.02, fired.append)
    try:
        t0 = time.perf_counter()
        dog.arm(True)
        while not fired and time.perf_counter() - t0 < 10.0:
            time.sleep(0.002)
        assert len(fired) == 1 and "no sample" in fired[0]
        assert dog.expired_at - t0 >= 0.02  # never before its timeout
        time.sleep(0.05)
        assert len(fired) == 1
    finally:
        dog.close()
    quiet = []
    dog = Watchdog(0.01, quiet.append)
    try:
        dog.arm(False)
        time.sleep(0.05)
        assert not quiet
    finally:
        dog.close()


def test_max_frame_bound():
    assert MAX_FRAME == HEADER.size + MAX_PAYLOAD_V2 + 4
