"""The board's inner loop (two-rate bench, protocol version 2): arithmetic, deadlines, the
grace and the safe state, on the loop itself, on the emulated board, and over the wire."""

from __future__ import annotations

import math

import pytest

from addedinertia_env.loop.board_loop import (
    DEFAULT_GRACE_US,
    HORIZON_PERIODS,
    BoardLoop,
    Segment,
    elapsed_us,
    zoh_segment,
)
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from hw_adapter import messages as m
from hw_adapter.board import Board
from hw_adapter.framing import FrameParser, encode_frame

DT_US = 1000


def seg(**kw) -> Segment:
    base = dict(seg_id=1, t0_us=10_000, duration_us=20_000, deadline_us=20_000, knot_us=10_000,
                currents=(1.0, 3.0, 2.0), brake=False)
    return Segment(**{**base, **kw})


def test_profile_is_piecewise_linear_and_held_within_the_grace():
    loop = BoardLoop(DT_US, i_max=15.0)
    assert loop.offer(seg(), now_us=10_000)
    # knots 1 A at t0, 3 A at +10 ms, 2 A at +20 ms
    for now, want in ((10_000, 1.0), (15_000, 2.0), (20_000, 3.0), (25_000, 2.5), (30_000, 2.0)):
        out = loop.command(now, phi=0.0)
        assert out.command.mode == "current" and out.command.value == pytest.approx(want) and not out.hold
    out = loop.command(30_000 + DEFAULT_GRACE_US, phi=0.0)  # ran out, still within the grace: hold
    assert out.hold and not out.starved and out.command.value == pytest.approx(2.0)
    out = loop.command(30_000 + DEFAULT_GRACE_US + DT_US, phi=0.0)  # one sample past the grace: safe
    assert out.starved and out.command.mode == "passive" and out.brake


def test_late_segment_is_counted_and_dropped():
    loop = BoardLoop(DT_US, i_max=15.0)
    assert loop.offer(seg(), now_us=10_000)
    late = seg(seg_id=2, t0_us=12_000, deadline_us=13_000, currents=(-5.0,))
    assert not loop.offer(late, now_us=13_001)
    assert loop.late_segments == 1 and loop.segment.seg_id == 1


def test_pd_acts_only_with_the_brake_released_and_the_brake_switch_lands_on_its_sample():
    loop = BoardLoop(DT_US, i_max=15.0)
    s = seg(currents=(0.5, 0.5), phi_refs=(0.1, 0.1), kp=-10.0, kd=0.0, knot_us=20_000, brake=True,
            brake_switch_us=15_000)
    loop.offer(s, 10_000)
    braked = loop.command(14_000, phi=0.0)
    assert braked.brake and braked.command.value == pytest.approx(0.5)  # braked: feed-forward only
    free = loop.command(15_000, phi=0.0)
    assert not free.brake and free.command.value == pytest.approx(0.5 - 10.0 * 0.1)
    clamp = BoardLoop(DT_US, i_max=2.0)
    clamp.offer(seg(currents=(9.0,)), 10_000)
    assert clamp.command(10_000, 0.0).command.value == 2.0


def test_a_segment_ending_in_the_safe_command_never_starves():
    loop = BoardLoop(DT_US, i_max=15.0)
    loop.offer(zoh_segment(1, MotorCommand("passive", 0.0), True, 0, 10_000), 0)
    out = loop.command(10**6, 0.0)
    assert not out.starved and out.command.mode == "passive" and out.brake


def test_elapsed_is_wrap_safe():
    assert elapsed_us(5, 2**32 - 5) == 10 and elapsed_us(2**32 - 5, 5) == -10


def armed_two_rate_board() -> Board:
    board = Board(rig_from_mapping(load_preset("wigley-2m")), lockstep=False)
    caps = board.handle(m.Hello(), 0, version=2)[0]
    assert caps.two_rate and caps.grace_ms * 1000 == DEFAULT_GRACE_US
    board.handle(m.Reset(0.0), 1, version=2)
    board.handle(m.Empty(m.ARM), 2, version=2)
    assert board.armed
    return board


@pytest.mark.parametrize("case", ["missing", "late"])
def test_board_reaches_the_safe_state_within_the_stated_grace(case):
    """The host stops sending (missing), or its next segment comes after its deadline
    (late: counted and dropped): the board holds the last segment for the grace, then goes
    to the safe state by itself, with fault SEGMENTS, at the sample the grace ends."""
    board = armed_two_rate_board()
    period = 10_000
    t0 = board.time_us
    board.handle(m.SegmentMsg(zoh_segment(1, MotorCommand("current", 2.0), False, t0, period)), 3, version=2)
    end = t0 + HORIZON_PERIODS * period
    safe_at = None
    for _ in range(200):
        if case == "late" and board.time_us == t0 + 2 * period + DT_US:
            late = zoh_segment(2, MotorCommand("current", 1.0), False, t0 + period, period)
            board.handle(m.SegmentMsg(late), 4, version=2)  # deadline t0 + 2 periods: one sample ago
        now = board.time_us
        board.tick()
        if not board.armed:
            safe_at = now
            break
    assert board.loop.late_segments == (1 if case == "late" else 0)
    assert safe_at is not None and board.fault_bits & m.F_SEGMENTS
    assert safe_at - end == DEFAULT_GRACE_US + DT_US  # the first sample past the grace
    assert board.is_safe and board.cmd.mode == "passive" and board.brake_request


def test_version_2_messages_round_trip_and_version_1_frames_do_not_carry_them():
    s = seg(phi_refs=(0.125, 0.25, 0.5), kp=-3.0, kd=-0.5, brake_switch_us=12_345, end_passive=True)
    frame = FrameParser().feed(encode_frame(m.SEGMENT, 7, 0, m.SegmentMsg(s).pack(), version=2))[0]
    assert m.decode(frame).segment == s
    samples = tuple(m.Sample(k, -k, 0.5 * k, 1.0, True, m.ST_ARMED, 0, 3, 40 + k, 0.25 * k) for k in range(9))
    batch = m.SampleBatch(40, 2, 3, samples)
    frame = FrameParser().feed(encode_frame(m.SAMPLE_BATCH, 8, 1000, batch.pack(), version=2))[0]
    got = m.decode(frame)
    assert got.samples == samples and got.late_segments == 2
    assert [t for t, _ in got.expand(frame.time_us, 1000)][:2] == [1000, 2000]
    v1 = FrameParser().feed(encode_frame(m.SEGMENT, 9, 0, m.SegmentMsg(seg()).pack()[:60], version=1))[0]
    with pytest.raises(m.MessageError):
        m.decode(v1)
    assert math.isnan(m.Sample.unpack(samples[1].pack()).i_cmd)  # not in a version-1 SAMPLE
