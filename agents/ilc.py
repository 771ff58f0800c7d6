"""Iterative learning control: the feedforward-PD loop plus a correction learned over cycles.

The reverse stroke of one scenario is repeated (the patent averages ``n`` cycles). Each
cycle, the feedback current the loop had to add is recorded against the stroke's
progress ``s = (t - t_begin) / duration`` in ``bins`` bins. When the next cycle starts
(``reset(context)``), that feedback is folded into the learned feedforward::

    u_{k+1}(s) = u_k(s) + learning_gain * Q[ feedback_k(s) ]

where ``Q`` is a zero-phase moving average over ``smooth_bins`` bins (the usual ILC
"Q-filter", for robustness to noise). The loop then needs less feedback on the next
cycle, so less encoder noise reaches the motor. The correction is kept on the controller
object between episodes of the same scenario; a new controller starts from zero. In the
benchmark ILC runs ``cycles`` episodes per scenario and the last one is scored
(docs/CONTROLLERS.md). The pre-spin does not change with learning.

Knobs (tuning: addedinertia_env/bench/tuning.py): the PD's ``omega_c`` and ``zeta``, ``learning_gain``,
``smooth_bins``, ``observer_bandwidth``.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

from agents.feedforward_pd import FeedforwardPD


class ILC(FeedforwardPD):
    """Feedforward-PD plus a feed-forward correction learned from the feedback of earlier cycles.

    Knobs beyond :class:`FeedforwardPD`'s: ``learning_gain`` (fraction of the last cycle's
    feedback folded in), ``smooth_bins`` (width of the Q-filter, bins) and ``bins`` (bins
    over the stroke's progress). :attr:`BENCH_CYCLES` episodes per benchmark scenario.
    """

    name = "ilc"
    DEFAULTS = {**FeedforwardPD.DEFAULTS, "learning_gain": 0.8, "smooth_bins": 9, "bins": 400}
    KNOBS = {"omega_c": (3.0, 40.0, "log"), "zeta": (0.5, 2.0, "lin"), "learning_gain": (0.2, 1.0, "lin"),
             "smooth_bins": (1.0, 40.0, "log"), "observer_bandwidth": (2.0, 80.0, "log")}
    BENCH_CYCLES = 3  # episodes per scenario in the benchmark; the last one is scored

    def __init__(self, tuned: bool = True, **overrides):
        super().__init__(tuned=tuned, **overrides)
        self.bins = int(self.bins)
        self.learned = np.zeros(self.bins)  # A, learned feedforward over the stroke's progress
        self._sum = np.zeros(self.bins)
        self._count = np.zeros(self.bins)
        self.cycles_seen = 0

    def reset(self, context) -> None:
        """Start a cycle: fold the last cycle's mean feedback per bin (smoothed, times ``learning_gain``) into the learned current, then reset as :class:`FeedforwardPD` does."""
        if self._count.any():  # a cycle ended: learn from it
            fb = np.divide(self._sum, self._count, out=np.zeros(self.bins), where=self._count > 0)
            width = max(1, int(round(self.smooth_bins)))
            self.learned = self.learned + self.learning_gain * uniform_filter1d(fb, width, mode="nearest")
            self.cycles_seen += 1
        self._sum[:] = 0.0
        self._count[:] = 0.0
        super().reset(context)

    def _bin(self, obs: dict[str, float]) -> int:
        return min(self.bins - 1, int(obs["phase_progress"] * self.bins))

    def feedforward_current(self, obs: dict[str, float]) -> float:
        """Feed-forward current, A: the recorded law's plus the learned correction at this point of the stroke."""
        return super().feedforward_current(obs) + float(self.learned[self._bin(obs)])

    def feedback(self, obs: dict[str, float], e: float, e_rate: float) -> float:
        """PD feedback, A, as :class:`FeedforwardPD`'s; also recorded per bin of the stroke's progress for the next cycle."""
        fb = super().feedback(obs, e, e_rate)
        k = self._bin(obs)
        self._sum[k] += fb
        self._count[k] += 1.0
        return fb
