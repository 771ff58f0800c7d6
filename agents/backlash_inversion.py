"""Feed-forward + PD through a gearbox with backlash: the torque keeps its sign (issue 28).

A gearbox's backlash (sim/drive.py) is a gap the rotor must cross whenever the motor's
torque changes sign; each crossing the flywheel gets no torque, and the rotor's impact on
the far flank loses the work the motor put into the crossing (``T b`` at torque ``T``):
work the current shows but the method's bookkeeping (current times the flywheel's angle)
never sees. A mirrored stroke needs a torque of one sign, so the crossings come from the
plan and from chatter. The classical answer, backlash inversion:

* **keep the sign** (pre-load): on the reverse stroke the command keeps the sign of the
  stroke's feed-forward impulse, at least ``preload`` A: the feedback can lower the torque
  but never pulls the rotor off its flank;
* **cross once, slowly**: the pre-spin's spin-up torque has the other sign, so the one
  crossing the plan needs is put at the end of the hold: over its last ``cross_s`` seconds
  the command ramps from the spin-up current to the pre-load, so the rotor crosses under
  a small torque (the impact loses little) while the hull is still braked;
* the pre-spin is :class:`~agents.drive_aware.DriveAwarePD`'s (a tuned fraction of the
  symmetric one, cut to the supply).

Everything it uses is known (``ctx.rig``, ``ctx.reference``); it never reads the hidden gap.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.base import ControllerContext, stroke_impulse
from agents.drive_aware import DriveAwarePD


class BacklashInversionPD(DriveAwarePD):
    """:class:`~agents.drive_aware.DriveAwarePD` whose torque keeps the stroke's sign (module doc)."""

    name = "backlash-inversion"
    DEFAULTS: dict[str, Any] = {**DriveAwarePD.DEFAULTS, "preload": 0.1, "cross_s": 0.3}
    KNOBS = {"prespin_fraction": (0.0, 1.2, "lin"), "preload": (0.02, 0.5, "log")}

    def reset(self, context: ControllerContext) -> None:
        """As :class:`DriveAwarePD`; then the stroke's torque sign (that of its feed-forward impulse)."""
        super().reset(context)
        self.sign = 1.0 if stroke_impulse(context, self.J) >= 0 else -1.0

    def current(self, obs: dict[str, float]) -> float:
        """The command, A: the spin-up, a slow ramp to the pre-load at the end of the hold, then
        feed-forward + PD kept at or beyond the pre-load in the stroke's sign."""
        ctx = self.ctx
        s, pre = self.sign, float(self.preload)
        if obs["is_hold"] > 0.5:
            i = self.hold_current(obs)
            left = obs["time_to_phase_end"]
            if left < float(self.cross_s):  # cross the gap once, under a small torque
                a = left / float(self.cross_s)  # 1 -> 0 over the ramp
                i = a * i + (1.0 - a) * s * pre
        elif obs["is_reverse"] > 0.5:
            e, e_rate = self.track_state(obs)
            i = self.feedforward_current(obs) + self.feedback(obs, e, e_rate)
            i = s * max(s * i, pre)
        else:
            i = 0.0
        i = float(np.clip(i, -ctx.i_max, ctx.i_max))
        self.i_prev = i
        return i
