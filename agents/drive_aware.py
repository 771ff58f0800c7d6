"""Feed-forward + PD with a pre-spin planned for the drive (issue 28): the classical answer to a
geared, supply-limited drive.

Through a gearbox the mesh loses ``(1 - efficiency) |torque|`` plus a drag against the
flywheel's motion (sim/drive.py), work the current shows but the flywheel never gets, so
the energy method's bookkeeping is off by a loss that depends on how fast the flywheel
turns while the current flows. The plan decides that: with no pre-spin the flywheel turns
one way through the whole stroke (the loss acts like a torque-scale error), with the full
pre-spin of :class:`~agents.feedforward_pd.FeedforwardPD` it reverses mid-stroke (the loss
changes sign against the current). Measured on wigley-2m (docs/DRIVE.md) the two biases
have opposite signs, so a pre-spin between them cancels most of it:

* ``prespin_fraction`` (-): the pre-spin as a fraction of the symmetric one (1: the
  flywheel ends the stroke at minus its start rate; 0: none), tuned on the suite's tuning
  split like every knob;
* supply-aware: the pre-spin is cut so that the back-EMF at the fastest flywheel rate of
  the plan, ``k_t |Omega|``, plus ``R`` times the current limit stays within
  :attr:`headroom` of the stated supply ``u_max`` (the drive then never runs out of
  voltage, which would stall the current loop where the stroke needs it most).

Everything it uses is known (``ctx.rig``: ``k_t`` at the flywheel with the gear ratio,
``R``, ``u_max``, ``J_flywheel``); it never reads the hidden efficiency or drag.
"""

from __future__ import annotations

from typing import Any

from agents.base import ControllerContext, stroke_impulse
from agents.feedforward_pd import FeedforwardPD


class DriveAwarePD(FeedforwardPD):
    """:class:`~agents.feedforward_pd.FeedforwardPD` with the pre-spin planned for the drive (module doc)."""

    name = "drive-aware"
    DEFAULTS: dict[str, Any] = {**FeedforwardPD.DEFAULTS, "prespin_fraction": 0.5, "headroom": 0.9}
    KNOBS = {"prespin_fraction": (0.0, 1.2, "lin")}  # the plan; the loop keeps feedforward-pd's default gains

    def reset(self, context: ControllerContext) -> None:
        """As :class:`FeedforwardPD`, then the pre-spin scaled by ``prespin_fraction`` and cut to the supply."""
        super().reset(context)
        rig = context.rig
        impulse = stroke_impulse(context, self.J)
        swing = impulse / rig.J_flywheel  # rad/s: the stroke's change of the flywheel rate
        start = -float(self.prespin_fraction) * swing / 2.0
        if rig.u_max is not None:
            i_lim = min(context.i_max, rig.current_limit)
            room = (float(self.headroom) * rig.u_max - rig.R * i_lim) / context.k_t  # rad/s the supply allows
            if room > 0:  # keep both ends of the stroke's flywheel rates within it
                hi, lo = max(start, start + swing), min(start, start + swing)
                if hi > room:
                    start -= hi - room
                if lo < -room:
                    start += -room - lo
        self.omega_start = start
        self.prespin = True
