"""Fuzzing the frame parser and the message decoder with hypothesis.

Properties: ``FrameParser.feed`` never raises, whatever it is fed and however it is
chunked; its buffer never exceeds one maximal frame; it returns quickly (linear in the
input); every frame it returns has a valid CRC; ``decode`` raises nothing but
``MessageError``; valid frames survive any garbage around them.
"""

from __future__ import annotations

import struct
import time
import zlib

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hw_adapter import messages as m
from hw_adapter.framing import HEADER, MAX_FRAME, MAX_PAYLOAD, MAX_PAYLOAD_V2, SYNC, FrameParser, encode_frame

# derandomize: the same examples on every run, so CI is reproducible. To explore further,
# run these tests by hand with derandomize off and more examples.
FUZZ = settings(max_examples=100, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

messages = st.one_of(
    st.builds(m.Command, st.sampled_from(["passive", "current", "voltage"]),
              st.floats(-100, 100, width=32), st.booleans(), st.integers(0, 0xFFFF)),
    st.builds(m.Sample, st.integers(-2**31, 2**31 - 1), st.integers(-2**31, 2**31 - 1),
              st.floats(-50, 50, width=32), st.floats(-60, 60, width=32), st.booleans(),
              st.integers(0, 255), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)),
    st.builds(m.Empty, st.sampled_from([m.ARM, m.DISARM, m.HEARTBEAT, m.QUERY]), st.integers(0, 0xFFFF)),
    st.builds(m.Fault, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.floats(-1e3, 1e3, width=32)),
)


def frame_bytes(msg, seq: int) -> bytes:
    return encode_frame(msg.type, seq, seq * 1000, msg.pack())


def feed_checked(parser: FrameParser, data: bytes, chunks: list[int]):
    """Feed ``data`` in ``chunks``; check the invariants after each call."""
    out = []
    pos = 0
    sizes = chunks or [len(data)]
    k = 0
    while pos < len(data):
        n = max(1, sizes[k % len(sizes)])
        k += 1
        frames = parser.feed(data[pos:pos + n])
        pos += n
        assert parser.buffered < MAX_FRAME
        for f in frames:
            assert f.version in (1, 2) and len(f.payload) <= (MAX_PAYLOAD if f.version == 1 else MAX_PAYLOAD_V2)
            raw = encode_frame(f.type, f.seq, f.time_us, f.payload, version=f.version)
            assert zlib.crc32(raw[:-4]) == struct.unpack("<I", raw[-4:])[0]
            try:
                m.decode(f)
            except m.MessageError:
                pass
        out += frames
    return out


@FUZZ
@given(st.binary(max_size=4096), st.lists(st.integers(1, 300), max_size=20))
def test_random_bytes_never_crash_and_stay_bounded(data, chunks):
    parser = FrameParser()
    t0 = time.perf_counter()
    feed_checked(parser, data, chunks)
    assert time.perf_counter() - t0 < 2.0


@FUZZ
@given(st.lists(messages, min_size=1, max_size=8), st.binary(max_size=200), st.lists(st.integers(1, 64), max_size=8))
def test_valid_frames_survive_garbage_between_them(msgs, garbage, chunks):
    # Garbage is cut where it could complete a sync word with the next frame's start.
    garbage = garbage.replace(SYNC, b"").rstrip(SYNC[:1])
    data = b"".join(garbage + frame_bytes(msg, k) for k, msg in enumerate(msgs))
    frames = feed_checked(FrameParser(), data, chunks)
    got = [m.decode(f) for f in frames if f.seq < len(msgs) and f.time_us == f.seq * 1000]
    # Garbage cannot hide a frame: a false sync inside it is a frame with a bad CRC
    # (probability 2^-32) or a length that overruns into the real frame; either way the
    # parser drops one byte and hunts on, so every real frame is found.
    assert [type(g) for g in got][-len(msgs):] == [type(x) for x in msgs]


@FUZZ
@given(messages, st.integers(0, 8 * 40 - 1))
def test_one_bit_flip_is_always_rejected(msg, bit):
    data = bytearray(frame_bytes(msg, 1))
    bit %= len(data) * 8
    data[bit // 8] ^= 1 << (bit % 8)
    parser = FrameParser()
    frames = parser.feed(bytes(data))
    assert frames == []  # CRC-32 detects every single-bit error; a hit sync word or header is refused
    assert parser.buffered < MAX_FRAME
    # and the next good frame is found at once
    assert len(parser.feed(frame_bytes(msg, 2) * 2)) >= 1


@FUZZ
@given(messages, st.integers(1, 60))
def test_truncated_frames_wait_then_resync(msg, cut):
    whole = frame_bytes(msg, 1)
    cut = min(cut, len(whole) - 1)
    parser = FrameParser()
    assert parser.feed(whole[:cut]) == []
    second = frame_bytes(msg, 2)
    frames = parser.feed(second)
    missing = len(whole) - cut
    if whole[cut:] == second[:missing]:
        # The next frame's first bytes happen to equal the truncated frame's missing tail
        # (its last CRC byte equal to the sync byte: odds 1 in 256 per byte): the bytes
        # received really are a valid frame 1, and frame 2 lost its start. No parser
        # can tell; hypothesis found this case.
        assert [f.seq for f in frames][:1] == [1]
    else:
        # The truncated frame's CRC fails against the new bytes; the new frame is still found.
        assert [f.seq for f in frames][-1:] == [2]


@FUZZ
@given(st.integers(MAX_PAYLOAD + 1, 0xFFFF), st.integers(0, 255), st.binary(max_size=600))
def test_huge_declared_lengths_are_refused_without_buffering(length, msg_type, tail):
    head = HEADER.pack(SYNC, 1, msg_type, 0, length, 0)
    parser = FrameParser()
    frames = parser.feed(head + tail)
    assert parser.stats.bad_length >= 1
    assert parser.buffered < MAX_FRAME
    for f in frames:
        assert len(f.payload) <= MAX_PAYLOAD


@FUZZ
@given(st.integers(0, 255), st.binary(max_size=MAX_PAYLOAD))
def test_decode_raises_only_message_error(msg_type, payload):
    frames = FrameParser().feed(encode_frame(msg_type, 0, 0, payload))
    assert len(frames) == 1
    try:
        m.decode(frames[0])
    except m.MessageError:
        pass


def test_a_megabyte_of_noise_is_parsed_fast_in_bounded_memory():
    import random

    rng = random.Random(0)
    noise = rng.randbytes(1 << 20)
    parser = FrameParser()
    t0 = time.perf_counter()
    for k in range(0, len(noise), 4096):
        parser.feed(noise[k:k + 4096])
        assert parser.buffered < MAX_FRAME
    assert time.perf_counter() - t0 < 10.0
