"""The bench after faults: an operator path to read and clear latched faults (never silently),
QUERY reports the present state, a second host is told BUSY, an idle host is dropped,
BAD_FRAMES latches (hw_adapter/emulator.py, hw_adapter/board.py, cli/bench_faults.py)."""

from __future__ import annotations

import json
import socket
import time

import pytest

from addedinertia_env.cli import main
from hw_adapter import messages as m
from hw_adapter.board import Board
from hw_adapter.emulator import EmulatorServer
from hw_adapter.framing import FrameParser, encode_frame
from addedinertia_env.sim.presets import load_rig


@pytest.fixture
def server():
    srv = EmulatorServer(Board(load_rig("wigley-2m"), lockstep=True), idle_timeout_s=1.0).start()
    yield srv
    srv.stop()


class Host:
    """A minimal host on a raw socket: frames out, decoded messages in."""

    def __init__(self, port: int):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=2.0)
        self.parser = FrameParser()
        self.seq = 0

    def send(self, msg) -> None:
        self.sock.sendall(encode_frame(msg.type, self.seq, 0, msg.pack()))
        self.seq += 1

    def recv(self, kind: int, timeout_s: float = 2.0):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                data = self.sock.recv(4096)
            except socket.timeout:
                continue
            if data == b"":
                return None
            for frame in self.parser.feed(data):
                msg = m.decode(frame)
                if msg.type == kind:
                    return msg
        return None

    def close(self) -> None:
        self.sock.close()


def _latch_link_fault(server) -> None:
    """A host arms, drives with the brake released, and vanishes: LINK latched."""
    host = Host(server.port)
    host.send(m.Hello())
    assert host.recv(m.CAPS) is not None
    host.send(m.Empty(m.ARM))
    assert host.recv(m.SAMPLE).status & m.ST_ARMED
    for _ in range(5):
        host.send(m.Command("current", 4.0, brake=False))
        host.recv(m.SAMPLE)
    host.close()
    deadline = time.monotonic() + 3.0
    while not server.board.fault_bits & m.F_LINK and time.monotonic() < deadline:
        time.sleep(0.02)
    assert server.board.fault_bits & m.F_LINK


def test_faults_shown_not_cleared_then_cleared_on_request(server, capsys):
    _latch_link_fault(server)
    phi_before = server.board.last_reading.phi
    rc = main(["bench-faults", "--bench", server.url, "--json"])
    out = capsys.readouterr()
    assert rc == 3 and "link" in out.err and "--clear" in out.err
    assert json.loads(out.out)["before"]["faults"] == ["link"]
    assert server.board.fault_bits & m.F_LINK  # never cleared silently
    time.sleep(0.1)
    rc = main(["bench-faults", "--bench", server.url, "--clear", "--json"])
    out = capsys.readouterr()
    result = json.loads(out.out)
    assert rc == 0 and result["cleared"] and result["after"]["faults"] == [] and "clearing link" in out.err
    assert server.board.fault_bits == 0
    assert abs(server.board.last_reading.phi - phi_before) < 1e-4  # the hull stays where it was


def test_query_reports_the_present_state_after_a_drop(server):
    _latch_link_fault(server)
    host = Host(server.port)
    host.send(m.Hello())
    host.recv(m.CAPS)
    host.send(m.Empty(m.QUERY))
    sample = host.recv(m.SAMPLE)
    host.close()
    assert sample.faults & m.F_LINK
    assert sample.brake and sample.current == 0.0 and not sample.status & m.ST_ARMED  # not the stale 4 A


def test_second_host_is_told_busy(capsys):
    server = EmulatorServer(Board(load_rig("wigley-2m"), lockstep=True), idle_timeout_s=30.0).start()
    first = Host(server.port)
    first.send(m.Hello())
    assert first.recv(m.CAPS) is not None
    rc = main(["bench-faults", "--bench", server.url])
    err = capsys.readouterr().err
    first.close()
    server.stop()
    assert rc == 4 and "busy" in err, err
    assert server.refused_busy == 1


def test_idle_host_is_dropped_after_the_stated_time(server):
    host = Host(server.port)
    host.send(m.Hello())
    assert host.recv(m.CAPS) is not None
    t0 = time.monotonic()
    assert host.recv(m.SAMPLE, timeout_s=5.0) is None  # the server closed the link
    assert 0.9 < time.monotonic() - t0 < 4.0 and server.dropped_idle == 1
    host.close()


def test_bad_frames_latch(server):
    host = Host(server.port)
    host.send(m.Hello())
    assert host.recv(m.CAPS) is not None
    good = encode_frame(m.HEARTBEAT, 1, 0, m.Empty(m.HEARTBEAT, 7).pack())
    bad = good[:-1] + bytes([good[-1] ^ 0xFF])  # CRC broken
    host.sock.sendall(bad * 12)
    host.send(m.Empty(m.QUERY))
    sample = host.recv(m.SAMPLE)
    host.close()
    assert sample.faults & m.F_BAD_FRAMES
