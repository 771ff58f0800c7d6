"""Messages of bench protocol versions 1 and 2: payload layouts (docs/PROTOCOL.md sections 3, 9).

Every payload is a little-endian ``struct`` layout. :func:`decode` turns a
:class:`~hw_adapter.framing.Frame` into one of the dataclasses below, or raises
:class:`MessageError` (unknown type, wrong payload length, a field out of range).
Version 2 (the two-rate bench) adds SEGMENT (host -> board: the set-point profile for
the next samples), SAMPLE_BATCH (board -> host: several samples in one frame) and a
longer CAPS; every version-1 message keeps its layout in a version-2 frame.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from addedinertia_env.loop.board_loop import MAX_KNOTS, Segment

from hw_adapter.framing import Frame

# Message types (u8).
HELLO = 0x01  # host -> board
CAPS = 0x02  # board -> host, answer to HELLO
RESET = 0x03  # host -> board
ARM = 0x04  # host -> board
DISARM = 0x05  # host -> board
COMMAND = 0x06  # host -> board
SAMPLE = 0x07  # board -> host
FAULT = 0x08  # board -> host
HEARTBEAT = 0x09  # both ways
QUERY = 0x0A  # host -> board: answer with one SAMPLE of the present state, no step
SEGMENT = 0x0B  # host -> board, version 2: set-point profile with a deadline
SAMPLE_BATCH = 0x0C  # board -> host, version 2: consecutive samples in one frame

TYPE_NAMES = {HELLO: "HELLO", CAPS: "CAPS", RESET: "RESET", ARM: "ARM", DISARM: "DISARM", COMMAND: "COMMAND",
              SAMPLE: "SAMPLE", FAULT: "FAULT", HEARTBEAT: "HEARTBEAT", QUERY: "QUERY", SEGMENT: "SEGMENT",
              SAMPLE_BATCH: "SAMPLE_BATCH"}

# Drive modes in COMMAND (u8); the names are MotorCommand's.
MODE_CODES = {"passive": 0, "current": 1, "voltage": 2}
MODE_NAMES = {v: k for k, v in MODE_CODES.items()}

# SAMPLE.status bits.
ST_ARMED = 1 << 0  # board accepts COMMAND; drive may be enabled
ST_RESET_DONE = 1 << 1  # set in the SAMPLE that answers RESET once the hull is placed and braked
ST_RESET_PENDING = 1 << 2  # RESET accepted, hull not yet placed (real bench: operator twisting)
ST_BRAKE_REQUESTED = 1 << 3  # the brake request the board is applying
ST_DRIVE_ENABLED = 1 << 4  # drive bridge enabled (current or voltage mode)
ST_SEGMENT_HOLD = 1 << 5  # version 2: the segment ran out; the board holds it within the grace

# Fault bits (u16) in SAMPLE.faults and FAULT.faults; latched until RESET.
F_WATCHDOG = 1 << 0  # no valid COMMAND within the board watchdog time while armed
F_LINK = 1 << 1  # link lost (cable, socket)
F_OVERCURRENT = 1 << 2
F_OVERVOLTAGE = 1 << 3
F_ANGLE_LIMIT = 1 << 4  # hull end switch
F_BRAKE = 1 << 5  # sensed brake differs from the request longer than brake_response_ms
F_ENCODER = 1 << 6
F_HOST_STOP = 1 << 7  # the host stopped the run (DISARM with a reason)
F_BAD_FRAMES = 1 << 8  # more rejected frames than the board tolerates
F_DRIVE = 1 << 9  # motor driver reports a fault
F_SEGMENTS = 1 << 10  # version 2: the last segment ran out and the grace passed with no new one
FAULT_NAMES = {F_WATCHDOG: "watchdog", F_LINK: "link", F_OVERCURRENT: "overcurrent", F_OVERVOLTAGE: "overvoltage",
               F_ANGLE_LIMIT: "angle_limit", F_BRAKE: "brake", F_ENCODER: "encoder", F_HOST_STOP: "host_stop",
               F_BAD_FRAMES: "bad_frames", F_DRIVE: "drive", F_SEGMENTS: "segments"}

# HEARTBEAT.reason of a board that already serves another host (sent unasked, then the link closes).
BUSY_REASON = 0xFFFF

# CAPS.flags bits.
CAP_EMULATOR = 1 << 0  # the board is the simulated bench
CAP_LOCKSTEP = 1 << 1  # one SAMPLE per COMMAND (emulator --fast); else free-running at the sample rate
CAP_TWIST_ACTUATOR = 1 << 2  # RESET moves the hull by itself; else an operator does
CAP_TWO_RATE = 1 << 3  # version 2: the board runs the inner loop on SEGMENTs

# Board modes (CAPS v2 ``board_modes`` bits): what the board does between host actions.
BOARD_MODE_BITS = {"zoh": 1 << 0, "pd": 1 << 1}


class MessageError(ValueError):
    """A frame whose type or payload is not a valid version-1 message."""


def fault_names(bits: int) -> list[str]:
    """Names of the latched fault bits in ``bits`` (u16), in bit order; unknown bits as ``unknown_0x....``."""
    return [name for bit, name in FAULT_NAMES.items() if bits & bit] + (
        [f"unknown_0x{bits & ~sum(FAULT_NAMES):04x}"] if bits & ~sum(FAULT_NAMES) & 0xFFFF else [])


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass(frozen=True)
class Hello:
    """Host -> board: open a session; the board answers with :class:`Caps`. Layout ``<HH``: host version, reserved."""

    type = HELLO
    layout = struct.Struct("<HH")  # host software version, reserved
    host_version: int = 1

    def pack(self) -> bytes:
        """The payload bytes (little-endian): host version, 0."""
        return self.layout.pack(self.host_version, 0)

    @classmethod
    def unpack(cls, b: bytes) -> "Hello":
        """The message from its payload bytes (the reserved field is ignored)."""
        v, _ = cls.layout.unpack(b)
        return cls(v)


@dataclass(frozen=True)
class Caps:
    """What the board knows about itself (the ``rig`` block's board half)."""

    type = CAPS
    layout = struct.Struct("<HHIIIffHH16s")
    firmware_version: int
    flags: int
    sample_period_us: int  # us, the board's sample (and control) period
    phi_counts: int  # hull encoder counts per turn
    psi_counts: int  # motor encoder counts per turn
    i_max: float  # A, the drive's current limit
    u_max: float  # V, the supply voltage
    watchdog_ms: int  # ms, board watchdog while armed
    brake_response_ms: int  # ms, time the brake takes to follow a request
    board_id: str = ""
    # Version 2 only (absent from a version-1 CAPS): the two-rate inner loop.
    batch_samples: int = 0  # samples per SAMPLE_BATCH while streaming (0: version-1 board)
    max_knots: int = 0  # knots per SEGMENT
    board_modes: int = 0  # BOARD_MODE_BITS the board runs
    grace_ms: int = 0  # ms the board holds a segment that ran out before it goes safe
    rate_filter_hz: int = 0  # Hz, corner of the board's rate estimate (pd mode)
    v2_layout = struct.Struct("<BBBxHH")

    def pack(self) -> bytes:
        """The payload bytes (little-endian): the version-1 block, then the version-2 block only for a two-rate board (``batch_samples`` > 0)."""
        v1 = self.layout.pack(self.firmware_version, self.flags, self.sample_period_us, self.phi_counts,
                              self.psi_counts, self.i_max, self.u_max, self.watchdog_ms, self.brake_response_ms,
                              self.board_id.encode("ascii", "replace")[:16])
        if not self.batch_samples:
            return v1
        return v1 + self.v2_layout.pack(self.batch_samples, self.max_knots, self.board_modes, self.grace_ms,
                                        self.rate_filter_hz)

    @classmethod
    def unpack(cls, b: bytes) -> "Caps":
        """The message from its payload bytes, version 1 or 2 (by length).

        Raises :class:`MessageError` for a zero period or encoder count, a current or voltage limit
        that is not finite and > 0, or version-2 batch and knot counts out of range.
        """
        fw, flags, period, pc, sc, i_max, u_max, wd, br, bid = cls.layout.unpack(b[:cls.layout.size])
        if period == 0 or pc == 0 or sc == 0 or not (_finite(i_max, u_max) and i_max > 0 and u_max > 0):
            raise MessageError(f"CAPS with period {period} us, counts {pc}/{sc}, i_max {i_max}, u_max {u_max}: "
                               "expected positive values")
        extra = cls.v2_layout.unpack(b[cls.layout.size:]) if len(b) > cls.layout.size else (0, 0, 0, 0, 0)
        if len(b) > cls.layout.size and not (1 <= extra[0] <= SampleBatch.MAX and 1 <= extra[1]):
            raise MessageError(f"CAPS v2 with batch_samples {extra[0]}, max_knots {extra[1]}: expected "
                               f"1..{SampleBatch.MAX} and >= 1")
        return cls(fw, flags, period, pc, sc, i_max, u_max, wd, br, bid.rstrip(b"\0").decode("ascii", "replace"),
                   *extra)

    @property
    def two_rate(self) -> bool:
        """Whether the board runs the version-2 inner loop on segments (it batches samples)."""
        return bool(self.batch_samples)

    def supports(self, board_mode: str) -> bool:
        """Whether the board runs ``board_mode`` (``zoh`` or ``pd``) between host actions."""
        return bool(self.board_modes & BOARD_MODE_BITS.get(board_mode, 0))

    @property
    def sample_rate(self) -> float:
        """The board's sample (and control) rate, Hz."""
        return 1e6 / self.sample_period_us


@dataclass(frozen=True)
class Reset:
    """Place the hull at ``phi0`` (rad, encoder frame) and brake it; clears latched faults."""

    type = RESET
    layout = struct.Struct("<fffB3x")
    phi0: float
    psi0: float = 0.0  # rad, the motor counter is preset to this angle
    omega0: float = 0.0  # rad/s, flywheel spin (emulator; a real board may only accept 0)
    brake: bool = True

    def pack(self) -> bytes:
        """The payload bytes (little-endian): ``phi0``, ``psi0`` (rad), ``omega0`` (rad/s) as f32, the brake flag, 3 bytes padding."""
        return self.layout.pack(self.phi0, self.psi0, self.omega0, 1 if self.brake else 0)

    @classmethod
    def unpack(cls, b: bytes) -> "Reset":
        """The message from its payload bytes; :class:`MessageError` for a non-finite value or ``|phi0|`` above 2 pi rad."""
        phi0, psi0, omega0, brake = cls.layout.unpack(b)
        if not _finite(phi0, psi0, omega0) or abs(phi0) > 2 * math.pi:
            raise MessageError(f"RESET to phi0={phi0}, psi0={psi0}, omega0={omega0}: expected finite, |phi0| <= 2 pi")
        return cls(phi0, psi0, omega0, bool(brake & 1))


@dataclass(frozen=True)
class Empty:
    """ARM, DISARM, HEARTBEAT and QUERY carry a u16 reason code (0 = none)."""

    type: int
    reason: int = 0
    layout = struct.Struct("<H")

    def pack(self) -> bytes:
        """The payload bytes (little-endian): the u16 reason code."""
        return self.layout.pack(self.reason)

    @classmethod
    def unpack_as(cls, msg_type: int, b: bytes) -> "Empty":
        """The message from its payload bytes of type ``msg_type`` (ARM, DISARM, HEARTBEAT or QUERY)."""
        (reason,) = cls.layout.unpack(b)
        return cls(msg_type, reason)


@dataclass(frozen=True)
class Command:
    """Host -> board (version 1): the drive command for the next sample, answering SAMPLE ``sample_seq``.

    Layout ``<BBHf``: mode code (:data:`MODE_CODES`), flags (bit 0 brake), u16 sample seq,
    f32 value (A in current mode, V in voltage mode, 0 passive).
    """

    type = COMMAND
    layout = struct.Struct("<BBHf")
    mode: str  # passive | current | voltage
    value: float  # A (current mode) or V (voltage mode); 0 in passive mode
    brake: bool  # brake request
    sample_seq: int = 0  # seq of the SAMPLE this command answers

    def pack(self) -> bytes:
        """The payload bytes (little-endian): mode code, brake flag, sample seq (u16, wraps), value."""
        return self.layout.pack(MODE_CODES[self.mode], 1 if self.brake else 0, self.sample_seq & 0xFFFF, self.value)

    @classmethod
    def unpack(cls, b: bytes) -> "Command":
        """The message from its payload bytes; :class:`MessageError` for an unknown mode or a value that is not finite."""
        mode, flags, seq, value = cls.layout.unpack(b)
        if mode not in MODE_NAMES:
            raise MessageError(f"COMMAND mode {mode}: expected one of {MODE_NAMES}")
        if not math.isfinite(value):
            raise MessageError(f"COMMAND value {value}: expected a finite number")
        return cls(MODE_NAMES[mode], value, bool(flags & 1), seq)


@dataclass(frozen=True)
class Sample:
    """Board -> host (version 1): one sample of the instruments and the board's state.

    Layout ``<iiffBBHHH``: hull and motor encoder counts (i32), current (A) and voltage (V)
    as f32, brake sensed, status bits (:data:`ST_ARMED` ...), latched fault bits, the seq of
    the COMMAND applied, the u16 step counter. ``i_cmd`` travels only in a :class:`SampleBatch`.
    """

    type = SAMPLE
    layout = struct.Struct("<iiffBBHHH")
    phi_count: int  # hull encoder, signed counts from the encoder zero
    psi_count: int  # motor encoder, free-running i32 counter (wraps; the host unwraps)
    current: float  # A, measured motor current
    voltage: float  # V, measured terminal voltage
    brake: bool  # brake sensed engaged
    status: int  # ST_* bits
    faults: int  # F_* bits, latched
    cmd_seq: int  # seq of the last COMMAND applied (0 before any); in a batch: the segment in force
    step: int = 0  # u16 board sample counter since RESET (wraps)
    i_cmd: float = math.nan  # A, version 2 batches: the current applied over the period ending at this sample

    def pack(self) -> bytes:
        """The payload bytes (little-endian) of the version-1 layout (``i_cmd`` is not sent; seq and step wrap at 16 bits)."""
        return self.layout.pack(self.phi_count, self.psi_count, self.current, self.voltage, 1 if self.brake else 0,
                                self.status, self.faults, self.cmd_seq & 0xFFFF, self.step & 0xFFFF)

    @classmethod
    def unpack(cls, b: bytes) -> "Sample":
        """The message from its payload bytes (version-1 layout; ``i_cmd`` stays NaN)."""
        phi, psi, i, u, brake, status, faults, cmd_seq, step = cls.layout.unpack(b)
        return cls(phi, psi, i, u, bool(brake & 1), status, faults, cmd_seq, step)


@dataclass(frozen=True)
class Fault:
    """Board -> host: a fault latched. Layout ``<HHf``: the bit that latched, all latched bits,
    the value that tripped it (A, V, rad or ms; NaN if none).
    """

    type = FAULT
    layout = struct.Struct("<HHf")
    code: int  # the F_* bit that latched
    faults: int  # all latched bits
    detail: float = 0.0  # the value that tripped (A, V, rad, ms), NaN if none

    def pack(self) -> bytes:
        """The payload bytes (little-endian): code, latched bits, detail."""
        return self.layout.pack(self.code, self.faults, self.detail)

    @classmethod
    def unpack(cls, b: bytes) -> "Fault":
        """The message from its payload bytes."""
        return cls(*cls.layout.unpack(b))


@dataclass(frozen=True)
class SegmentMsg:
    """Version 2, host -> board: one :class:`~addedinertia_env.loop.board_loop.Segment` on the wire.

    Layout: u16 seg_id, u8 flags (bit 0 brake at t0, bit 1 brake switch valid, bit 2 pd:
    reference knots follow, bit 3 end passive, bit 4 passive), u8 n knots (1..8), u32
    t0_us, u32 duration_us, u32 deadline_us, u32 brake_switch_us, u32 knot_us, f32 kp
    (A/rad), f32 kd (A/(rad/s)), then n f32 current knots (A) and, in pd mode, n f32
    reference knots (rad, encoder frame): 32 + 4 n or 32 + 8 n bytes.
    """

    type = SEGMENT
    head = struct.Struct("<HBBIIIIIff")
    segment: Segment

    def pack(self) -> bytes:
        """The payload bytes (little-endian) of the class docstring's layout: the head, the current knots, then the reference knots in pd mode."""
        g = self.segment
        flags = ((1 if g.brake else 0) | (2 if g.brake_switch_us is not None else 0)
                 | (4 if g.phi_refs is not None else 0) | (8 if g.end_passive else 0) | (16 if g.passive else 0))
        knots = list(g.currents) + list(g.phi_refs or ())
        return self.head.pack(g.seg_id & 0xFFFF, flags, len(g.currents), g.t0_us & 0xFFFFFFFF, g.duration_us,
                              g.deadline_us & 0xFFFFFFFF, (g.brake_switch_us or 0) & 0xFFFFFFFF, g.knot_us, g.kp,
                              g.kd) + struct.pack(f"<{len(knots)}f", *knots)

    @classmethod
    def unpack(cls, b: bytes) -> "SegmentMsg":
        """The message from its payload bytes; :class:`MessageError` for a short payload, a knot count outside
        1..:data:`MAX_KNOTS`, a length that does not match it, or a segment the board loop refuses.
        """
        if len(b) < cls.head.size:
            raise MessageError(f"SEGMENT payload of {len(b)} bytes; expected at least {cls.head.size}")
        seg_id, flags, n, t0, duration, deadline, switch, knot_us, kp, kd = cls.head.unpack_from(b)
        pd = bool(flags & 4)
        want = cls.head.size + 4 * n * (2 if pd else 1)
        if not 1 <= n <= MAX_KNOTS or len(b) != want:
            raise MessageError(f"SEGMENT with {n} knots in {len(b)} bytes: expected 1..{MAX_KNOTS} knots "
                               f"and {want} bytes")
        knots = struct.unpack_from(f"<{n * (2 if pd else 1)}f", b, cls.head.size)
        try:
            seg = Segment(seg_id, t0, duration, deadline, knot_us, tuple(knots[:n]), tuple(knots[n:]) if pd else None,
                          kp, kd, bool(flags & 1), switch if flags & 2 else None, bool(flags & 8), bool(flags & 16))
        except ValueError as e:
            raise MessageError(f"SEGMENT {seg_id}: {e}") from None
        return cls(seg)


@dataclass(frozen=True)
class SampleBatch:
    """Version 2, board -> host: ``count`` consecutive samples, the first at the frame's
    ``time_us``, the next ones one sample period apart.

    Layout: u16 first_step, u8 count (1..9), u8 reserved, u16 late_segments (the board's
    count so far), u16 seg_id (the segment in force at the last sample), then per sample
    i32 phi_count, i32 psi_count, f32 current (A), f32 voltage (V), f32 i_cmd (A, the
    current the board applied over the period that ends at that sample; 0 when passive), u8 brake, u8 status,
    u16 faults: 8 + 24 count bytes.
    """

    type = SAMPLE_BATCH
    head = struct.Struct("<HBxHH")
    item = struct.Struct("<iifffBBH")
    MAX = 9
    first_step: int
    late_segments: int
    seg_id: int
    samples: tuple[Sample, ...]
    time_us: int = -1  # board time of the first sample (the frame's time_us; not in the payload)

    def pack(self) -> bytes:
        """The payload bytes (little-endian): the head, then each sample (a NaN ``i_cmd`` is sent as 0)."""
        out = [self.head.pack(self.first_step & 0xFFFF, len(self.samples), self.late_segments & 0xFFFF,
                              self.seg_id & 0xFFFF)]
        for x in self.samples:
            i_cmd = 0.0 if not math.isfinite(x.i_cmd) else x.i_cmd
            out.append(self.item.pack(x.phi_count, x.psi_count, x.current, x.voltage, i_cmd, 1 if x.brake else 0,
                                      x.status, x.faults))
        return b"".join(out)

    @classmethod
    def unpack(cls, b: bytes) -> "SampleBatch":
        """The message from its payload bytes: the samples with their step numbers and the segment in force;
        :class:`MessageError` for a count outside 1..:attr:`MAX` or a length that does not match it.
        """
        if len(b) < cls.head.size:
            raise MessageError(f"SAMPLE_BATCH payload of {len(b)} bytes; expected at least {cls.head.size}")
        first, n, late, seg_id = cls.head.unpack_from(b)
        if not 1 <= n <= cls.MAX or len(b) != cls.head.size + n * cls.item.size:
            raise MessageError(f"SAMPLE_BATCH of {n} samples in {len(b)} bytes: expected 1..{cls.MAX} samples "
                               f"and {cls.head.size + n * cls.item.size} bytes")
        samples = []
        for k in range(n):
            phi, psi, i, u, i_cmd, brake, status, faults = cls.item.unpack_from(b, cls.head.size + k * cls.item.size)
            samples.append(Sample(phi, psi, i, u, bool(brake & 1), status, faults, seg_id, (first + k) & 0xFFFF,
                                  i_cmd))
        return cls(first, late, seg_id, tuple(samples))

    def expand(self, time_us: int, period_us: int) -> list[tuple[int, Sample]]:
        """``(time_us, sample)`` of each sample, the first at the frame's ``time_us`` (u32)."""
        return [((time_us + k * period_us) & 0xFFFFFFFF, x) for k, x in enumerate(self.samples)]


_DECODERS = {HELLO: Hello.unpack, CAPS: Caps.unpack, RESET: Reset.unpack, COMMAND: Command.unpack,
             SAMPLE: Sample.unpack, FAULT: Fault.unpack}
_V2_DECODERS = {SEGMENT: SegmentMsg.unpack, SAMPLE_BATCH: SampleBatch.unpack}
_EMPTY = (ARM, DISARM, HEARTBEAT, QUERY)
PAYLOAD_SIZES = {HELLO: Hello.layout.size, CAPS: Caps.layout.size, RESET: Reset.layout.size,
                 COMMAND: Command.layout.size, SAMPLE: Sample.layout.size, FAULT: Fault.layout.size,
                 **{t: Empty.layout.size for t in _EMPTY}}
CAPS_V2_SIZE = Caps.layout.size + Caps.v2_layout.size

Message = Hello | Caps | Reset | Empty | Command | Sample | Fault | SegmentMsg | SampleBatch


def decode(frame: Frame) -> Message:
    """The message in ``frame``; :class:`MessageError` if it is not a valid one."""
    v2 = getattr(frame, "version", 1) >= 2
    if v2 and frame.type in _V2_DECODERS:
        return _V2_DECODERS[frame.type](frame.payload)
    size = PAYLOAD_SIZES.get(frame.type)
    if size is None:
        raise MessageError(f"unknown message type 0x{frame.type:02x} (version {getattr(frame, 'version', 1)})")
    if v2 and frame.type == CAPS:
        size = CAPS_V2_SIZE
    if len(frame.payload) != size:
        raise MessageError(f"{TYPE_NAMES[frame.type]} payload of {len(frame.payload)} bytes; expected {size}")
    try:
        if frame.type in _EMPTY:
            return Empty.unpack_as(frame.type, frame.payload)
        return _DECODERS[frame.type](frame.payload)
    except struct.error as e:  # pragma: no cover - sizes are checked above
        raise MessageError(f"{TYPE_NAMES[frame.type]}: {e}") from None
