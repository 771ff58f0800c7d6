"""The emulated bench board: the simulated rig behind the protocol's board-side rules.

:class:`Board` has no I/O. It takes decoded messages and returns the messages to send
back; :class:`~hw_adapter.emulator.EmulatorServer` moves bytes. It implements what
docs/PROTOCOL.md section 5 asks of real firmware: latched faults, the board watchdog,
brake supervision, the safe state (drive passive, brake on) and its own limits, so the
host's safety code is tested against a board that behaves like the real one should.

Protocol version 2 (the two-rate bench, docs/PROTOCOL.md section 9): a host whose HELLO
comes in a version-2 frame gets a version-2 CAPS; armed, the board then runs the inner
loop of :mod:`addedinertia_env.loop.board_loop` at every tick on the newest valid
SEGMENT (late ones counted and dropped; when they run out it holds for the grace, then
goes safe by itself with fault SEGMENTS), and streams its samples in SAMPLE_BATCH frames.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from addedinertia_env.loop.board_loop import DEFAULT_GRACE_US, DEFAULT_RATE_FILTER_HZ, MAX_KNOTS, BoardLoop
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.sensors import Reading

from hw_adapter import messages as m
from hw_adapter.faults import FaultLog, FaultPlan

PASSIVE = MotorCommand("passive", 0.0)
WIRE_COUNTS = 2**24  # counts per turn on the wire when the simulated encoder is exact (counts = 0)
FIRMWARE_VERSION = 1


@dataclass(frozen=True)
class BoardLimits:
    """The board's own protection, independent of the host (docs/PROTOCOL.md section 5)."""

    watchdog_ms: int = 50  # ms without a COMMAND while armed and driving -> safe state
    brake_response_ms: int = 20  # ms the brake may take to follow a request
    overcurrent_factor: float = 1.25  # measured |i| above this x i_max -> fault
    angle_limit: float = 0.8  # rad from the calibrated neutral: the hull's end switches
    encoder_rate_max: float = 20.0  # rad/s: a hull encoder step beyond this x dt is a glitch, not motion
    grace_ms: int = DEFAULT_GRACE_US // 1000  # version 2: ms a segment that ran out is held, then safe state
    batch_samples: int = 5  # version 2: samples per SAMPLE_BATCH
    rate_filter_hz: int = int(DEFAULT_RATE_FILTER_HZ)  # version 2: corner of the pd mode's rate estimate


@dataclass(frozen=True)
class ReceivedCommand:
    """A command the emulated board received: when (s after RESET), drive ``mode`` and ``value`` (A or V), brake request, and whether it was armed."""

    board_t: float  # s after RESET
    mode: str
    value: float
    brake: bool
    armed: bool


class Board:
    """State machine of the board around one :class:`MujocoRig`."""

    def __init__(self, params: RigParams, seed: int = 0, faults: FaultPlan | None = None, lockstep: bool = True,
                 limits: BoardLimits | None = None, board_id: str = "emulator"):
        self.params = params
        self.rig = MujocoRig(params, seed=seed)
        self.faults_plan = faults or FaultPlan()
        self.lockstep = lockstep
        self.limits = limits or BoardLimits()
        self.board_id = board_id
        s = params.sensors
        self.period_us = int(round(1e6 / s.sample_rate))
        self.phi_counts = s.phi_counts or WIRE_COUNTS
        self.psi_counts = s.psi_counts or WIRE_COUNTS
        self.armed = False
        self.fault_bits = 0
        self.cmd = PASSIVE
        self.brake_request = True
        self.cmd_seq = 0
        self.step_count = 0
        self.clock_base_us = 0
        self.last_reading = Reading(t=0.0, phi=0.0, psi=0.0, u=0.0, i=0.0, brake=True)
        self.last_command_wall = time.monotonic()
        self._mismatch_since: float | None = None  # board t when brake and request first differed
        self._glitch_done = False
        self._phi_read_prev: float | None = None  # the last hull encoder value read (encoder check)
        self._stuck_logged = False
        self.log = FaultLog()
        self.commands: list[ReceivedCommand] = []
        self.outbox: list = []  # FAULT messages raised outside handle() (watchdog, link)
        self.version = 1  # protocol version of the session (the HELLO's frame version)
        self.loop = BoardLoop(self.period_us, params.motor.i_max, self.limits.grace_ms * 1000,
                              float(self.limits.rate_filter_hz))
        self.on_segments = False  # version 2: the loop drives (a SEGMENT came since ARM); else COMMANDs do
        self.applied = PASSIVE  # the command applied over the last period
        self.segments_received = 0
        self._batch: list[m.Sample] = []
        self._batch_t0 = 0

    # --- clocks -------------------------------------------------------------------------
    @property
    def board_t(self) -> float:
        """Seconds since the last RESET (the fault schedule's clock)."""
        return self.rig.time

    @property
    def time_us(self) -> int:
        """The board clock, monotonic across RESETs, us."""
        return self.clock_base_us + int(round(self.rig.time * 1e6))

    def caps(self) -> m.Caps:
        """The board's CAPS: sample period, encoder counts, the drive's limits (A, V), watchdog (ms); the version-2 fields for a two-rate board."""
        mo, lim = self.params.motor, self.limits
        flags = m.CAP_EMULATOR | m.CAP_TWIST_ACTUATOR | (m.CAP_LOCKSTEP if self.lockstep else 0)
        if self.version < 2:
            return m.Caps(FIRMWARE_VERSION, flags, self.period_us, self.phi_counts, self.psi_counts, mo.i_max,
                          mo.u_max, lim.watchdog_ms, lim.brake_response_ms, self.board_id)
        return m.Caps(FIRMWARE_VERSION, flags | m.CAP_TWO_RATE, self.period_us, self.phi_counts, self.psi_counts,
                      mo.i_max, mo.u_max, lim.watchdog_ms, lim.brake_response_ms, self.board_id, lim.batch_samples,
                      MAX_KNOTS, sum(m.BOARD_MODE_BITS.values()), lim.grace_ms, lim.rate_filter_hz)

    # --- messages -----------------------------------------------------------------------
    def handle(self, msg, seq: int = 0, version: int = 1) -> list:
        """Answer one message from the host (``seq``, ``version``: its frame's sequence number and version)."""
        t = msg.type
        if t == m.HELLO:
            self.version = version
            self._batch = []
            return [self.caps()]
        if t == m.SEGMENT:
            return self._segment(msg)
        if t == m.QUERY:
            return self._flush_batch() + [self.sample(self.present())]
        if t == m.HEARTBEAT:
            return [m.Empty(m.HEARTBEAT, msg.reason)]
        if t == m.RESET:
            return [self._reset(msg)]
        if t == m.ARM:
            return self._arm()
        if t == m.DISARM:
            self.go_safe(m.F_HOST_STOP if msg.reason else 0, float(msg.reason))
            return self.pending() + self._flush_batch() + [self.sample(self.last_reading)]
        if t == m.COMMAND:
            return self._command(msg, seq)
        return []  # CAPS, SAMPLE, FAULT from a host: ignored

    def _reset(self, msg: m.Reset) -> m.Sample:
        self.clock_base_us = self.time_us + self.period_us  # the board clock never goes back
        self.armed = False
        self.fault_bits = 0
        self.cmd = PASSIVE
        self.brake_request = msg.brake
        self.cmd_seq = 0
        self.step_count = 0
        self._mismatch_since = None
        self.loop.restart()
        self.on_segments = False
        self._batch = []
        self._phi_read_prev = None  # the hull is placed: no step across a RESET
        self.last_reading = self.rig.reset(phi0=msg.phi0, psi0=msg.psi0, omega0=msg.omega0, brake=msg.brake)
        return self.sample(self.last_reading, extra_status=m.ST_RESET_DONE)

    def _arm(self) -> list:
        if self.fault_bits:
            return [m.Fault(self.fault_bits & -self.fault_bits, self.fault_bits, math.nan), self.sample(self.last_reading)]
        if not self.rig.brake:
            return [m.Fault(m.F_BRAKE, self.fault_bits, math.nan), self.sample(self.last_reading)]
        self.armed = True
        self.last_command_wall = time.monotonic()
        self.loop.restart()
        self.on_segments = False
        return self._flush_batch() + [self.sample(self.last_reading)]

    def _command(self, msg: m.Command, seq: int) -> list:
        self.commands.append(ReceivedCommand(self.board_t, msg.mode, msg.value, msg.brake, self.armed))
        self.last_command_wall = time.monotonic()
        if self.armed:
            limit = self.params.motor.i_max if msg.mode == "current" else self.params.motor.u_max
            self.cmd = MotorCommand(msg.mode, max(-limit, min(limit, msg.value)) if msg.mode != "passive" else 0.0)
            self.brake_request = msg.brake
            self.cmd_seq = seq
            self.on_segments = False  # a COMMAND (the host's safe stop, a version-1 host) overrides the loop
        if self.lockstep:
            return self.pending() + self._flush_batch() + [self.tick()] + self.pending()
        return []

    def _segment(self, msg: m.SegmentMsg) -> list:
        """Version 2: offer the segment to the loop (late ones are counted and dropped).
        Lock-step: then run the samples up to the segment's deadline (one host period)."""
        seg = msg.segment
        self.segments_received += 1
        self.commands.append(ReceivedCommand(self.board_t, "segment", seg.currents[0], seg.brake, self.armed))
        if self.armed:
            self.last_command_wall = time.monotonic()
            if self.loop.offer(seg, self.time_us):
                self.on_segments = True
        if not self.lockstep:
            return []
        out = self.pending()
        ticks = max(1, -(-((seg.deadline_us - self.time_us + 2**31) % 2**32 - 2**31) // self.period_us))
        for _ in range(min(ticks, 1000)):
            out += self.stream(self.tick()) + self.pending()
        return out + self._flush_batch()

    def present(self) -> Reading:
        """The instruments now, without stepping (what QUERY reports).

        The encoders have not moved since the last sample (the simulated bench only moves
        on a step), but a safe state entered since then (DISARM, a fault, a dropped link)
        has already opened the drive and set the brake: a passive drive carries no current
        and its terminals show the flywheel's back-EMF.
        """
        r = self.last_reading
        if self.armed and self.cmd.mode != "passive":
            return r
        back_emf = float(getattr(self.rig, "k_t", self.params.motor.k_t)) * self.rig.true_state().omega
        return Reading(t=r.t, phi=r.phi, psi=r.psi, u=back_emf, i=0.0, brake=bool(self.rig.brake))

    # --- the sample period --------------------------------------------------------------
    def tick(self) -> m.Sample:
        """One sample period under the latched command or, version 2, the inner loop (safe state when disarmed)."""
        hold = False
        if self.armed and self.on_segments:
            out = self.loop.command(self.time_us, self.last_reading.phi)
            if out.starved:
                self.go_safe(m.F_SEGMENTS, (self.time_us - self.loop.segment.end_us) * 1e-3)
            else:
                self.cmd, self.brake_request, hold = out.command, out.brake, out.hold
                self.cmd_seq = out.seg_id
        cmd = self.cmd if self.armed else PASSIVE
        request = self.brake_request if self.armed else True
        self.applied = cmd
        stuck = self.faults_plan.active("stuck_brake", self.board_t) > 0
        if request != self.rig.brake:
            if stuck:
                if not self._stuck_logged:
                    self._stuck_logged = True
                    self.log.add("fault_onset", time.monotonic(), self.board_t, fault="stuck_brake")
            else:
                self.rig.set_brake(request)
        r = self.rig.step(cmd)
        self.step_count += 1
        self._supervise(r, request)
        phi_offset = 0.0
        glitch = self.faults_plan.active("glitch", self.board_t)
        if glitch and not self._glitch_done:
            self._glitch_done = True
            phi_offset = glitch
            self.log.add("fault_onset", time.monotonic(), self.board_t, fault="glitch")
        self._check_encoder(r.phi + phi_offset)
        self.last_reading = r
        self._log_safe()
        return self.sample(r, phi_offset=phi_offset, extra_status=m.ST_SEGMENT_HOLD if hold else 0)

    def stream(self, sample: m.Sample) -> list:
        """What a free-running board sends for the sample of one tick: the SAMPLE itself
        (version 1), or a SAMPLE_BATCH once ``batch_samples`` have gathered (version 2)."""
        if self.version < 2:
            return [sample]
        if not self._batch:
            self._batch_t0 = self.time_us
        self._batch.append(sample)
        if len(self._batch) >= self.limits.batch_samples:
            return self._flush_batch()
        return []

    def _flush_batch(self) -> list:
        """The samples gathered so far as one SAMPLE_BATCH (none if none)."""
        if not self._batch:
            return []
        b, self._batch = self._batch, []
        return [m.SampleBatch(b[0].step, self.loop.late_segments, b[-1].cmd_seq, tuple(b), time_us=self._batch_t0)]

    def _check_encoder(self, phi_read: float) -> None:
        """Encoder plausibility (fault ENCODER): a step between two samples that no hull
        motion can make (``encoder_rate_max`` x the sample period) is a glitch or a
        miscount; armed, the board goes safe at that sample (PROTOCOL.md section 5)."""
        prev, self._phi_read_prev = self._phi_read_prev, phi_read
        step_max = self.limits.encoder_rate_max * self.period_us * 1e-6
        if self.armed and prev is not None and abs(phi_read - prev) > step_max and not self.fault_bits & m.F_ENCODER:
            self.go_safe(m.F_ENCODER, phi_read - prev)

    def _supervise(self, r: Reading, request: bool) -> None:
        lim, p = self.limits, self.params
        if request != r.brake:
            if self._mismatch_since is None:
                self._mismatch_since = r.t
            elif r.t - self._mismatch_since > lim.brake_response_ms * 1e-3 and not self.fault_bits & m.F_BRAKE:
                self.go_safe(m.F_BRAKE, r.t - self._mismatch_since)
        else:
            self._mismatch_since = None
        if abs(r.i) > lim.overcurrent_factor * p.motor.i_max:
            self.go_safe(m.F_OVERCURRENT, r.i)
        if abs(r.phi - p.spring.phi_neutral) > lim.angle_limit and not self.fault_bits & m.F_ANGLE_LIMIT:
            self.go_safe(m.F_ANGLE_LIMIT, r.phi)

    def check_watchdog(self, now: float) -> None:
        """Free-running board: no COMMAND for ``watchdog_ms`` while driving -> safe state."""
        if self.armed and not self.commanding_safe and now - self.last_command_wall > self.limits.watchdog_ms * 1e-3:
            self.go_safe(m.F_WATCHDOG, (now - self.last_command_wall) * 1e3)

    @property
    def commanding_safe(self) -> bool:
        """The latched command is already the safe state (drive passive, brake requested)."""
        return self.cmd.mode == "passive" and self.brake_request

    def go_safe(self, bit: int = 0, detail: float = math.nan) -> None:
        """Drive passive and brake on now; latch ``bit`` and queue a FAULT message."""
        self.armed = False
        self.on_segments = False
        self.cmd = PASSIVE
        self.brake_request = True
        if not (self.faults_plan.active("stuck_brake", self.board_t) > 0):
            self.rig.set_brake(True)
        if bit and not self.fault_bits & bit:
            self.fault_bits |= bit
            self.outbox.append(m.Fault(bit, self.fault_bits, float(detail)))
            self.log.add("board_fault", time.monotonic(), self.board_t, fault=m.FAULT_NAMES.get(bit, str(bit)))
        self._log_safe()

    def link_lost(self) -> None:
        """The connection dropped: safe state, latched LINK fault if it was armed."""
        self.go_safe(m.F_LINK if self.armed else 0)

    def _log_safe(self) -> None:
        if self.log.first("fault_onset") is not None and self.log.first("safe") is None and self.is_safe:
            self.log.add("safe", time.monotonic(), self.board_t)

    @property
    def is_safe(self) -> bool:
        """Disarmed, drive passive, brake requested and (unless stuck) engaged."""
        stuck = self.faults_plan.active("stuck_brake", self.board_t) > 0
        return not self.armed and self.cmd.mode == "passive" and self.brake_request and (self.rig.brake or stuck)

    def pending(self) -> list:
        """The messages queued for the host since the last call (FAULTs, unasked HEARTBEATs), emptying the queue."""
        out, self.outbox = self.outbox, []
        return out

    # --- encoding -----------------------------------------------------------------------
    def sample(self, r: Reading, extra_status: int = 0, phi_offset: float = 0.0) -> m.Sample:
        """Encode reading ``r`` as a SAMPLE: angles (rad) to encoder counts (the motor's as a wrapping
        i32 counter), current (A), voltage (V), the status and latched fault bits. ``phi_offset`` (rad)
        is added to the hull angle (an encoder glitch); ``extra_status`` bits are or-ed in.
        """
        status = extra_status
        status |= m.ST_ARMED if self.armed else 0
        status |= m.ST_BRAKE_REQUESTED if (self.brake_request or not self.armed) else 0
        status |= m.ST_DRIVE_ENABLED if (self.armed and self.cmd.mode != "passive") else 0
        phi_count = int(round((r.phi + phi_offset) / (2 * math.pi) * self.phi_counts))
        psi_count = int(round(r.psi / (2 * math.pi) * self.psi_counts))
        psi_wrapped = (psi_count + 2**31) % 2**32 - 2**31  # a free-running i32 counter
        phi_count = max(-2**31, min(2**31 - 1, phi_count))
        i_cmd = self.applied.value if self.applied.mode == "current" else 0.0
        return m.Sample(phi_count, psi_wrapped, float(r.i), float(r.u), bool(r.brake), status, self.fault_bits,
                        self.cmd_seq, self.step_count, i_cmd)
