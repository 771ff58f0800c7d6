"""Messages of bench protocol version 1: payload layouts (docs/PROTOCOL.md section 3).

Every payload is a fixed little-endian ``struct`` layout. :func:`decode` turns a
:class:`~hw_adapter.framing.Frame` into one of the dataclasses below, or raises
:class:`MessageError` (unknown type, wrong payload length, a field out of range).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from .framing import Frame

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

TYPE_NAMES = {HELLO: "HELLO", CAPS: "CAPS", RESET: "RESET", ARM: "ARM", DISARM: "DISARM", COMMAND: "COMMAND",
              SAMPLE: "SAMPLE", FAULT: "FAULT", HEARTBEAT: "HEARTBEAT", QUERY: "QUERY"}

# Drive modes in COMMAND (u8); the names are MotorCommand's.
MODE_CODES = {"passive": 0, "current": 1, "voltage": 2}
MODE_NAMES = {v: k for k, v in MODE_CODES.items()}

# SAMPLE.status bits.
ST_ARMED = 1 << 0  # board accepts COMMAND; drive may be enabled
ST_RESET_DONE = 1 << 1  # set in the SAMPLE that answers RESET once the hull is placed and braked
ST_RESET_PENDING = 1 << 2  # RESET accepted, hull not yet placed (real bench: operator twisting)
ST_BRAKE_REQUESTED = 1 << 3  # the brake request the board is applying
ST_DRIVE_ENABLED = 1 << 4  # drive bridge enabled (current or voltage mode)

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
FAULT_NAMES = {F_WATCHDOG: "watchdog", F_LINK: "link", F_OVERCURRENT: "overcurrent", F_OVERVOLTAGE: "overvoltage",
               F_ANGLE_LIMIT: "angle_limit", F_BRAKE: "brake", F_ENCODER: "encoder", F_HOST_STOP: "host_stop",
               F_BAD_FRAMES: "bad_frames", F_DRIVE: "drive"}

# CAPS.flags bits.
CAP_EMULATOR = 1 << 0  # the board is the simulated bench
CAP_LOCKSTEP = 1 << 1  # one SAMPLE per COMMAND (emulator --fast); else free-running at the sample rate
CAP_TWIST_ACTUATOR = 1 << 2  # RESET moves the hull by itself; else an operator does


class MessageError(ValueError):
    """A frame whose type or payload is not a valid version-1 message."""


def fault_names(bits: int) -> list[str]:
    return [name for bit, name in FAULT_NAMES.items() if bits & bit] + (
        [f"unknown_0x{bits & ~sum(FAULT_NAMES):04x}"] if bits & ~sum(FAULT_NAMES) & 0xFFFF else [])


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass(frozen=True)
class Hello:
    type = HELLO
    layout = struct.Struct("<HH")  # host software version, reserved
    host_version: int = 1

    def pack(self) -> bytes:
        return self.layout.pack(self.host_version, 0)

    @classmethod
    def unpack(cls, b: bytes) -> "Hello":
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

    def pack(self) -> bytes:
        return self.layout.pack(self.firmware_version, self.flags, self.sample_period_us, self.phi_counts,
                                self.psi_counts, self.i_max, self.u_max, self.watchdog_ms, self.brake_response_ms,
                                self.board_id.encode("ascii", "replace")[:16])

    @classmethod
    def unpack(cls, b: bytes) -> "Caps":
        fw, flags, period, pc, sc, i_max, u_max, wd, br, bid = cls.layout.unpack(b)
        if period == 0 or pc == 0 or sc == 0 or not (_finite(i_max, u_max) and i_max > 0 and u_max > 0):
            raise MessageError(f"CAPS with period {period} us, counts {pc}/{sc}, i_max {i_max}, u_max {u_max}: "
                               "expected positive values")
        return cls(fw, flags, period, pc, sc, i_max, u_max, wd, br, bid.rstrip(b"\0").decode("ascii", "replace"))

    @property
    def sample_rate(self) -> float:
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
        return self.layout.pack(self.phi0, self.psi0, self.omega0, 1 if self.brake else 0)

    @classmethod
    def unpack(cls, b: bytes) -> "Reset":
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
        return self.layout.pack(self.reason)

    @classmethod
    def unpack_as(cls, msg_type: int, b: bytes) -> "Empty":
        (reason,) = cls.layout.unpack(b)
        return cls(msg_type, reason)


@dataclass(frozen=True)
class Command:
    type = COMMAND
    layout = struct.Struct("<BBHf")
    mode: str  # passive | current | voltage
    value: float  # A (current mode) or V (voltage mode); 0 in passive mode
    brake: bool  # brake request
    sample_seq: int = 0  # seq of the SAMPLE this command answers

    def pack(self) -> bytes:
        return self.layout.pack(MODE_CODES[self.mode], 1 if self.brake else 0, self.sample_seq & 0xFFFF, self.value)

    @classmethod
    def unpack(cls, b: bytes) -> "Command":
        mode, flags, seq, value = cls.layout.unpack(b)
        if mode not in MODE_NAMES:
            raise MessageError(f"COMMAND mode {mode}: expected one of {MODE_NAMES}")
        if not math.isfinite(value):
            raise MessageError(f"COMMAND value {value}: expected a finite number")
        return cls(MODE_NAMES[mode], value, bool(flags & 1), seq)


@dataclass(frozen=True)
class Sample:
    type = SAMPLE
    layout = struct.Struct("<iiffBBHHH")
    phi_count: int  # hull encoder, signed counts from the encoder zero
    psi_count: int  # motor encoder, free-running i32 counter (wraps; the host unwraps)
    current: float  # A, measured motor current
    voltage: float  # V, measured terminal voltage
    brake: bool  # brake sensed engaged
    status: int  # ST_* bits
    faults: int  # F_* bits, latched
    cmd_seq: int  # seq of the last COMMAND applied (0 before any)
    step: int = 0  # u16 board sample counter since RESET (wraps)

    def pack(self) -> bytes:
        return self.layout.pack(self.phi_count, self.psi_count, self.current, self.voltage, 1 if self.brake else 0,
                                self.status, self.faults, self.cmd_seq & 0xFFFF, self.step & 0xFFFF)

    @classmethod
    def unpack(cls, b: bytes) -> "Sample":
        phi, psi, i, u, brake, status, faults, cmd_seq, step = cls.layout.unpack(b)
        return cls(phi, psi, i, u, bool(brake & 1), status, faults, cmd_seq, step)


@dataclass(frozen=True)
class Fault:
    type = FAULT
    layout = struct.Struct("<HHf")
    code: int  # the F_* bit that latched
    faults: int  # all latched bits
    detail: float = 0.0  # the value that tripped (A, V, rad, ms), NaN if none

    def pack(self) -> bytes:
        return self.layout.pack(self.code, self.faults, self.detail)

    @classmethod
    def unpack(cls, b: bytes) -> "Fault":
        return cls(*cls.layout.unpack(b))


_DECODERS = {HELLO: Hello.unpack, CAPS: Caps.unpack, RESET: Reset.unpack, COMMAND: Command.unpack,
             SAMPLE: Sample.unpack, FAULT: Fault.unpack}
_EMPTY = (ARM, DISARM, HEARTBEAT, QUERY)
PAYLOAD_SIZES = {HELLO: Hello.layout.size, CAPS: Caps.layout.size, RESET: Reset.layout.size,
                 COMMAND: Command.layout.size, SAMPLE: Sample.layout.size, FAULT: Fault.layout.size,
                 **{t: Empty.layout.size for t in _EMPTY}}

Message = Hello | Caps | Reset | Empty | Command | Sample | Fault


def decode(frame: Frame) -> Message:
    """The message in ``frame``; :class:`MessageError` if it is not a valid one."""
    size = PAYLOAD_SIZES.get(frame.type)
    if size is None:
        raise MessageError(f"unknown message type 0x{frame.type:02x}")
    if len(frame.payload) != size:
        raise MessageError(f"{TYPE_NAMES[frame.type]} payload of {len(frame.payload)} bytes; expected {size}")
    try:
        if frame.type in _EMPTY:
            return Empty.unpack_as(frame.type, frame.payload)
        return _DECODERS[frame.type](frame.payload)
    except struct.error as e:  # pragma: no cover - sizes are checked above
        raise MessageError(f"{TYPE_NAMES[frame.type]}: {e}") from None
