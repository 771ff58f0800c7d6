"""Binary framing of the bench link (docs/PROTOCOL.md section 2).

A frame is a 12-byte little-endian header, a payload and a CRC-32::

    offset size field
    0      2    sync        0xA5 0x5A
    2      1    version     1 or 2 (SUPPORTED_VERSIONS; 2 adds the two-rate messages)
    3      1    type        message type (see :mod:`hw_adapter.messages`)
    4      2    seq         sender's frame counter, u16, +1 per frame sent, wraps
    6      2    length      payload length in bytes, 0..64 (version 1), 0..240 (version 2)
    8      4    time_us     sender's clock in microseconds, u32, wraps every 71.6 min
    12     n    payload
    12+n   4    crc32       CRC-32 (zlib / IEEE 802.3) of bytes 0 .. 12+n-1

:class:`FrameParser` is a streaming parser: it takes bytes in any chunks, returns whole
frames, skips garbage by hunting for the next sync word, and rejects frames whose
version, length or CRC is wrong. Its buffer never holds more than one maximal frame
(``MAX_FRAME`` bytes), whatever it is fed.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

SYNC = b"\xa5\x5a"
PROTOCOL_VERSION = 1  # the version a frame gets unless told otherwise
SUPPORTED_VERSIONS = (1, 2)
HEADER = struct.Struct("<2sBBHHI")  # sync, version, type, seq, length, time_us
CRC = struct.Struct("<I")
MAX_PAYLOAD = 64  # bytes in a version-1 frame: the largest message (CAPS) is 44
MAX_PAYLOAD_V2 = 240  # bytes in a version-2 frame: a SAMPLE_BATCH of 9 samples is 224
PAYLOAD_LIMITS = {1: MAX_PAYLOAD, 2: MAX_PAYLOAD_V2}
MAX_FRAME = HEADER.size + MAX_PAYLOAD_V2 + CRC.size  # 256 bytes: the parser's buffer bound


class FrameError(ValueError):
    """A frame that cannot be built (payload too long, field out of range)."""


@dataclass(frozen=True)
class Frame:
    """One decoded frame: header fields and the raw payload."""

    type: int
    seq: int
    time_us: int
    payload: bytes
    version: int = PROTOCOL_VERSION


def encode_frame(msg_type: int, seq: int, time_us: int, payload: bytes = b"", version: int = PROTOCOL_VERSION) -> bytes:
    """Bytes of one frame; ``seq`` and ``time_us`` are taken modulo their field width."""
    if version not in SUPPORTED_VERSIONS:
        raise FrameError(f"protocol version {version}: expected one of {SUPPORTED_VERSIONS}")
    if len(payload) > PAYLOAD_LIMITS[version]:
        raise FrameError(f"payload of {len(payload)} bytes; at most {PAYLOAD_LIMITS[version]} fit in a "
                         f"version-{version} frame")
    if not 0 <= msg_type <= 0xFF:
        raise FrameError(f"message type {msg_type}: expected 0..255")
    head = HEADER.pack(SYNC, version, msg_type, seq & 0xFFFF, len(payload), time_us & 0xFFFFFFFF)
    body = head + payload
    return body + CRC.pack(zlib.crc32(body) & 0xFFFFFFFF)


@dataclass
class ParserStats:
    """What the parser threw away; the link's error budget reads these."""

    frames: int = 0
    bad_crc: int = 0
    bad_version: int = 0
    bad_length: int = 0
    skipped_bytes: int = 0  # garbage before a sync word, or bytes of rejected frames
    by_type: dict[int, int] = field(default_factory=dict)

    @property
    def errors(self) -> int:
        """Frames rejected so far: bad CRC, unknown version or impossible length."""
        return self.bad_crc + self.bad_version + self.bad_length


class FrameParser:
    """Streaming frame parser with a bounded buffer; see the module docstring.

    ``feed(data)`` returns the frames completed by ``data``. It never raises on any
    input: bad bytes are counted in :attr:`stats` and skipped. ``wanted()`` is how many
    more bytes could complete the frame being assembled (at least 1), so a reader can
    ask the port for exactly that many.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = ParserStats()

    @property
    def buffered(self) -> int:
        """Bytes held of the frame being assembled."""
        return len(self._buf)

    def wanted(self) -> int:
        """How many more bytes could complete the frame being assembled (at least 1): what a reader should ask the port for."""
        buf = self._buf
        if len(buf) < HEADER.size:
            return HEADER.size - len(buf)
        length = buf[6] | (buf[7] << 8)
        if length > PAYLOAD_LIMITS.get(buf[2], -1):
            return 1
        return max(1, HEADER.size + length + CRC.size - len(buf))

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """The frames completed by ``data`` (any bytes; never raises: bad ones are counted in :attr:`stats` and skipped)."""
        frames: list[Frame] = []
        view = memoryview(data)
        # Take at most what fits, parse, repeat: the buffer stays under MAX_FRAME bytes.
        while len(view):
            room = MAX_FRAME - len(self._buf)
            self._buf += view[:room]
            view = view[room:]
            frames += self._drain()
        return frames

    def _drain(self) -> list[Frame]:
        out: list[Frame] = []
        buf, st = self._buf, self.stats
        while True:
            start = buf.find(SYNC)
            if start < 0:
                # Keep a trailing first sync byte: the second may come in the next chunk.
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                st.skipped_bytes += len(buf) - keep
                del buf[:len(buf) - keep]
                return out
            if start:
                st.skipped_bytes += start
                del buf[:start]
            if len(buf) < HEADER.size:
                return out
            _, version, msg_type, seq, length, time_us = HEADER.unpack_from(buf)
            if version not in SUPPORTED_VERSIONS:
                st.bad_version += 1
                self._skip_one()
                continue
            if length > PAYLOAD_LIMITS[version]:
                st.bad_length += 1
                self._skip_one()
                continue
            end = HEADER.size + length
            if len(buf) < end + CRC.size:
                return out
            (crc,) = CRC.unpack_from(buf, end)
            if crc != zlib.crc32(buf[:end]) & 0xFFFFFFFF:
                st.bad_crc += 1
                self._skip_one()
                continue
            out.append(Frame(type=msg_type, seq=seq, time_us=time_us, payload=bytes(buf[HEADER.size:end]),
                             version=version))
            st.frames += 1
            st.by_type[msg_type] = st.by_type.get(msg_type, 0) + 1
            del buf[:end + CRC.size]

    def _skip_one(self) -> None:
        """Drop the first byte of a rejected frame and hunt for the next sync word."""
        self.stats.skipped_bytes += 1
        del self._buf[:1]


def seq_gap(previous: int | None, current: int) -> int:
    """Frames missing between two u16 sequence numbers (0 when consecutive)."""
    if previous is None:
        return 0
    return (current - previous - 1) & 0xFFFF


class ClockUnwrapper:
    """Extends the u32 microsecond timestamps of one sender to a monotonic 64-bit count."""

    def __init__(self) -> None:
        self._last: int | None = None
        self._total = 0

    def __call__(self, time_us: int) -> int:
        if self._last is None:
            self._total = time_us
        else:
            self._total += (time_us - self._last) & 0xFFFFFFFF
        self._last = time_us
        return self._total
