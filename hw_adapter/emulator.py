"""The bench emulator's server: a :class:`~hw_adapter.board.Board` on a TCP port of 127.0.0.1.

Hosts connect with ``socket://127.0.0.1:PORT`` (pyserial). One host at a time; the board
outlives connections, so a host that lost its link can reconnect and see the safe state.

Modes:

* ``lockstep`` (``--fast``): the board steps once per COMMAND and answers with one SAMPLE;
  the simulated bench does not move while it waits, so it runs as fast as the host.
* free-running (``--realtime``): the board ticks at its sample rate on the wall clock,
  applies the latest COMMAND, streams a SAMPLE every tick, and runs its own watchdog.

Link faults (latency, jitter, drop, corrupt, disconnect) act on the frames the board
sends; board faults (glitch, stuck brake) act inside :class:`Board`. Fault onsets and
the moment the board is safe again are logged in ``board.log`` (monotonic wall clock).
"""

from __future__ import annotations

import heapq
import json
from collections import deque
import random
import select
import socket
import threading
import time
from pathlib import Path

from addedinertia_env.foundation.atomic import atomic_write_text

from hw_adapter import messages as m
from hw_adapter.board import Board
from hw_adapter.framing import FrameParser, encode_frame

HEARTBEAT_S = 0.1  # s, idle heartbeat of a free-running board before the host's HELLO
IDLE_TIMEOUT_S = 30.0  # s without a valid frame from the host: the connection is dropped (board safe)
BAD_FRAME_WINDOW = 100  # frames; more than BAD_FRAME_LIMIT of them bad latches BAD_FRAMES (PROTOCOL.md 5.5)
BAD_FRAME_LIMIT = 10


class EmulatorServer:
    """Serve ``board`` on ``host:port`` (port 0: any free port; see :attr:`port`)."""

    def __init__(self, board: Board, port: int = 0, host: str = "127.0.0.1", events_path: str | Path | None = None,
                 idle_timeout_s: float = IDLE_TIMEOUT_S):
        if host not in ("127.0.0.1", "localhost", "::1"):
            raise ValueError(f"bench emulator host {host!r}: it listens on loopback only (127.0.0.1)")
        self.board = board
        self.listener = socket.create_server((host, port))
        self.host, self.port = self.listener.getsockname()[:2]
        self.realtime = not board.lockstep
        self.rng = random.Random(board.faults_plan.seed)
        self.events_path = Path(events_path) if events_path else None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._disconnect_done = False
        self._onset_logged: set[str] = set()
        self.connections = 0
        self.idle_timeout_s = float(idle_timeout_s)
        self.refused_busy = 0  # second hosts answered BUSY while one was connected
        self.dropped_idle = 0  # connections dropped for silence
        self._frame_window: deque[bool] = deque(maxlen=BAD_FRAME_WINDOW)  # True: a bad frame
        self.board_overruns = 0
        self._seq = 0

    @property
    def url(self) -> str:
        """The pyserial URL a host connects to: ``socket://127.0.0.1:PORT``."""
        return f"socket://{self.host}:{self.port}"

    # --- life cycle ---------------------------------------------------------------------
    def start(self) -> "EmulatorServer":
        """Serve in a daemon thread (tests); :meth:`serve_forever` for a process of its own."""
        self._thread = threading.Thread(target=self.serve_forever, name="bench-emulator", daemon=True)
        self._thread.start()
        return self

    def request_stop(self) -> None:
        """Ask :meth:`serve_forever` to return (safe from a signal handler)."""
        self._stop.set()

    def stop(self) -> None:
        """Stop serving (waits up to 5 s for the thread), close the port and write the event log."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.listener.close()
        self.write_events()

    def serve_forever(self, once: bool = False) -> None:
        """Accept hosts one after another until :meth:`stop` (or after one with ``once``)."""
        self.listener.settimeout(0.1)
        while not self._stop.is_set():
            try:
                conn, _ = self.listener.accept()
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                break
            self.connections += 1
            try:
                self._serve(conn)
            finally:
                self.board.link_lost()  # safe before the host can see the link drop
                conn.close()
                self.write_events()
            if once:
                break

    def write_events(self) -> None:
        """Write the board's fault and safe-state events to ``events_path`` (JSON lines, atomically), if one was given."""
        if self.events_path is not None:
            atomic_write_text(self.events_path, "".join(json.dumps(e) + "\n" for e in self.board.log.events))

    # --- one connection -----------------------------------------------------------------
    def _serve(self, conn: socket.socket) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn.setblocking(False)
        parser = FrameParser()
        board = self.board
        self._frame_window.clear()  # BAD_FRAMES counts this host's frames
        outq: list[tuple[float, int, bytes]] = []  # (due, order, bytes)
        period = board.period_us * 1e-6
        next_tick = time.monotonic()
        streaming = False
        last_due = 0.0
        order = 0

        def send(msg) -> None:
            nonlocal last_due, order
            now = time.monotonic()
            bt = board.board_t
            stamp = getattr(msg, "time_us", -1)  # a SAMPLE_BATCH carries its first sample's time
            data = encode_frame(msg.type, self._seq, stamp if stamp >= 0 else board.time_us, msg.pack(),
                                version=board.version)
            self._seq = (self._seq + 1) & 0xFFFF
            plan = board.faults_plan
            if plan.active("drop", bt) and self.rng.random() < plan.active("drop", bt):
                self._onset("drop", now, bt)
                return
            if plan.active("corrupt", bt) and self.rng.random() < plan.active("corrupt", bt):
                self._onset("corrupt", now, bt)
                k = self.rng.randrange(len(data) * 8)
                data = bytes(data[:k // 8]) + bytes([data[k // 8] ^ (1 << (k % 8))]) + bytes(data[k // 8 + 1:])
            delay = plan.active("latency", bt) * 1e-3
            jitter = plan.active("jitter", bt) * 1e-3
            if jitter:
                delay += self.rng.uniform(0.0, jitter)
            if delay:
                self._onset("latency" if plan.active("latency", bt) else "jitter", now, bt)
            due = max(now + delay, last_due)  # frames keep their order
            last_due = due
            order += 1
            heapq.heappush(outq, (due, order, data))

        last_heard = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if now - last_heard > self.idle_timeout_s:
                self.dropped_idle += 1
                self.board.log.add("idle_drop", now, board.board_t)
                return  # the finally of serve_forever closes the socket and puts the board safe
            waits = [0.05]
            if self.realtime:
                waits.append(next_tick - now)
            if outq:
                waits.append(outq[0][0] - now)
            ready, _, _ = select.select([conn, self.listener], [], [], max(0.0, min(waits)))
            if self.listener in ready:
                self._answer_busy()
            if conn in ready:
                try:
                    data = conn.recv(4096)
                except (BlockingIOError, InterruptedError):
                    data = None
                except OSError:
                    return
                if data == b"":
                    return  # the host closed the link
                crc_before = parser.stats.bad_crc
                frames = parser.feed(data or b"")
                self._count_frames(parser.stats.bad_crc - crc_before, 0)
                for frame in frames:
                    try:
                        msg = m.decode(frame)
                    except m.MessageError:
                        self._count_frames(1, 0)
                        continue
                    self._count_frames(0, 1)
                    last_heard = time.monotonic()
                    if msg.type == m.HELLO:
                        streaming = True
                    for reply in board.handle(msg, frame.seq, frame.version):
                        send(reply)
            now = time.monotonic()
            if self.realtime and now >= next_tick:
                board.check_watchdog(now)
                for msg in board.pending():
                    send(msg)
                sample = board.tick()
                for msg in board.pending():
                    send(msg)
                if streaming:
                    for out in board.stream(sample):  # version 2: batched
                        send(out)
                next_tick += period
                if now - next_tick > 10 * period:  # the emulator itself fell behind
                    self.board_overruns += 1
                    next_tick = now + period
            for msg in board.pending():
                send(msg)
            now = time.monotonic()
            due = bytearray()
            while outq and outq[0][0] <= now:
                due += heapq.heappop(outq)[2]
            if due and not self._send_now(conn, bytes(due)):
                return
            if self._disconnect_due():
                self._onset("disconnect", time.monotonic(), board.board_t)
                return  # the finally of serve_forever closes the socket and puts the board safe

    def _answer_busy(self) -> None:
        """A second host while one is served: its frames are answered with a HEARTBEAT of reason BUSY, then it is closed."""
        try:
            other, _ = self.listener.accept()
        except (BlockingIOError, TimeoutError, socket.timeout, OSError):
            return
        self.refused_busy += 1
        frame = encode_frame(m.HEARTBEAT, 0, self.board.time_us, m.Empty(m.HEARTBEAT, m.BUSY_REASON).pack())
        threading.Thread(target=_say_busy, args=(other, frame), name="bench-emulator-busy", daemon=True).start()

    def _count_frames(self, bad: int, good: int) -> None:
        """Slide the window of the host's last frames; too many bad ones latch BAD_FRAMES (board safe)."""
        self._frame_window.extend([True] * min(bad, BAD_FRAME_WINDOW) + [False] * good)
        n_bad = sum(self._frame_window)
        if n_bad > BAD_FRAME_LIMIT and not self.board.fault_bits & m.F_BAD_FRAMES:
            self.board.go_safe(m.F_BAD_FRAMES, float(n_bad))

    @staticmethod
    def _send_now(conn: socket.socket, data: bytes) -> bool:
        """Write ``data`` whole on the non-blocking socket; False if the host is gone."""
        view = memoryview(data)
        while len(view):
            try:
                view = view[conn.send(view):]
            except BlockingIOError:  # the host reads slowly: wait for room
                select.select([], [conn], [], 0.5)
            except OSError:
                return False
        return True

    def _disconnect_due(self) -> bool:
        if self._disconnect_done or not self.board.faults_plan.active("disconnect", self.board.board_t):
            return False
        self._disconnect_done = True
        return True

    def _onset(self, name: str, wall: float, board_t: float) -> None:
        if name not in self._onset_logged:
            self._onset_logged.add(name)
            self.board.log.add("fault_onset", wall, board_t, fault=name)


def _say_busy(conn: socket.socket, frame: bytes, linger_s: float = 3.0) -> None:
    """Answer whatever another host sends (its HELLO) with the BUSY frame, until it hangs up or
    ``linger_s`` passes. Answering, not sending unasked: a serial layer may discard bytes that
    arrive while it is still opening the port."""
    try:
        conn.settimeout(0.25)
        deadline = time.monotonic() + linger_s
        while time.monotonic() < deadline:
            try:
                data = conn.recv(4096)
            except socket.timeout:
                continue
            if not data:
                break
            conn.sendall(frame)
    except OSError:
        pass
    finally:
        conn.close()
