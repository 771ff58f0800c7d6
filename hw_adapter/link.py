"""The host end of the bench link over pyserial: real ports, ``socket://`` and ``loop://``.

``serial.serial_for_url`` gives one object for ``/dev/ttyUSB0``, ``socket://127.0.0.1:5555``
(the emulator) and ``loop://`` (tests), so nothing above this module knows which it is.
Writes are serialised by a lock: the watchdog thread may send the safe command while
the control loop is blocked reading.
"""

from __future__ import annotations

import socket
import threading
import time
from collections import deque
from dataclasses import dataclass

import serial

from hw_adapter.framing import ClockUnwrapper, Frame, FrameParser, encode_frame, seq_gap
from hw_adapter.messages import Message, MessageError, decode

DEFAULT_BAUDRATE = 2_000_000  # real serial ports; ignored by socket:// and loop://
MAX_LATE_READS = 64  # non-blocking reads allowed after a recv's deadline (draining what already arrived)


class LinkError(RuntimeError):
    """The port could not be opened, or the link broke (unplugged, socket closed)."""


@dataclass
class LinkStats:
    """Counts of the link: frames sent and received, board frames missing (sequence gaps) and frames with a valid CRC but an invalid payload."""

    sent: int = 0
    received: int = 0
    seq_gaps: int = 0  # board frames missing, from the sequence numbers
    bad_messages: int = 0  # frames with a valid CRC but an invalid payload


class Link:
    """Frames to and from the board; ``recv`` returns ``(frame, message)`` or ``None`` on timeout."""

    def __init__(self, url: str, open_timeout_s: float = 2.0, baudrate: int = DEFAULT_BAUDRATE):
        self.url = url
        try:
            self.port = serial.serial_for_url(url, baudrate=baudrate, timeout=open_timeout_s, write_timeout=1.0)
        except (serial.SerialException, ValueError, OSError) as e:
            raise LinkError(f"cannot open bench link {url!r}: {e}") from None
        sock = getattr(self.port, "_socket", None)  # socket:// (the emulator): no Nagle delay on small frames,
        if sock is not None:                        # else a silent board's delayed ACKs hold the host's safe stop ~40 ms
            try:
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except OSError:
                pass
        self.parser = FrameParser()
        self.stats = LinkStats()
        self.board_clock = ClockUnwrapper()
        self._pending: deque[Frame] = deque()
        self._lock = threading.Lock()
        self._seq = 0
        self._last_rx_seq: int | None = None
        self._t0 = time.perf_counter()
        self._timeout: float | None = open_timeout_s
        self.closed = False
        self.version = 1  # protocol version of the frames sent (2: the two-rate bench)

    # --- sending -----------------------------------------------------------------------
    def send(self, msg: Message) -> int:
        """Send one message; returns its sequence number."""
        with self._lock:
            if self.closed:
                raise LinkError(f"bench link {self.url!r} is closed")
            seq = self._seq
            self._seq = (self._seq + 1) & 0xFFFF
            data = encode_frame(msg.type, seq, int((time.perf_counter() - self._t0) * 1e6), msg.pack(),
                                version=self.version)
            try:
                self.port.write(data)
            except (serial.SerialException, OSError) as e:
                self.closed = True
                raise LinkError(f"bench link {self.url!r}: write failed ({e})") from None
            self.stats.sent += 1
            return seq

    # --- receiving ---------------------------------------------------------------------
    def recv(self, timeout_s: float) -> tuple[Frame, Message] | None:
        """The next valid message, or ``None`` if none arrives within ``timeout_s``."""
        deadline = time.perf_counter() + timeout_s
        late_reads = 0
        while True:
            while self._pending:
                frame = self._pending.popleft()
                gap = seq_gap(self._last_rx_seq, frame.seq)
                self._last_rx_seq = frame.seq
                self.stats.seq_gaps += gap
                try:
                    msg = decode(frame)
                except MessageError:
                    self.stats.bad_messages += 1
                    continue
                self.stats.received += 1
                return frame, msg
            left = deadline - time.perf_counter()
            if left <= 0:
                late_reads += 1
                if late_reads > MAX_LATE_READS:
                    return None  # a stream of garbage must not hold the caller past its deadline
            data = self._read(self.parser.wanted(), max(0.0, left))
            if not data and left <= 0:
                return None  # past the deadline and nothing more waiting
            self._pending.extend(self.parser.feed(data))

    def _read(self, n: int, timeout_s: float) -> bytes:
        if self.closed:
            raise LinkError(f"bench link {self.url!r} is closed")
        try:
            if self._timeout != timeout_s:
                self.port.timeout = timeout_s
                self._timeout = timeout_s
            return self.port.read(n)
        except (serial.SerialException, OSError) as e:
            self.closed = True
            raise LinkError(f"bench link {self.url!r}: read failed ({e})") from None

    def drain(self) -> None:
        """Forget anything already received (stale samples after a pause)."""
        self._pending.clear()
        try:
            self.port.reset_input_buffer()
        except (serial.SerialException, OSError):
            pass

    @property
    def errors(self) -> int:
        """Frames lost or rejected so far: the safety envelope's link budget counts these."""
        return self.parser.stats.errors + self.stats.seq_gaps + self.stats.bad_messages

    def close(self) -> None:
        """Close the port (once; later calls do nothing)."""
        with self._lock:
            if not self.closed:
                self.closed = True
                try:
                    self.port.close()
                except (serial.SerialException, OSError):  # pragma: no cover
                    pass
