"""The control loop between a controller and a simulated drive: delay, command rate, quantisation.

A lab's loop is rarely the ideal 1 kHz one. :class:`ControlLoop` says how this one differs,
and :class:`LoopRig` wraps any rig (the rig protocol of :mod:`.interface`) so that the
experiment, the benchmark and the environment all see the same loop:

* ``obs_delay_s``: every reading reaches the host this late (the DAQ's transport and
  filtering). The values are ``obs_delay_s`` old; the time stamp is the arrival time, so
  the record is consistent in itself (a uniform shift of every channel) and the
  controller acts on old data.
* ``command_period_s``: the drive accepts a new current set-point this often and holds
  it in between (zero-order hold). The hold clock starts when the drive leaves passive
  mode, i.e. at the first controlled sample, so a loop that calls the controller every
  ``command_every`` samples from there (``experiment.runner.drive``) never has a command
  discarded.
* ``current_step_A``: current set-points are rounded to this quantum (a DAC's step).
* ``stated_round_trip_s``: the round trip the lab states to its controllers (s; measured as a
  lab measures it, e.g. a loopback ping; None: not stated). It changes no physics; a suite's
  ``link:`` block draws it (bench/scenario_draws.py) and the controller context carries it
  (``ControllerContext.link_round_trip_s``).

Nothing else here is known to the controller except through its control period (the context's
``dt`` is ``command_every`` samples). The wrapper passes everything else (``params``,
``true_state``, ``truth``, ``k_t``, ...) through to the wrapped rig.

The arithmetic lives in one place, :class:`LoopState`: the loops of ``n`` environments on
arrays (delay lines of readings, held set-points, the hold clock). :class:`LoopRig` is
that state with ``n = 1``; the batched experiment pool (``vector/pool.py``) runs the same
class over all its slots, so a suite's loop (hard-v0) trains on the batched engine
exactly as it runs in the single environment and on the benchmark.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Sequence

import numpy as np

from addedinertia_env.rig.signals import MotorCommand, Reading


@dataclass(frozen=True)
class ControlLoop:
    """How a loop differs from the ideal one; zeros mean ideal (see module doc)."""

    obs_delay_s: float = 0.0  # s, age of every reading the host receives
    command_period_s: float = 0.0  # s, the drive's set-point period (zero-order hold); 0: every sample
    current_step_A: float = 0.0  # A, quantum of current set-points; 0: none
    stated_round_trip_s: float | None = None  # s, the round trip stated to the controllers (None: not stated)

    def __post_init__(self) -> None:
        for name in ("obs_delay_s", "command_period_s", "current_step_A"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"ControlLoop.{name} = {value!r}: expected a finite number >= 0")
        v = self.stated_round_trip_s
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0):
            raise ValueError(f"ControlLoop.stated_round_trip_s = {v!r}: expected None or a finite number >= 0 (s)")

    @property
    def ideal(self) -> bool:
        """Whether the loop changes nothing: no observation delay, command every sample, no current quantisation."""
        return self.obs_delay_s == 0 and self.command_period_s == 0 and self.current_step_A == 0

    def delay_samples(self, dt: float) -> int:
        """Whole samples of reading delay at sample period ``dt`` (s)."""
        return int(round(self.obs_delay_s / dt))

    def command_every(self, dt: float) -> int:
        """Samples per drive set-point at sample period ``dt`` (s), at least 1."""
        return max(1, int(round(self.command_period_s / dt)))

    def to_dict(self) -> dict[str, float]:
        """The loop as ``{obs_delay_s, command_period_s (s), current_step_A (A)}`` for the ``truth`` block."""
        out = {"obs_delay_s": self.obs_delay_s, "command_period_s": self.command_period_s,
               "current_step_A": self.current_step_A}
        if self.stated_round_trip_s is not None:  # what the controllers were told, beside the truth
            out["stated_round_trip_s"] = self.stated_round_trip_s
        return out


def quantise_current(value, step_A):
    """``value`` (A) rounded to the nearest multiple of ``step_A`` (A; 0: unchanged), ties up;
    scalars or arrays (elementwise)."""
    q = np.asarray(step_A, dtype=float)
    v = np.asarray(value, dtype=float)
    out = np.where(q > 0, q * np.floor(v / np.where(q > 0, q, 1.0) + 0.5), v)
    return float(out) if out.ndim == 0 else out


class LoopState:
    """The control loops of ``n`` environments at sample period ``dt`` (s), on arrays.

    Per environment: ``delay`` (samples of reading delay), ``every`` (samples per drive
    set-point), ``step_A`` (A, set-point quantum), the held set-point and its clock, and a
    delay line of the last ``size`` readings (``phi, psi, u, i``). :meth:`command` is the
    drive's side (quantise, latch every ``every`` driven samples, hold), :meth:`arrive`
    the host's (the reading ``delay`` samples old). Environments not named in a call keep
    their state (a paused slot of the batched pool).
    """

    FIELDS = ("phi", "psi", "u", "i")

    def __init__(self, n: int, dt: float, size: int = 64):
        self.n, self.dt, self.size = int(n), float(dt), int(size)
        self.delay = np.zeros(n, dtype=np.int64)
        self.every = np.ones(n, dtype=np.int64)
        self.step_A = np.zeros(n)
        self.held = np.zeros(n)  # A or V, the set-point the drive holds
        self.holding = np.zeros(n, dtype=bool)  # False: the next driven sample latches
        self.since = np.zeros(n, dtype=np.int64)  # driven samples since the last latch
        self._ring = np.zeros((len(self.FIELDS), self.size, n))
        self._count = np.zeros(n, dtype=np.int64)  # readings pushed since reset
        self.ideal = True  # no environment delays, holds or quantises: both calls pass through

    def configure(self, envs: Sequence[int], loops: Sequence[ControlLoop | None]) -> None:
        """Environments ``envs`` get the loops ``loops`` (None: ideal); call :meth:`reset` next."""
        for k, loop in zip(envs, loops):
            loop = loop or ControlLoop()
            delay = loop.delay_samples(self.dt)
            if delay >= self.size:
                raise ValueError(f"ControlLoop.obs_delay_s = {loop.obs_delay_s} s: {delay} samples at "
                                 f"{self.dt} s; expected fewer than {self.size}")
            self.delay[k], self.every[k], self.step_A[k] = delay, loop.command_every(self.dt), loop.current_step_A
        self.ideal = not (np.any(self.delay) or np.any(self.every != 1) or np.any(self.step_A))

    def reset(self, envs, reading: Sequence[np.ndarray]) -> None:
        """Environments ``envs`` start over: no set-point held, delay line holding only ``reading``
        (its ``phi, psi, u, i`` for those environments)."""
        envs = np.asarray(envs, dtype=np.int64)
        self.holding[envs] = False
        self.since[envs] = 0
        self._count[envs] = 0
        active = np.zeros(self.n, dtype=bool)
        active[envs] = True
        full = [np.zeros(self.n) for _ in self.FIELDS]
        for f, x in zip(full, reading):
            f[envs] = x
        self.arrive(full, active)

    def command(self, value: np.ndarray, driven: np.ndarray, passive: np.ndarray, quantise: bool | np.ndarray):
        """The set-points the drives act on this sample: ``value`` (A or V per environment)
        quantised where ``quantise`` (current mode), latched where ``driven`` and the hold is
        due, held otherwise; ``passive`` environments drop their held set-point. Entries
        that are not ``driven`` come back as given."""
        if self.ideal:
            return value
        v = np.where(quantise, quantise_current(value, self.step_A), value)
        latch = driven & (~self.holding | (self.since >= self.every))
        np.copyto(self.held, v, where=latch)
        self.since[latch] = 0
        self.since += driven
        self.holding |= driven
        self.holding &= ~passive
        return np.where(driven, self.held, value)

    def arrive(self, reading: Sequence[np.ndarray], active: np.ndarray | None = None) -> list[np.ndarray]:
        """What the hosts receive now: each ``active`` environment's reading (``phi, psi, u,
        i`` arrays) pushed into its delay line, and the one taken ``delay`` samples ago (the
        first reading while fewer have come) given back; the others' entries as given."""
        if self.ideal:
            return list(reading)
        cols = np.arange(self.n) if active is None else np.nonzero(active)[0]
        pos = self._count[cols] % self.size
        for j, x in enumerate(reading):
            self._ring[j, pos, cols] = np.asarray(x)[cols]
        self._count[cols] += 1
        back = np.maximum(self._count[cols] - 1 - self.delay[cols], 0) % self.size
        out = [np.array(x, dtype=float, copy=True) for x in reading]
        for j, o in enumerate(out):
            o[cols] = self._ring[j, back, cols]
        return out


class LoopRig:
    """``rig`` seen through ``loop`` (module doc); implements the rig protocol with a
    one-environment :class:`LoopState`."""

    def __init__(self, rig: Any, loop: ControlLoop):
        self.rig = rig
        self.loop = loop
        self.source = getattr(rig, "source", "sim")
        self.state = LoopState(1, rig.dt, size=loop.delay_samples(rig.dt) + 1)
        self.state.configure([0], [loop])
        self.command_every = int(self.state.every[0])
        self._held: MotorCommand | None = None
        self._one = np.ones(1, dtype=bool)
        self._none = np.zeros(1, dtype=bool)

    def __getattr__(self, name: str) -> Any:  # params, true_state, truth, k_t, sensors, ...
        return getattr(self.__dict__["rig"], name)

    @property
    def dt(self) -> float:
        """The wrapped rig's sample period, s."""
        return self.rig.dt

    @property
    def known(self) -> Any:
        """The wrapped rig's known constants."""
        return self.rig.known

    @property
    def stated_round_trip_s(self) -> float | None:
        """The link's round trip as stated to the controllers, s (None: not stated); never the truth."""
        return self.loop.stated_round_trip_s

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True) -> Reading:
        """Reset the wrapped rig (angles in rad, ``omega0`` rad/s) and fill the delay line with its first reading; returns it."""
        r = self.rig.reset(phi0=phi0, psi0=psi0, omega0=omega0, brake=brake)
        self.state.reset([0], [np.array([getattr(r, f)]) for f in LoopState.FIELDS])
        self._held = None
        return r

    def set_brake(self, on: bool) -> None:
        """Set the wrapped rig's brake at once (the brake does not go through the loop)."""
        self.rig.set_brake(on)

    def step(self, cmd: MotorCommand) -> Reading:
        """Apply ``cmd`` as the loop does (held at the command rate, quantised) for one sample; returns the reading ``obs_delay_s`` old, stamped now."""
        return self._arrive(self.rig.step(self._applied(cmd)))

    def truth(self) -> Any:
        """The wrapped rig's ``truth`` block with the loop's settings added (``control_loop``); None on a bench."""
        truth = self.rig.truth()
        if truth is not None:
            truth = {**truth, "control_loop": self.loop.to_dict()}
        return truth

    # --- internals ------------------------------------------------------------------
    def _applied(self, cmd: MotorCommand) -> MotorCommand:
        """The set-point the drive acts on this sample (quantised, held): :meth:`LoopState.command`."""
        passive = cmd.mode == "passive"
        s = self.state
        was = bool(s.holding[0]) and int(s.since[0]) < int(s.every[0])
        value = s.command(np.array([float(cmd.value)]), self._none if passive else self._one,
                          self._one if passive else self._none, cmd.mode == "current")
        if passive:
            self._held = None
            return cmd
        if not was or self._held is None:  # latched now: the drive takes this command's mode
            self._held = cmd
        self._held = replace(self._held, value=float(value[0]))
        return self._held

    def _arrive(self, r: Reading) -> Reading:
        """The reading the host receives now: the one taken ``delay`` samples ago, stamped now."""
        phi, psi, u, i = self.state.arrive([np.array([getattr(r, f)]) for f in LoopState.FIELDS])
        return replace(r, phi=float(phi[0]), psi=float(psi[0]), u=float(u[0]), i=float(i[0]))
