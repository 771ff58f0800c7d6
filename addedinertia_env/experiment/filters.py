"""Causal rate estimation from quantised encoder samples.

A raw difference of a 17-bit hull encoder at 1 kHz is 0.05 rad/s per count (physics.md
section 7): far too coarse for a derivative gain. The estimator here is the slope at the
newest sample of a least-squares quadratic over a sliding window: a fixed FIR filter.
"""

from __future__ import annotations

from collections import deque

import numpy as np


def endpoint_slope_weights(n: int, dt: float) -> np.ndarray:
    """FIR weights giving the slope at the newest of ``n`` samples of a quadratic LSQ fit."""
    if n < 3:
        raise ValueError(f"rate window of {n} samples: expected at least 3")
    tau = (np.arange(n) - (n - 1)) * dt  # newest sample at 0
    V = np.vstack([np.ones(n), tau, tau**2]).T
    return np.linalg.pinv(V)[1]  # row that yields the linear coefficient = slope at tau = 0


class RateEstimator:
    """Causal rate from angle samples; returns 0 until the window has filled once."""

    def __init__(self, dt: float, window_s: float = 0.04):
        self.dt = dt
        self.n = max(3, int(round(window_s / dt)))
        self.w = endpoint_slope_weights(self.n, dt)
        self.buf: deque[float] = deque(maxlen=self.n)
        self.value = 0.0  # rad/s, estimate at the newest sample

    def reset(self) -> None:
        """Forget the samples so far (a new run); the rate reads 0 again until the window refills."""
        self.buf.clear()
        self.value = 0.0

    def update(self, angle: float) -> float:
        """Add the newest ``angle`` (rad); returns the rate estimate, rad/s.

        The slope of a quadratic least-squares fit at the newest sample once the window is
        full; before that the mean slope over the samples so far (0 with fewer than two).
        """
        self.buf.append(angle)
        n = len(self.buf)
        if n == self.n:
            self.value = float(np.dot(self.w, np.fromiter(self.buf, float, self.n)))
        elif n >= 2:
            self.value = float((self.buf[-1] - self.buf[0]) / ((n - 1) * self.dt))
        return self.value
