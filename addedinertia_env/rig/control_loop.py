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

Nothing here is known to the controller except through its control period (the context's
``dt`` is ``command_every`` samples). The wrapper passes everything else (``params``,
``true_state``, ``truth``, ``k_t``, ...) through to the wrapped rig.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

from .motor import MotorCommand
from .sensors import Reading


@dataclass(frozen=True)
class ControlLoop:
    """How a loop differs from the ideal one; zeros mean ideal (see module doc)."""

    obs_delay_s: float = 0.0  # s, age of every reading the host receives
    command_period_s: float = 0.0  # s, the drive's set-point period (zero-order hold); 0: every sample
    current_step_A: float = 0.0  # A, quantum of current set-points; 0: none

    def __post_init__(self) -> None:
        for name in ("obs_delay_s", "command_period_s", "current_step_A"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"ControlLoop.{name} = {value!r}: expected a finite number >= 0")

    @property
    def ideal(self) -> bool:
        return self.obs_delay_s == 0 and self.command_period_s == 0 and self.current_step_A == 0

    def delay_samples(self, dt: float) -> int:
        """Whole samples of reading delay at sample period ``dt`` (s)."""
        return int(round(self.obs_delay_s / dt))

    def command_every(self, dt: float) -> int:
        """Samples per drive set-point at sample period ``dt`` (s), at least 1."""
        return max(1, int(round(self.command_period_s / dt)))

    def to_dict(self) -> dict[str, float]:
        return {"obs_delay_s": self.obs_delay_s, "command_period_s": self.command_period_s,
                "current_step_A": self.current_step_A}


class LoopRig:
    """``rig`` seen through ``loop`` (module doc); implements the rig protocol."""

    def __init__(self, rig: Any, loop: ControlLoop):
        self.rig = rig
        self.loop = loop
        self.source = getattr(rig, "source", "sim")
        self._delay = loop.delay_samples(rig.dt)
        self.command_every = loop.command_every(rig.dt)
        self._queue: deque[Reading] = deque(maxlen=self._delay + 1)
        self._held: MotorCommand | None = None
        self._since_latch = 0

    def __getattr__(self, name: str) -> Any:  # params, true_state, truth, k_t, sensors, ...
        return getattr(self.__dict__["rig"], name)

    @property
    def dt(self) -> float:
        return self.rig.dt

    @property
    def known(self) -> Any:
        return self.rig.known

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True) -> Reading:
        r = self.rig.reset(phi0=phi0, psi0=psi0, omega0=omega0, brake=brake)
        self._queue.clear()
        self._held = None
        self._since_latch = 0
        return self._arrive(r)

    def set_brake(self, on: bool) -> None:
        self.rig.set_brake(on)

    def step(self, cmd: MotorCommand) -> Reading:
        return self._arrive(self.rig.step(self._applied(cmd)))

    def truth(self) -> Any:
        truth = self.rig.truth()
        if truth is not None:
            truth = {**truth, "control_loop": self.loop.to_dict()}
        return truth

    # --- internals ------------------------------------------------------------------
    def _applied(self, cmd: MotorCommand) -> MotorCommand:
        """The set-point the drive acts on this sample (quantised, held)."""
        if cmd.mode == "passive":
            self._held = None
            return cmd
        if cmd.mode == "current" and self.loop.current_step_A > 0:
            q = self.loop.current_step_A
            cmd = replace(cmd, value=q * math.floor(cmd.value / q + 0.5))
        if self._held is None or self._since_latch >= self.command_every:
            self._held, self._since_latch = cmd, 0
        self._since_latch += 1
        return self._held

    def _arrive(self, r: Reading) -> Reading:
        """The reading the host receives now: the one taken ``delay`` samples ago, stamped now."""
        self._queue.append(r)
        old = self._queue[0]
        return old if old is r else replace(old, t=r.t, brake=r.brake)
