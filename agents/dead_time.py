"""A dead-time compensator for the hull observer: the Smith predictor's model branch (Smith 1957).

Behind a link whose readings reach the host ``n`` samples late, a loop that feeds back the
reading feeds back the hull as it was ``n`` samples ago; its phase lag ``omega n dt`` at the
crossover is what limits the loop (Astrom & Hagglund, *Advanced PID Control*, ISA 2006,
section 7.x "Dead-time compensation": the Smith predictor). The compensator keeps the
commands it has sent and the model of the plant, and feeds back the model's prediction of the
state *now*::

    x(k - n)  from the observer on the delayed readings (its model advanced with the command
              that was applied then, corrected with the reading that arrives now)
    x(k)      = x(k - n) advanced through the model with the n commands sent since

With an exact model and no noise the prediction equals the undelayed state (tests/test_smith_pd.py
checks it against an independent simulation of the delayed plant). The model is the observer's
(:class:`~agents.observer.HullObserver`: ``J phi'' = -c phi - k_t i + d_expected + d`` with the
inertia prior, the rod's known stiffness, the known torque constant and the residual torque
``d`` held over the round trip). Where the model errs (the hull's damping, the inertia prior),
the correction with each delayed reading pulls the estimate back: the mismatch enters the loop
like a disturbance seen ``n`` samples late, not as a phase lag of the whole loop.

Commands sent while the hull is braked move no hull: they enter the queue as ``None`` and the
model holds the hull there (the brake holds it at rest).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from agents.observer import HullObserver


class DeadTimePredictor:
    """The hull's state ``[phi, w, d]`` now, from readings ``delay_samples`` late (module doc)."""

    def __init__(self, observer: HullObserver, delay_samples: int):
        if isinstance(delay_samples, bool) or not isinstance(delay_samples, (int, np.integer)) or delay_samples < 0:
            raise ValueError(f"DeadTimePredictor: delay_samples = {delay_samples!r}; expected a whole number >= 0")
        self.observer = observer
        self.n = int(delay_samples)
        self.queue: deque = deque()
        self.x = np.zeros(3)

    def start(self, phi: float) -> np.ndarray:
        """Start on the first reading ``phi`` (rad) of a hull braked at rest until now: the last ``n`` commands
        moved no hull. Returns the state now."""
        self.observer.start(phi, 0.0, 0.0)
        self.queue = deque([None] * self.n)
        self.x = self.observer.x.copy()
        return self.x

    def update(self, current: float | None, d_expected: float, phi_delayed: float) -> np.ndarray:
        """One sample: ``current`` (A; None: the hull was braked) and ``d_expected`` (N m) are what was applied
        over the last sample, ``phi_delayed`` (rad) the reading that arrived now (the hull ``n`` samples ago).
        Returns the state now, ``[phi (rad), w (rad/s), d (N m)]``."""
        self.queue.append(None if current is None else (float(current), float(d_expected)))
        applied = self.queue.popleft()  # the command that acted over the sample before the arriving reading
        if applied is not None:
            self.observer.predict(*applied)
        self.observer.correct(phi_delayed)
        x = self.observer.x.copy()
        A, B, k_t = self.observer.A, self.observer.B, self.observer.k_t
        for entry in self.queue:  # the n commands sent since that reading was taken
            if entry is not None:
                x = A @ x + B * (-k_t * entry[0] + entry[1])
        self.x = x
        return x
