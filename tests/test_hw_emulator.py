"""The emulated board (board-side rules of docs/PROTOCOL.md) and BenchRig over loopback."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.presets import load_rig
from hw_adapter import messages as m
from hw_adapter.bench_rig import BenchRig
from hw_adapter.board import Board, BoardLimits
from hw_adapter.faults import parse_faults
from hw_adapter.lab import load_lab
from hw_adapter.loopback import start_emulator
from hw_adapter.safety import SafetyTrip

RIG = load_rig("wigley-2m")


def armed_board(**kwargs) -> Board:
    board = Board(RIG, seed=3, **kwargs)
    reply = board.handle(m.Reset(-0.1, 0.0, 0.0, True))
    assert reply[0].status & m.ST_RESET_DONE
    assert isinstance(board.handle(m.Empty(m.ARM))[-1], m.Sample) and board.armed
    return board


def test_board_steps_once_per_command_and_echoes_its_sequence():
    board = armed_board()
    t0 = board.time_us
    (s1,) = board.handle(m.Command("current", 2.0, True, 0), seq=17)
    (s2,) = board.handle(m.Command("current", 2.0, True, 0), seq=18)
    assert (s1.cmd_seq, s2.cmd_seq) == (17, 18)
    assert (s1.step, s2.step) == (1, 2)
    assert board.time_us - t0 == 2 * board.period_us
    assert s2.status & m.ST_ARMED and s2.status & m.ST_DRIVE_ENABLED
    assert abs(s2.current - 2.0) < 0.1  # the drive's current loop tracks the command
    assert s2.phi_count == round(-0.1 / (2 * math.pi) * RIG.sensors.phi_counts)


def test_the_wire_is_transparent_the_board_reads_like_the_simulated_rig():
    """Same seed, same commands: the board's samples decode to the MujocoRig's readings."""
    board = armed_board()
    rig = MujocoRig(RIG, seed=3)
    rig.reset(phi0=-0.1, brake=True)
    rig.set_brake(False)
    for k in range(30):
        cmd = MotorCommand("current", 3.0 * math.sin(k / 5))
        (s,) = board.handle(m.Command(cmd.mode, cmd.value, False, 0), seq=k)
        r = rig.step(MotorCommand("current", float(np.float32(cmd.value))))
        assert s.phi_count * 2 * math.pi / board.phi_counts == pytest.approx(r.phi, abs=1e-12)
        assert s.psi_count * 2 * math.pi / board.psi_counts == pytest.approx(r.psi, abs=1e-12)
        assert s.current == pytest.approx(r.i, rel=1e-6, abs=1e-6)
        assert s.voltage == pytest.approx(r.u, rel=1e-6, abs=1e-5)
        assert s.brake == r.brake is False


def test_board_refuses_to_arm_with_a_latched_fault_or_a_released_brake():
    board = armed_board()
    board.handle(m.Empty(m.DISARM, 8))
    assert board.fault_bits & m.F_HOST_STOP and not board.armed
    reply = board.handle(m.Empty(m.ARM))
    assert isinstance(reply[0], m.Fault) and not board.armed
    board.handle(m.Reset(0.0, 0.0, 0.0, False))  # RESET clears faults; the brake is released
    reply = board.handle(m.Empty(m.ARM))
    assert isinstance(reply[0], m.Fault) and reply[0].code == m.F_BRAKE and not board.armed


def test_board_watchdog_stops_a_driving_board_but_not_a_safe_one():
    board = armed_board(lockstep=False, limits=BoardLimits(watchdog_ms=30))
    board.handle(m.Command("passive", 0.0, True, 0))  # the safe command: nothing to stop
    board.check_watchdog(time.monotonic() + 1.0)
    assert board.armed
    board.handle(m.Command("current", 5.0, True, 0))
    board.check_watchdog(board.last_command_wall + 0.02)
    assert board.armed
    board.check_watchdog(board.last_command_wall + 0.031)
    assert not board.armed and board.fault_bits & m.F_WATCHDOG and board.is_safe
    assert any(isinstance(x, m.Fault) and x.code == m.F_WATCHDOG for x in board.pending())
    s = board.tick()
    assert abs(s.current) < 0.05 and s.brake and not s.status & m.ST_ARMED  # zero, to sensor noise


def test_stuck_brake_is_latched_by_the_board_within_its_response_time():
    board = armed_board(faults=parse_faults("stuck_brake"), limits=BoardLimits(brake_response_ms=20))
    samples = [next(x for x in board.handle(m.Command("passive", 0.0, False, 0)) if isinstance(x, m.Sample))
               for _ in range(25)]
    assert all(s.brake for s in samples)  # it never released
    faulted = [k for k, s in enumerate(samples) if s.faults & m.F_BRAKE]
    assert faulted and 19 <= faulted[0] <= 22
    assert board.log.first("fault_onset")["fault"] == "stuck_brake" and board.log.first("safe") is not None


def test_glitch_offsets_exactly_one_sample():
    board = armed_board(faults=parse_faults("glitch=0.3@0.005"))
    samples = [[x for x in board.handle(m.Command("passive", 0.0, True, 0)) if isinstance(x, m.Sample)][-1]
               for _ in range(10)]
    phis = [s.phi_count * 2 * math.pi / board.phi_counts for s in samples]
    jumps = [k for k in range(10) if abs(phis[k] + 0.1) > 0.01]
    assert len(jumps) == 1 and abs(phis[jumps[0]] - 0.2) < 1e-3
    # the board's encoder check latches ENCODER and goes safe at that very sample
    faulted = [k for k, s in enumerate(samples) if s.faults & m.F_ENCODER]
    assert faulted and faulted[0] == jumps[0] and not board.armed


def test_bench_rig_over_loopback_runs_the_rig_protocol():
    server = start_emulator(fast=True)
    rig = BenchRig(server.url, load_lab("wigley-2m"))
    try:
        caps = rig.connect()
        assert rig.source == "emulator" and rig.lockstep and rig.dt == pytest.approx(1e-3)
        assert caps.phi_counts == RIG.sensors.phi_counts
        known = rig.known
        assert known.c_torsion == RIG.spring.c and known.i_max == RIG.motor.i_max
        assert "lambda66" not in str(known.to_block()) and rig.truth() is None
        rig.arm()
        r0 = rig.reset(phi0=-0.1)
        assert r0.t == 0.0 and r0.brake and abs(r0.phi + 0.1) < 1e-4
        rig.set_brake(False)
        rs = [rig.step(MotorCommand("passive", 0.0)) for _ in range(200)]
        assert [round(r.t, 6) for r in rs[:3]] == [0.001, 0.002, 0.003]
        assert not rs[-1].brake and rs[-1].phi > rs[0].phi  # released: the rod swings it back
        rig.set_brake(True)
        r = rig.step(MotorCommand("current", 50.0))  # beyond the limit: clamped
        assert r.brake
        assert rig.sent[-1].value == RIG.motor.i_max
        assert max(abs(c.value) for c in server.board.commands) <= RIG.motor.i_max
        rig.disarm()
        assert rig.confirm_safe()["confirmed"]
        assert server.board.is_safe
    finally:
        rig.close()
        server.stop()


def test_link_loss_leaves_the_board_safe_and_a_reconnecting_host_sees_it():
    server = start_emulator(fast=True, faults="disconnect@0.05")
    rig = BenchRig(server.url, load_lab("wigley-2m"))
    try:
        rig.connect()
        rig.arm()
        rig.reset(phi0=-0.1)
        with pytest.raises(SafetyTrip) as e:
            for _ in range(200):
                rig.step(MotorCommand("current", 1.0))
        assert e.value.kind == "link"
        assert server.board.is_safe and server.board.fault_bits & m.F_LINK
        state = rig.confirm_safe(timeout_s=3.0)
        assert state["confirmed"] and state["reconnects"] >= 1 and "link" in state["board_faults"]
    finally:
        rig.close()
        server.stop()


def test_free_running_board_streams_at_its_sample_rate():
    server = start_emulator(fast=False)
    rig = BenchRig(server.url, load_lab("wigley-2m"), watchdog_s=0.5)
    try:
        rig.connect()
        assert not rig.lockstep
        stamps = []
        deadline = time.perf_counter() + 5.0
        while len(stamps) < 50 and time.perf_counter() < deadline:
            got = rig.link.recv(0.5)
            if got is not None and isinstance(got[1], m.Sample):
                stamps.append(got[0].time_us)
        assert len(stamps) == 50
        steps = np.diff(stamps)
        assert np.all(steps % server.board.period_us == 0) and np.all(steps > 0)  # board clock: whole periods
    finally:
        rig.close()
        server.stop()


def test_bench_server_refuses_bad_options(capsys):
    assert main(["bench-server", "--faults", "explode=1", "--port", "0"]) == 2
    assert "unknown fault 'explode'" in capsys.readouterr().err
    assert main(["bench-server", "--rig", "no-such-rig", "--port", "0"]) == 2
