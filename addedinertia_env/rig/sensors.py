"""What the rig's instruments report: encoder quantisation, current and voltage errors.

The current and voltage channel can lag the encoders (the hidden ``sensor_delay``
effect); the lag is applied by linear interpolation in a short history.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from . import forces
from .params import RigParams


@dataclass(frozen=True)
class Reading:
    """One sample as the data acquisition sees it (SI units)."""

    t: float
    phi: float  # rad, hull encoder
    psi: float  # rad, motor encoder (flywheel relative to hull), unwrapped
    u: float  # V, terminal voltage
    i: float  # A, motor current
    brake: bool


def quantise(x: float, counts: int) -> float:
    """Encoder reading of angle ``x`` for ``counts`` counts per turn (0: exact)."""
    if counts <= 0:
        return x
    q = 2.0 * math.pi / counts
    return math.floor(x / q + 0.5) * q


class Sensors:
    """Maps the true state to readings; owns its own random stream."""

    def __init__(self, params: RigParams, rng: np.random.Generator):
        self.p = params
        self.rng = rng
        self.delay_samples = forces.channel_delay(params) * params.sensors.sample_rate  # hidden lag, samples
        self._history: deque[tuple[float, float]] = deque(maxlen=int(math.ceil(self.delay_samples)) + 2)

    def reset(self) -> None:
        self._history.clear()

    def read(self, t: float, phi: float, psi: float, u: float, i: float, brake: bool) -> Reading:
        s = self.p.sensors
        self._history.append((u, i))
        u_lag, i_lag = self._delayed()
        i_meas = (1.0 + s.current_gain_error) * i_lag + s.current_offset + s.current_noise * self.rng.standard_normal()
        u_meas = (1.0 + s.voltage_gain_error) * u_lag + s.voltage_offset + s.voltage_noise * self.rng.standard_normal()
        return Reading(t=t, phi=quantise(phi, s.phi_counts), psi=quantise(psi, s.psi_counts),
                       u=u_meas, i=i_meas, brake=brake)

    def _delayed(self) -> tuple[float, float]:
        h = self._history
        if self.delay_samples == 0.0 or len(h) == 1:
            return h[-1]
        back = min(self.delay_samples, len(h) - 1)
        k = int(math.floor(back))
        frac = back - k
        newer, older = h[-1 - k], h[-1 - min(k + 1, len(h) - 1)]
        return (newer[0] * (1 - frac) + older[0] * frac, newer[1] * (1 - frac) + older[1] * frac)
