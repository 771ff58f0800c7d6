"""BenchRig: a bench (real or emulated) behind the rig protocol of ``rig/interface.py``.

``Experiment`` and ``run_experiment`` drive it unchanged. Every command goes through the
:class:`~hw_adapter.safety.SafetyEnvelope` and every sample is checked by it; a failed
check, a board fault, link silence beyond the watchdog time or lost frames beyond the
budget send the bench to the safe state (drive passive = zero current, brake requested,
DISARM) and raise :class:`~hw_adapter.safety.SafetyTrip`. A :class:`Watchdog` thread
does the same if the control loop stalls while the bench is driven.

Protocol choices (docs/PROTOCOL.md):

* ``reset(phi0)`` sends RESET and waits for the SAMPLE flagged RESET_DONE: the emulator
  places the hull at once; a real board with a twist actuator moves it; without one an
  operator twists the rod and sets the brake (the host waits up to ``reset_timeout_s``,
  sending HEARTBEATs). The sample times of the run start at 0 at that SAMPLE. RESET
  disarms the board; ``reset`` re-arms it if it was armed.
* ``set_brake(on)`` changes the brake request carried by every COMMAND. On a
  free-running board it is sent at once (the hull may be moving); in lock-step it goes
  with the next step, which is the same instant of board time.
* ``step(cmd)`` sends one COMMAND and returns the next SAMPLE. On a free-running board,
  samples that queued while the host was busy are skipped to the newest and counted as
  overruns.

Two-rate mode (``host_rate_hz``; protocol version 2, docs/PROTOCOL.md section 9): the
board runs the inner loop every sample and the host sends SEGMENTs at its own rate.
``step(cmd)`` then returns the *next* board sample in order (none is skipped: every one
is checked and recorded) and, once per host period, sends ``cmd`` as a zero-order-hold
segment (the experiment's uncontrolled phases); ``step(None)`` only reads, the caller
sends its own segments with :meth:`send_segment` (``experiment.two_rate.drive_two_rate``).
``set_brake`` sends a segment at once. Samples arrive in SAMPLE_BATCH frames.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

from addedinertia_env.loop.board_loop import Segment, elapsed_us, zoh_segment
from addedinertia_env.rig.known import KnownRig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.sensors import Reading

from hw_adapter import messages as m
from hw_adapter.framing import ClockUnwrapper, Frame
from hw_adapter.lab import LabConfig, known_rig
from hw_adapter.link import Link, LinkError
from hw_adapter.safety import SafetyEnvelope, SafetyLimits, SafetyTrip
from hw_adapter.watchdog import Watchdog

PASSIVE = MotorCommand("passive", 0.0)
REALTIME_WATCHDOG_S = 0.020  # s: link silence that trips a free-running (real) bench
LOCKSTEP_WATCHDOG_S = 1.0  # s: a lock-stepped emulator does not move while it waits; only a dead one is caught
LOCKSTEP_RETRY_S = 0.1  # s: a lock-step answer this late is asked for again (counts against the link budget)
HELLO_TRIES = 5
STOP_REASONS = {"angle": 1, "rate": 2, "flywheel_rate": 3, "current": 4, "voltage": 5, "board_fault": 6, "brake": 7,
                "link": 8, "sensor": 9, "watchdog": 10, "operator": 11, "arming": 12, "experiment": 13,
                "controller": 14}  # DISARM reason codes (docs/PROTOCOL.md)


@dataclass
class SentCommand:
    """A command the host sent: when (host ``perf_counter`` s), drive ``mode`` and ``value`` (A or V), brake request."""

    host_s: float  # s, host perf_counter
    mode: str
    value: float
    brake: bool


@dataclass
class LoopTiming:
    """Host-side timing of the control loop (perf_counter seconds)."""

    intervals: list[float] = field(default_factory=list)  # between successive samples of the loop
    compute_s: list[float] = field(default_factory=list)  # sample received -> next command sent
    skipped_samples: int = 0  # stale samples dropped to catch up (free-running board)
    overruns: int = 0  # loop iterations longer than one sample period, + skipped samples
    lockstep_retries: int = 0
    # Two-rate mode (host_rate_hz):
    segment_intervals: list[float] = field(default_factory=list)  # s between successive segments sent
    segment_slack_ms: list[float] = field(default_factory=list)  # deadline - estimated board time at sending
    segments_sent: int = 0
    samples_lost: int = 0  # board samples missing from the record (step gaps after RESET)
    late_segments: int = 0  # the board's count: segments that reached it after their deadline
    hold_samples: int = 0  # samples the board ran on a segment that had run out (within the grace)


class BenchRig:
    """See the module docstring; ``source`` is ``"emulator"`` or ``"bench"`` from the board's CAPS."""

    def __init__(self, url: str, lab: LabConfig, watchdog_s: float | None = None, reset_timeout_s: float = 120.0,
                 limit_overrides: dict[str, float] | None = None,
                 on_sample: Callable[[Reading, MotorCommand | None], None] | None = None,
                 host_rate_hz: float | None = None):
        self.url = url
        self.host_rate_hz = host_rate_hz
        self.two_rate = host_rate_hz is not None
        self.applied_command: MotorCommand | None = None  # two-rate: what the board applied (last sample)
        self.lab = lab
        self.reset_timeout_s = reset_timeout_s
        self.limit_overrides = limit_overrides or {}
        self.on_sample = on_sample
        self._watchdog_s = watchdog_s
        self.link = Link(url)
        self.caps: m.Caps | None = None
        self.source = "bench"
        self.stated_round_trip_s: float | None = None  # s, the link's round trip stated to the controllers (deploy)
        self.sent: list[SentCommand] = []
        self.timing = LoopTiming()
        self.trip: SafetyTrip | None = None
        self.trip_wall: float | None = None  # perf_counter when the trip was detected
        self.safe_command_wall: float | None = None  # perf_counter when the safe state was sent
        self.last_sample: m.Sample | None = None
        self.armed = False
        self.brake_request = True
        self._trip_lock = threading.Lock()
        self._clock = ClockUnwrapper()
        self._t0_us = 0
        self._psi_total = 0
        self._psi_last: int | None = None
        self._last_cmd_seq = 0
        self._last_sample_seq = 0
        self._last_sample_wall: float | None = None
        self._last_board_us: int | None = None
        self._mismatch_since: float | None = None
        self._last_logged_t = -math.inf
        self.watchdog: Watchdog | None = None
        self.envelope: SafetyEnvelope | None = None
        self.limits: SafetyLimits | None = None
        self._queued: deque = deque()  # two-rate: samples of a batch not yet handed out
        self._newest_raw_us: int | None = None  # board time (u32) of the newest sample received
        self._newest_wall = 0.0
        self._seg_id = 0
        self._zoh: tuple[MotorCommand, bool] | None = None
        self._zoh_t0 = 0
        self._last_segment_wall: float | None = None

    # --- connection ---------------------------------------------------------------------
    def connect(self) -> m.Caps:
        """HELLO -> CAPS; builds the rig block, the limits and the watchdog."""
        if self.two_rate:
            self.link.version = 2
        for _ in range(HELLO_TRIES):
            self.link.send(m.Hello())
            deadline = time.perf_counter() + 0.5
            while (left := deadline - time.perf_counter()) > 0:
                got = self.link.recv(left)
                if got is not None and isinstance(got[1], m.Caps):
                    self.caps = got[1]
                    break
                if got is not None and got[1].type == m.HEARTBEAT and got[1].reason == m.BUSY_REASON:
                    raise LinkError(f"bench {self.url!r} is busy: another host is connected; "
                                    "try again when its run has ended")
            if self.caps is not None:
                break
        if self.caps is None:
            raise LinkError(f"bench {self.url!r} did not answer HELLO with CAPS ({HELLO_TRIES} tries of 0.5 s); "
                            "is the board powered and is this its port?"
                            + (" (two-rate mode sends a version-2 HELLO, which a version-1 board ignores: "
                               "run without --host-rate-hz)" if self.two_rate else ""))
        if self.two_rate and not self.caps.two_rate:
            raise LinkError(f"bench {self.url!r} answered without the two-rate capability (CAPS version 1); "
                            "run without --host-rate-hz")
        self.source = "emulator" if self.caps.flags & m.CAP_EMULATOR else "bench"
        self._known = known_rig(self.lab, self.caps)
        self.limits = self.lab.safety_limits(self.caps, **self.limit_overrides)
        self.envelope = SafetyEnvelope(self.limits, self.lab.constants["phi_neutral"])
        if self._watchdog_s is None:
            self._watchdog_s = LOCKSTEP_WATCHDOG_S if self.lockstep else REALTIME_WATCHDOG_S
            # Two-rate mode keeps the single-rate default (20 ms) so that no link fault takes
            # longer to stop than before; a slower host may relax it to the board's own bound
            # for a silent host, --watchdog-ms 50 (3 host periods + grace at 100 Hz).
        if self.watchdog is None:
            self.watchdog = Watchdog(self._watchdog_s, self._watchdog_expired)
        return self.caps

    @property
    def lockstep(self) -> bool:
        """Whether the board steps once per command (the emulator's ``--fast``) instead of free-running."""
        return bool(self.caps and self.caps.flags & m.CAP_LOCKSTEP)

    @property
    def watchdog_s(self) -> float:
        """The host watchdog's timeout, s (20 ms free-running, 1 s lock-step, unless given)."""
        return float(self._watchdog_s or REALTIME_WATCHDOG_S)

    def close(self) -> None:
        """Stop the host watchdog and close the link (no safe command is sent: see :meth:`disarm`)."""
        if self.watchdog is not None:
            self.watchdog.close()
        self.link.close()

    # --- the rig protocol ---------------------------------------------------------------
    @property
    def dt(self) -> float:
        """The board's sample (and control) period, s."""
        return self.caps.sample_period_us * 1e-6

    @property
    def known(self) -> KnownRig:
        """What the experimenter knows of this bench (lab file + the board's CAPS)."""
        return self._known

    def truth(self) -> None:
        """None: a bench has no truth (the emulator keeps its own in its process)."""
        return None  # a bench has no truth, the emulator's stays in its own process

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True) -> Reading:
        """Place the hull at ``phi0`` (rad) with the motor counter at ``psi0`` (rad) and the flywheel at
        ``omega0`` (rad/s, emulator), braked as given; waits (up to ``reset_timeout_s``) for the board's
        RESET_DONE, re-arms if it was armed, and returns that sample as a :class:`Reading`.
        Raises :class:`SafetyTrip` if no RESET_DONE comes or a check fails.
        """
        self._raise_if_tripped()
        was_armed = self.armed
        self.armed = False
        self.watchdog.arm(False)
        self.link.send(m.Reset(phi0, psi0, omega0, brake))
        deadline = time.perf_counter() + self.reset_timeout_s
        next_beat = time.perf_counter() + 0.5
        while True:
            now = time.perf_counter()
            if now > deadline:
                raise self.stop("link", f"no RESET_DONE within {self.reset_timeout_s} s of RESET")
            if now > next_beat:
                self.link.send(m.Empty(m.HEARTBEAT))
                next_beat = now + 0.5
            got = self._recv(min(0.1, deadline - now))
            if got is None:
                continue
            frame, msg = got
            if isinstance(msg, m.Sample) and msg.status & m.ST_RESET_DONE:
                break
        self.brake_request = brake
        self.last_sample = msg
        self._last_sample_wall = None
        self._clock_reset(frame, msg)
        reading = self._reading(frame, msg)
        self.envelope.forget_motion()
        self._check(reading, msg)
        if self.on_sample is not None:
            self.on_sample(reading, None)
        if was_armed:
            self.arm()
        return reading

    def set_brake(self, on: bool) -> None:
        """Request the brake on or off; sent at once while armed (a new zero-order-hold segment in two-rate mode), else with the next command."""
        self.brake_request = bool(on)
        if self.two_rate:  # at once while zero-order-hold segments run; a planned segment has its own schedule
            if self.armed and self._zoh is not None:
                self._send_zoh(self._zoh[0])
            return
        if not self.lockstep and self.armed:
            last = self.sent[-1] if self.sent else SentCommand(0.0, "passive", 0.0, True)
            self._send_command(MotorCommand(last.mode, last.value))

    def step(self, cmd: MotorCommand | None) -> Reading:
        """Send ``cmd`` (clamped to the safety envelope) and return the next sample as a :class:`Reading`.

        Two-rate: a new zero-order-hold segment only when the command changes or a host period has
        passed. Raises :class:`SafetyTrip` on a disarmed bench or a tripped check.
        """
        self._raise_if_tripped()
        if not self.armed:
            raise self.stop("operator", "step() on a disarmed bench; call arm() after connect()")
        if self.two_rate:
            if cmd is not None:
                cmd = self.envelope.clamp(cmd)
                t_new = self._newest_raw_us if self._newest_raw_us is not None else 0
                if self._zoh != (cmd, self.brake_request) or (
                        elapsed_us(t_new, self._zoh_t0) >= self.host_period_us and self.poll() == 0):
                    self._send_zoh(cmd)
            return self._next_sample_two_rate()
        if self._last_sample_wall is not None:
            busy = time.perf_counter() - self._last_sample_wall
            self.timing.compute_s.append(busy)
            if busy > self.dt:
                self.timing.overruns += 1
        sent = self._send_command(self.envelope.clamp(cmd))
        return self._next_sample(sent)

    # --- two-rate (protocol version 2) ------------------------------------------------------
    @property
    def host_period_us(self) -> int:
        """The host's period in two-rate mode, us."""
        return int(round(1e6 / self.host_rate_hz))

    def next_seg_id(self) -> int:
        """The next segment id (u16, wraps)."""
        self._seg_id = (self._seg_id + 1) & 0xFFFF
        return self._seg_id

    def board_time_us(self, t: float) -> int:
        """Board clock (u32, us) of record time ``t`` (s after RESET)."""
        return (self._t0_us + int(round(t * 1e6))) & 0xFFFFFFFF

    @property
    def newest_board_us(self) -> int:
        """Board time (u32) of the newest sample received, read or not."""
        return self._newest_raw_us if self._newest_raw_us is not None else self.board_time_us(0.0)

    def poll(self) -> int:
        """Read what has arrived without waiting; returns the samples not yet handed out."""
        while True:
            got = self._recv(0.0, hold=True)
            if got is None:
                break
        return len(self._queued)

    def send_segment(self, seg: Segment) -> None:
        """Send one SEGMENT (refused after a trip, like every command); timing is recorded."""
        self._zoh = None
        self._send_segment(seg)

    def _send_zoh(self, cmd: MotorCommand) -> None:
        self.poll()  # t0 = the freshest board time known, so the segment is not late on arrival
        t0 = self.newest_board_us
        switch = None
        self._send_segment(zoh_segment(self.next_seg_id(), cmd, self.brake_request, t0, self.host_period_us, switch))
        self._zoh, self._zoh_t0 = (cmd, self.brake_request), t0

    def _send_segment(self, seg: Segment) -> None:
        with self._trip_lock:
            if self.trip is not None:
                raise self.trip
            self.link.send(m.SegmentMsg(seg))
        now = time.perf_counter()
        t = self.timing
        t.segments_sent += 1
        if self._last_segment_wall is not None:
            t.segment_intervals.append(now - self._last_segment_wall)
        self._last_segment_wall = now
        if self._newest_raw_us is not None:
            board_now = self._newest_raw_us + int((now - self._newest_wall) * 1e6)
            t.segment_slack_ms.append(elapsed_us(seg.deadline_us, board_now) * 1e-3)
        value = seg.currents[0] if not seg.passive else 0.0
        self.sent.append(SentCommand(now, "passive" if seg.passive else "current", float(value), seg.brake))
        # The watchdog thread stays disarmed in two-rate mode: a stalled host sends no more
        # segments, and the board holds the last one for its grace, then goes safe by itself
        # (at most two host periods + the grace after the last segment). Link silence is
        # still caught by the loop (_next_sample_two_rate), at the host watchdog time.

    def _next_sample_two_rate(self) -> Reading:
        """The next board sample in order (blocking up to the host watchdog); none is skipped."""
        start = time.perf_counter()
        deadline = start + self.watchdog_s
        while not self._queued:
            self._raise_if_tripped()
            now = time.perf_counter()
            if now >= deadline:
                raise self.stop("link", f"no sample for {1e3 * (now - start):.1f} ms "
                                        f"(watchdog {1e3 * self.watchdog_s:.0f} ms)")
            self._recv(deadline - now, hold=True)
        frame, msg = self._queued.popleft()
        reading = self._accept(frame, msg)
        return self._arrived(reading)

    # --- arming -------------------------------------------------------------------------
    def query(self) -> tuple[m.Sample, Reading]:
        """The board's present state without a step (QUERY -> SAMPLE)."""
        for _ in range(3):
            self.link.send(m.Empty(m.QUERY))
            deadline = time.perf_counter() + 0.5
            while (left := deadline - time.perf_counter()) > 0:
                got = self._recv(left)
                if got is not None and isinstance(got[1], m.Sample):
                    frame, msg = got
                    if self._last_board_us is None:
                        self._clock_reset(frame, msg)
                    return msg, self._reading(frame, msg, advance_psi=False)
        raise self.stop("link", "the board did not answer QUERY")

    def arm(self) -> None:
        """ARM the board and wait (1 s) for a sample that confirms it; raises :class:`SafetyTrip` if the board refuses or does not answer."""
        self.link.send(m.Empty(m.ARM))
        deadline = time.perf_counter() + 1.0
        while (left := deadline - time.perf_counter()) > 0:
            got = self._recv(left)
            if got is None:
                break
            frame, msg = got
            if isinstance(msg, m.Fault):
                raise self.stop("board_fault", f"the board refused ARM: faults {m.fault_names(msg.faults)}")
            if isinstance(msg, m.Sample) and msg.status & m.ST_ARMED:
                self.armed = True
                self.last_sample = None if not self.lockstep else msg  # free-running: samples skipped below
                self._last_sample_seq = frame.seq
                self.link.drain()
                self._queued.clear()
                self._zoh = None
                self._last_sample_wall = None
                return
        raise self.stop("link", "the board did not confirm ARM within 1 s")

    def disarm(self, reason: int = 0) -> None:
        """Pause the watchdog, send the safe command (passive, braked) and DISARM with ``reason``; a dead link is ignored here."""
        self.watchdog.arm(False)
        self.armed = False
        try:
            self._send_command(PASSIVE, brake=True, safe=True)
            self.link.send(m.Empty(m.DISARM, reason))
        except LinkError:
            pass

    # --- safe stop ----------------------------------------------------------------------
    def stop(self, kind: str, message: str) -> SafetyTrip:
        """Send the safe state (once) and return the trip to raise."""
        with self._trip_lock:
            if self.trip is None:
                self.trip = SafetyTrip(kind, message)
                self.trip_wall = time.perf_counter()
                self._send_safe(STOP_REASONS.get(kind, 99))
        return self.trip

    def _watchdog_expired(self, why: str) -> None:
        self.stop("watchdog", why)

    def _send_safe(self, reason: int) -> None:
        if self.watchdog is not None:
            self.watchdog.arm(False)
        self.armed = False
        self.brake_request = True
        try:
            self._send_command(PASSIVE, brake=True, safe=True)
            self.link.send(m.Empty(m.DISARM, reason))
            self.safe_command_wall = time.perf_counter()
        except LinkError:
            pass  # the board's own watchdog and link-loss rule take over; confirm_safe reconnects

    def _raise_if_tripped(self) -> None:
        if self.trip is not None:
            raise self.trip

    def confirm_safe(self, timeout_s: float = 1.0, needed: int = 3) -> dict:
        """After a stop: read the board (reconnecting if the link broke) until it shows the
        safe state ``needed`` times in a row: disarmed, brake requested, |current| small."""
        deadline = time.perf_counter() + timeout_s
        good = 0
        last: m.Sample | None = None
        reconnects = 0
        while time.perf_counter() < deadline and good < needed:
            try:
                if self.link.closed:
                    reconnects += 1
                    self.link = Link(self.url, open_timeout_s=0.5)
                    self.link.send(m.Hello())
                self._send_command(PASSIVE, brake=True, safe=True)
                got = self._recv(0.05, check_trip=False)
            except LinkError:
                time.sleep(0.05)
                continue
            if got is None or not isinstance(got[1], m.Sample):
                continue
            frame, last = got
            reading = self._reading(frame, last, advance_psi=True, update_clock=True)
            if self.on_sample is not None and reading.t > self._last_logged_t:
                self.on_sample(reading, PASSIVE)
                self._last_logged_t = reading.t
            safe = (not last.status & m.ST_ARMED and last.status & m.ST_BRAKE_REQUESTED
                    and abs(last.current) <= max(0.05 * self.caps.i_max, 0.2))
            good = good + 1 if safe else 0
        state = {"confirmed": good >= needed, "reconnects": reconnects}
        if last is not None:
            state.update({"armed": bool(last.status & m.ST_ARMED), "brake_requested": bool(last.status & m.ST_BRAKE_REQUESTED),
                          "brake_engaged": bool(last.brake), "current_A": float(last.current),
                          "board_faults": m.fault_names(last.faults)})
        return state

    # --- internals ----------------------------------------------------------------------
    def _send_command(self, cmd: MotorCommand, brake: bool | None = None, safe: bool = False) -> int:
        """Send one COMMAND. Unless it is the safe state sent by a trip, it is refused
        once the envelope has tripped: nothing but the safe state follows a trip."""
        brake = self.brake_request if brake is None else brake
        if safe:
            seq = self.link.send(m.Command(cmd.mode, float(cmd.value), brake, self._last_sample_seq))
        else:
            with self._trip_lock:
                if self.trip is not None:
                    raise self.trip
                seq = self.link.send(m.Command(cmd.mode, float(cmd.value), brake, self._last_sample_seq))
        self.sent.append(SentCommand(time.perf_counter(), cmd.mode, float(cmd.value), brake))
        self._last_cmd_seq = seq
        if self.watchdog is not None and self.armed:
            self.watchdog.arm(not (cmd.mode == "passive" and brake))
        return seq

    def _recv(self, timeout_s: float, check_trip: bool = True, hold: bool = False):
        """The next message (a SAMPLE_BATCH comes out as its samples, one per call, in order).
        ``hold``: samples go to the queue for :meth:`_next_sample_two_rate` instead."""
        if self._queued and not hold:
            return self._queued.popleft()
        try:
            got = self.link.recv(timeout_s)
        except LinkError as e:
            if check_trip:
                raise self.stop("link", str(e)) from None
            raise
        if got is not None and isinstance(got[1], (m.SampleBatch, m.Sample)):
            frame, msg = got
            self._newest_wall = time.perf_counter()
            if isinstance(msg, m.SampleBatch):
                self.timing.late_segments = max(self.timing.late_segments, msg.late_segments)
                items = msg.expand(frame.time_us, self.caps.sample_period_us)
                self._newest_raw_us = items[-1][0]
                self._queued.extend((Frame(m.SAMPLE, frame.seq, t_us, b"", frame.version), x) for t_us, x in items)
                return self._queued.popleft() if not hold else got
            self._newest_raw_us = frame.time_us
            if hold and self.two_rate:
                self._queued.append(got)
                return got
        if got is not None and isinstance(got[1], m.Fault) and check_trip and self.armed:
            f = got[1]
            raise self.stop("board_fault", f"board fault {m.fault_names(f.code)} (detail {f.detail:g}); "
                                                f"latched {m.fault_names(f.faults)}")
        return got

    def _next_sample(self, sent_seq: int) -> Reading:
        start = time.perf_counter()
        deadline = start + self.watchdog_s
        retry_s = min(self.watchdog_s / 4, LOCKSTEP_RETRY_S)
        retry_at = start + retry_s if self.lockstep else math.inf
        got = None
        while got is None:
            self._raise_if_tripped()
            now = time.perf_counter()
            if now >= deadline:
                raise self.stop("link", f"no sample for {1e3 * (now - start):.1f} ms "
                                             f"(watchdog {1e3 * self.watchdog_s:.0f} ms)")
            if now >= retry_at:  # lock-step: the answer was lost; ask again (counts against the budget)
                self.timing.lockstep_retries += 1
                last = self.sent[-1]
                sent_seq = self._send_command(MotorCommand(last.mode, last.value))
                retry_at = now + retry_s
            got = self._recv(min(deadline, retry_at) - now)
            if got is not None and not isinstance(got[1], m.Sample):
                got = None
        # Every sample that arrived is checked by the envelope and recorded, in order; the
        # controller gets the newest (a free-running board kept going while the host was busy).
        reading = self._accept(*got)
        skipped = 0
        while True:
            more = self._recv(0.0)
            if more is None:
                break
            if isinstance(more[1], m.Sample):
                skipped += 1
                reading = self._accept(*more)
        self.timing.skipped_samples += skipped
        self.timing.overruns += skipped
        return self._arrived(reading)

    def _arrived(self, reading: Reading) -> Reading:
        """Book the wall-clock interval since the last sample handed on and kick the watchdog."""
        now = time.perf_counter()
        if self._last_sample_wall is not None:
            self.timing.intervals.append(now - self._last_sample_wall)
        self._last_sample_wall = now
        self.watchdog.kick()
        return reading

    def _accept(self, frame, msg: m.Sample) -> Reading:
        """Budget, continuity and envelope checks of one sample; then it is recorded."""
        lim = self.limits
        self._last_sample_seq = frame.seq
        errors = self.link.errors + self.timing.lockstep_retries
        if errors > lim.link_error_budget:
            raise self.stop("link", f"{errors} frames lost or corrupted (budget {lim.link_error_budget}): "
                                    f"{self.link.parser.stats.bad_crc} bad CRC, {self.link.stats.seq_gaps} "
                                    f"missing, {self.timing.lockstep_retries} lock-step retries")
        if self.last_sample is not None:
            missing = (msg.step - self.last_sample.step - 1) & 0xFFFF
            self.timing.samples_lost += missing
            if missing > lim.max_missed_in_row:
                raise self.stop("link", f"{missing} samples missing in a row (limit {lim.max_missed_in_row})")
        reading = self._reading(frame, msg)
        self._check(reading, msg)
        self.last_sample = msg
        if self.two_rate:
            driven = msg.status & m.ST_DRIVE_ENABLED and math.isfinite(msg.i_cmd)
            self.applied_command = MotorCommand("current", float(msg.i_cmd)) if driven else PASSIVE
            if msg.status & m.ST_SEGMENT_HOLD:
                self.timing.hold_samples += 1
        if self.on_sample is not None:
            if self.two_rate:
                applied = self.applied_command
            else:
                last = self.sent[-1]
                applied = MotorCommand(last.mode, last.value)
            self.on_sample(reading, applied)
            self._last_logged_t = reading.t
        return reading

    def _check(self, r: Reading, msg: m.Sample) -> None:
        if msg.faults and self.armed:
            raise self.stop("board_fault", f"board reports faults {m.fault_names(msg.faults)} at t={r.t:.4f} s")
        try:
            self.envelope.check(r.t, r.phi, r.psi, r.i, r.u)
        except SafetyTrip as e:
            raise self.stop(e.kind, str(e)) from None
        if r.brake != self.brake_request:
            if self._mismatch_since is None:
                self._mismatch_since = r.t
            allowed = self.caps.brake_response_ms * 1e-3 + 2 * self.dt
            if r.t - self._mismatch_since > allowed:
                raise self.stop("brake", f"brake sensed {'engaged' if r.brake else 'released'} while "
                                              f"{'engaged' if self.brake_request else 'released'} was requested "
                                              f"for {1e3 * (r.t - self._mismatch_since):.0f} ms "
                                              f"(allowed {1e3 * allowed:.0f} ms) at t={r.t:.4f} s")
        else:
            self._mismatch_since = None

    def _clock_reset(self, frame, msg: m.Sample) -> None:
        self._t0_us = self._clock(frame.time_us)
        self._last_board_us = self._t0_us
        self._psi_last = msg.psi_count
        self._psi_total = msg.psi_count

    def _reading(self, frame, msg: m.Sample, advance_psi: bool = True, update_clock: bool = True) -> Reading:
        board_us = self._clock(frame.time_us) if update_clock else self._last_board_us
        self._last_board_us = board_us
        psi_total = self._psi_total
        if self._psi_last is not None:
            psi_total += ((msg.psi_count - self._psi_last + 2**31) % 2**32) - 2**31
        if advance_psi:
            self._psi_total, self._psi_last = psi_total, msg.psi_count
        caps = self.caps
        return Reading(t=(board_us - self._t0_us) * 1e-6,
                       phi=msg.phi_count * 2 * math.pi / caps.phi_counts,
                       psi=psi_total * 2 * math.pi / caps.psi_counts,
                       u=float(msg.voltage), i=float(msg.current), brake=bool(msg.brake))
