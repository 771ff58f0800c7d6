"""The bench board's inner loop (protocol version 2, two rates): written once, used everywhere.

The host acts at the policy rate (for example 100 Hz) and sends *segments*; the board
runs this loop at every sample (1 kHz) on the newest valid segment. The same code runs

* in the bench emulator's board (``hw_adapter/board.py``),
* in the simulator's two-rate rig (:class:`TwoRateSimRig`, what a policy trained or
  benchmarked at a lower rate drives), and
* as the reference a firmware engineer ports: ``firmware/board_loop.c`` is the C
  version, held equal to this one by ``tests/test_board_loop.py``.

All times are board-clock microseconds (integers; on the wire u32 that wrap every
71.6 min, so every comparison below uses the wrap-safe difference :func:`elapsed_us`).

A segment (docs/PROTOCOL.md section 9) says, for board times ``t0 .. t_end``:

* ``currents``: feed-forward current knots, A, ``knot_us`` apart from ``t0``;
  piecewise-linear between knots, the last knot held up to ``t_end``. One knot is a
  zero-order hold (board mode ``zoh``).
* ``phi_refs`` (board mode ``pd`` only): hull-angle reference knots, rad, on the same
  grid; with gains ``kp`` (A/rad) and ``kd`` (A/(rad/s)) the board adds
  ``kp (phi_ref - phi) + kd (phi_ref' - w)`` where ``phi_ref'`` is the slope of the
  current piece and ``w`` the board's own rate estimate. The PD acts only while the
  brake is released (a braked hull cannot follow, and the hold must not draw current).
* ``brake`` (the request at ``t0``) and ``brake_switch_us`` (if not ``None``: the board
  time from which the request is the opposite), so a brake event lands on its sample
  whatever the host's latency.
* ``deadline_us``: a segment that reaches the board after its deadline is *late*: it is
  counted and dropped; the board keeps the segment it has.
* ``end_passive``: at ``t_end`` the drive goes passive on purpose (the last planned
  segment of a stroke), instead of holding; ``passive``: the drive is passive (terminals
  open) for the whole segment, only the brake schedule matters (the experiment's
  uncontrolled phases).

Step by step, at each sample instant ``now`` with the measured hull angle ``phi``:

1. Rate estimate (alpha-beta filter, fading memory ``theta = exp(-2 pi f_c dt)``,
   ``alpha = 1 - theta^2``, ``beta = (1 - theta)^2``)::

       phi_pred = phi_hat + dt w_hat;  r = phi - phi_pred
       phi_hat = phi_pred + alpha r;   w_hat = w_hat + (beta / dt) r

   (first sample after :meth:`BoardLoop.restart`: ``phi_hat = phi``, ``w_hat = 0``).
2. No segment yet: passive, brake requested (the safe state's command).
3. ``s = elapsed_us(now, t0)``; before ``t0`` (``s < 0``) use ``s = 0``.
4. Past ``t_end`` (``elapsed_us(now, t_end) > 0``): a segment that ends in the safe
   state's command (passive, brake requested) just keeps it: nothing to stop. Otherwise,
   once ``elapsed_us(now, t_end) > grace_us``: *starved*: passive, brake requested, and the board goes to the safe state
   by itself (fault SEGMENTS). Within the grace: with ``end_passive`` (or ``passive``):
   passive, brake as the segment leaves it; otherwise *hold*: evaluate at ``t_end`` and
   set the HOLD status.
5. Knot interval ``k = min(s // knot_us, n - 2)``, fraction ``f = (s - k knot_us) / knot_us``
   (one knot: the constant). ``i_ff = c[k] + f (c[k+1] - c[k])``, same for ``phi_ref``,
   ``rate_ref = (p[k+1] - p[k]) / (knot_us 1e-6)`` (0 beyond the last knot).
6. Brake request: ``brake`` before ``brake_switch_us``, ``not brake`` from it on.
7. PD (pd mode, brake released): ``i = i_ff + kp (phi_ref - phi) + kd (rate_ref - w_hat)``.
8. Clamp ``|i| <= i_max``; the drive is in current mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from addedinertia_env.rig.signals import MotorCommand, Reading

BOARD_MODES = ("zoh", "pd")  # what the board does between the host's actions
MAX_KNOTS = 8  # knots per segment (the wire format's limit)
DEFAULT_GRACE_US = 20_000  # us the board holds a segment that ran out, then safe state
DEFAULT_RATE_FILTER_HZ = 40.0  # Hz, corner of the board's alpha-beta rate estimate
HORIZON_PERIODS = 3  # a segment lasts this many host periods: due within one, the others are margin
PASSIVE = MotorCommand("passive", 0.0)


def elapsed_us(now_us: int, then_us: int) -> int:
    """``now - then`` in us on a u32 clock that wraps (signed, valid within +-35 min)."""
    return ((int(now_us) - int(then_us) + 2**31) % 2**32) - 2**31


@dataclass(frozen=True)
class Segment:
    """One host action: what the board does from ``t0_us`` to ``t0_us + duration_us``."""

    seg_id: int  # u16, +1 per segment sent
    t0_us: int  # board time of knot 0, us
    duration_us: int  # us, the segment runs out at t0 + duration
    deadline_us: int  # board time after which the segment is late (dropped), us
    knot_us: int  # us between knots (> 0)
    currents: tuple[float, ...]  # A, feed-forward knots (1..MAX_KNOTS)
    phi_refs: tuple[float, ...] | None = None  # rad, pd mode: reference knots, as many as currents
    kp: float = 0.0  # A/rad, pd mode
    kd: float = 0.0  # A/(rad/s), pd mode
    brake: bool = True  # brake request at t0
    brake_switch_us: int | None = None  # board time from which the request is ``not brake``
    end_passive: bool = False  # passive (not hold) after the end
    passive: bool = False  # drive passive (terminals open) for the whole segment; currents ignored

    def __post_init__(self) -> None:
        n = len(self.currents)
        if not 1 <= n <= MAX_KNOTS:
            raise ValueError(f"segment with {n} knots: expected 1..{MAX_KNOTS}")
        if self.phi_refs is not None and len(self.phi_refs) != n:
            raise ValueError(f"segment with {n} current knots and {len(self.phi_refs)} reference knots")
        if self.knot_us <= 0 or self.duration_us <= 0:
            raise ValueError(f"segment knot spacing {self.knot_us} us, duration {self.duration_us} us: expected > 0")
        values = (*self.currents, *(self.phi_refs or ()), self.kp, self.kd)
        if not all(math.isfinite(v) for v in values):
            raise ValueError("segment with a non-finite knot or gain")

    @property
    def mode(self) -> str:
        """``pd`` when the segment carries reference knots (the board closes a PD loop), else ``zoh`` (held current)."""
        return "pd" if self.phi_refs is not None else "zoh"

    @property
    def end_us(self) -> int:
        """Board time (u32, us, wraps) at which the segment runs out."""
        return (self.t0_us + self.duration_us) % 2**32


@dataclass
class LoopOutput:
    """What the loop decided for one sample period."""

    command: MotorCommand
    brake: bool  # brake request
    hold: bool = False  # the segment ran out; holding within the grace
    starved: bool = False  # the grace ran out too: go to the safe state
    seg_id: int = 0


@dataclass
class BoardLoop:
    """State of the inner loop; see the module docstring for the arithmetic."""

    dt_us: int  # us, the sample period
    i_max: float  # A, the drive's current limit
    grace_us: int = DEFAULT_GRACE_US
    rate_filter_hz: float = DEFAULT_RATE_FILTER_HZ
    segment: Segment | None = None
    late_segments: int = 0  # segments that arrived after their deadline (dropped)
    accepted_segments: int = 0
    phi_hat: float = 0.0
    w_hat: float = 0.0
    _started: bool = field(default=False, repr=False)

    def __post_init__(self) -> None:
        theta = math.exp(-2.0 * math.pi * self.rate_filter_hz * self.dt_us * 1e-6)
        self.alpha = 1.0 - theta * theta
        self.beta = (1.0 - theta) ** 2

    def restart(self) -> None:
        """After RESET or ARM: no segment, rate estimate restarts at the next sample."""
        self.segment = None
        self._started = False

    def offer(self, seg: Segment, now_us: int) -> bool:
        """A segment arrived at board time ``now_us``: keep it, or count it late and drop it."""
        if elapsed_us(now_us, seg.deadline_us) > 0:
            self.late_segments += 1
            return False
        if self.segment is not None and elapsed_us(seg.t0_us, self.segment.t0_us) < 0:
            self.late_segments += 1  # older than the one in force (reordered): also dropped
            return False
        self.segment = seg
        self.accepted_segments += 1
        return True

    def update_rate(self, phi: float) -> None:
        """Step 1: the alpha-beta rate estimate from the hull encoder, rad/s."""
        dt = self.dt_us * 1e-6
        if not self._started:
            self.phi_hat, self.w_hat, self._started = float(phi), 0.0, True
            return
        pred = self.phi_hat + dt * self.w_hat
        r = float(phi) - pred
        self.phi_hat = pred + self.alpha * r
        self.w_hat = self.w_hat + (self.beta / dt) * r

    def command(self, now_us: int, phi: float) -> LoopOutput:
        """Steps 1-8: the drive command and brake request for the period starting at ``now_us``."""
        self.update_rate(phi)
        seg = self.segment
        if seg is None:
            return LoopOutput(PASSIVE, True)
        s = max(0, elapsed_us(now_us, seg.t0_us))
        over = elapsed_us(now_us, seg.end_us)
        hold = False
        if over > 0:
            ends_safe = (seg.end_passive or seg.passive) and self._brake_at(seg, now_us)
            if ends_safe:  # already the safe state's command: nothing to stop (PROTOCOL.md 5.2)
                return LoopOutput(PASSIVE, True, seg_id=seg.seg_id)
            if over > self.grace_us:
                return LoopOutput(PASSIVE, True, hold=True, starved=True, seg_id=seg.seg_id)
            if seg.end_passive or seg.passive:
                return LoopOutput(PASSIVE, self._brake_at(seg, now_us), seg_id=seg.seg_id)
            hold = True
            s = seg.duration_us
        brake = self._brake_at(seg, now_us)
        if seg.passive:
            return LoopOutput(PASSIVE, brake, seg_id=seg.seg_id)
        i_ff, phi_ref, rate_ref = self._profile(seg, s)
        i = i_ff
        if seg.phi_refs is not None and not brake:
            i += seg.kp * (phi_ref - float(phi)) + seg.kd * (rate_ref - self.w_hat)
        i = min(self.i_max, max(-self.i_max, i))
        return LoopOutput(MotorCommand("current", i), brake, hold=hold, seg_id=seg.seg_id)

    @staticmethod
    def _profile(seg: Segment, s: int) -> tuple[float, float, float]:
        """Step 5: feed-forward, reference and reference rate ``s`` us after t0."""
        c, p = seg.currents, seg.phi_refs
        n = len(c)
        if n == 1:
            return c[0], (p[0] if p is not None else 0.0), 0.0
        k = min(s // seg.knot_us, n - 2)
        f = (s - k * seg.knot_us) / seg.knot_us
        if f > 1.0:  # past the last knot: held
            f, rate = 1.0, 0.0
        else:
            rate = (p[k + 1] - p[k]) / (seg.knot_us * 1e-6) if p is not None else 0.0
        i_ff = c[k] + f * (c[k + 1] - c[k])
        phi_ref = p[k] + f * (p[k + 1] - p[k]) if p is not None else 0.0
        return i_ff, phi_ref, rate

    @staticmethod
    def _brake_at(seg: Segment, now_us: int) -> bool:
        """Step 6."""
        if seg.brake_switch_us is not None and elapsed_us(now_us, seg.brake_switch_us) >= 0:
            return not seg.brake
        return seg.brake


def zoh_segment(seg_id: int, cmd: MotorCommand, brake: bool, t0_us: int, host_period_us: int,
                brake_switch_us: int | None = None) -> Segment:
    """``cmd`` held (current or passive mode) from ``t0_us``: due within one host period,
    lasting :data:`HORIZON_PERIODS` (margin for a late host before the grace starts)."""
    if cmd.mode not in ("current", "passive"):
        raise ValueError(f"two-rate board: drive mode {cmd.mode!r}; expected current or passive")
    return Segment(seg_id, t0_us % 2**32, HORIZON_PERIODS * host_period_us, (t0_us + host_period_us) % 2**32, host_period_us,
                   (float(cmd.value) if cmd.mode == "current" else 0.0,), brake=brake,
                   brake_switch_us=brake_switch_us, passive=cmd.mode == "passive")


class TwoRateSimRig:
    """A simulated rig seen through the board's inner loop: the simulator's two-rate bench.

    Implements the rig protocol like :class:`~hw_adapter.bench_rig.BenchRig` in two-rate
    mode: ``send_segment`` hands a segment to the loop (on time: no link here),
    ``step(None)`` runs one sample under the loop, and ``step(cmd)`` (the experiment's
    uncontrolled phases) sends ``cmd`` as a zero-order-hold segment once per host period.
    ``set_brake`` sends the last such command again with the new brake request, at once
    (a planned segment carries its own brake schedule).
    """

    def __init__(self, rig: Any, host_rate_hz: float, grace_us: int = DEFAULT_GRACE_US,
                 rate_filter_hz: float = DEFAULT_RATE_FILTER_HZ, latency_samples: int = 0):
        self.rig = rig
        self.latency_samples = int(latency_samples)  # samples a segment takes to reach the board (a bench's link)
        self._in_flight: list[Segment] = []
        self.source = getattr(rig, "source", "sim")
        self.dt_us = int(round(rig.dt * 1e6))
        self.host_period_us = int(round(1e6 / host_rate_hz))
        self.loop = BoardLoop(self.dt_us, rig.known.current_limit, grace_us, rate_filter_hz)
        self.brake_request = True
        self.last: Reading | None = None
        self.applied_command = PASSIVE  # the command the loop applied over the last period
        self.starved = False
        self._seg_id = 0
        self._zoh: tuple[MotorCommand, bool] | None = None
        self._zoh_t0 = 0

    # rig protocol ---------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """The sample period of the simulated rig, s."""
        return self.rig.dt

    @property
    def known(self):
        """The simulated rig's known constants (its ``rig`` block, typed)."""
        return self.rig.known

    def truth(self):
        """The simulated rig's ``truth`` block (scoring only)."""
        return self.rig.truth()

    @property
    def stated_round_trip_s(self) -> float | None:
        """The link's round trip the wrapped rig states to the controllers, s (a
        :class:`~addedinertia_env.loop.control_loop.LoopRig`'s; None: not stated); never the truth."""
        value = getattr(self.rig, "stated_round_trip_s", None)
        return float(value) if value is not None else None

    @property
    def now_us(self) -> int:
        """Board time of the newest sample, us (0 before the first)."""
        return int(round(self.last.t * 1e6)) if self.last is not None else 0

    def board_time_us(self, t: float) -> int:
        """Board clock (us) of record time ``t`` (s after RESET)."""
        return int(round(t * 1e6))

    @property
    def host_rate_hz(self) -> float:
        """The host's rate, Hz (one zero-order-hold segment per host period)."""
        return 1e6 / self.host_period_us

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True) -> Reading:
        """Reset the simulated rig (angles in rad, ``omega0`` in rad/s) and restart the board loop with no segment; returns the first reading."""
        self.last = self.rig.reset(phi0=phi0, psi0=psi0, omega0=omega0, brake=brake)
        self.brake_request = brake
        self.loop.restart()
        self._zoh = None
        return self.last

    def set_brake(self, on: bool) -> None:
        """Sent at once while zero-order-hold segments run; a planned segment schedules its own brake."""
        self.brake_request = bool(on)
        if self._zoh is not None:
            self._send_zoh(self._zoh[0])

    def step(self, cmd: MotorCommand | None) -> Reading:
        """Run one sample under the board loop and return its reading.

        ``cmd`` (uncontrolled phases) is sent as a zero-order-hold segment when it changes or a
        host period has passed; segments in flight arrive after ``latency_samples``; the loop's
        command (and brake) drive the rig; a starved loop sets :attr:`starved`.
        """
        if cmd is not None and (self._zoh != (cmd, self.brake_request)
                                or elapsed_us(self.now_us, self._zoh_t0) >= self.host_period_us):
            self._send_zoh(cmd)
        while self._in_flight and elapsed_us(self.now_us, self._in_flight[0].t0_us) >= \
                self.latency_samples * self.dt_us:
            self.loop.offer(self._in_flight.pop(0), self.now_us)
        out = self.loop.command(self.now_us, self.last.phi)
        if out.starved:
            self.starved = True
        if out.brake != self.rig.brake:
            self.rig.set_brake(out.brake)
        self.applied_command = out.command
        self.last = self.rig.step(out.command)
        return self.last

    # two-rate ---------------------------------------------------------------------------
    def next_seg_id(self) -> int:
        """The next segment id (u16, wraps)."""
        self._seg_id = (self._seg_id + 1) & 0xFFFF
        return self._seg_id

    def send_segment(self, seg: Segment) -> None:
        """Hand ``seg`` to the board loop (after ``latency_samples`` if set); a held zero-order-hold command is forgotten."""
        self._zoh = None
        self._deliver(seg)

    def _deliver(self, seg: Segment) -> None:
        if self.latency_samples:
            self._in_flight.append(seg)
        else:
            self.loop.offer(seg, self.now_us)

    def poll(self) -> int:
        """Samples waiting to be read (none: the simulator is in step with the host)."""
        return 0

    def _send_zoh(self, cmd: MotorCommand) -> None:
        t0 = self.now_us
        seg = zoh_segment(self.next_seg_id(), cmd, self.brake_request, t0, self.host_period_us)
        self._deliver(seg)
        self._zoh, self._zoh_t0 = (cmd, self.brake_request), t0
