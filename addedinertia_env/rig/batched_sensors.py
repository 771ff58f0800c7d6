"""The rig's instruments for a batch of environments (vectorised :mod:`.sensors`).

Same readings as :class:`~addedinertia_env.rig.sensors.Sensors`, element by element:
encoder quantisation (``floor(x / q + 0.5) q``), current and voltage gain, offset and
noise, and the hidden current/voltage channel delay (linear interpolation in a short
per-environment history, here a ring buffer).

Noise comes either from one :class:`numpy.random.Generator` for the whole batch (fast:
one draw of ``n`` normals per channel and sample) or from one Generator per environment
(a Python loop, for small batches that must reproduce a given single rig's noise). With
one environment both give exactly the stream of a :class:`Sensors` with the same seed:
current noise first, then voltage noise, at every reading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from . import forces
from .batched_params import BatchedParams
from .sensors import Reading


@dataclass
class BatchedReading:
    """One sample of every environment (or of a subset), as arrays (SI units)."""

    t: np.ndarray  # s
    phi: np.ndarray  # rad, hull encoder
    psi: np.ndarray  # rad, motor encoder
    u: np.ndarray  # V
    i: np.ndarray  # A
    brake: np.ndarray  # bool

    def single(self, k: int = 0) -> Reading:
        """Environment ``k`` as a :class:`Reading` of plain floats."""
        return Reading(t=float(self.t[k]), phi=float(self.phi[k]), psi=float(self.psi[k]), u=float(self.u[k]),
                       i=float(self.i[k]), brake=bool(self.brake[k]))


def quantise_array(x: np.ndarray, counts: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Encoder reading of angles ``x`` (rad) for ``counts`` counts per turn (0: exact)."""
    q = 2.0 * math.pi / np.where(counts > 0, counts, 1)
    y = np.floor(x / q + 0.5) * q
    if np.all(counts > 0):
        return y.astype(x.dtype, copy=False)
    return np.where(counts > 0, y, x).astype(x.dtype, copy=False)


class BatchedSensors:
    """Maps the true state of a batch to readings."""

    def __init__(self, params: BatchedParams, rng: np.random.Generator | Sequence[np.random.Generator]):
        self.p = params
        n = params.n
        if isinstance(rng, np.random.Generator):
            self.rng, self.rngs = rng, None
        else:
            self.rng, self.rngs = None, list(rng)
            if len(self.rngs) != n:
                raise ValueError(f"BatchedSensors: {len(self.rngs)} generators for {n} environments; "
                                 "give one per environment or a single Generator")
        self.delay_samples = (params.per_env(forces.channel_delay(params)).astype(float) * params.sample_rate
                              if forces.has_channel_delay(params) else None)  # hidden lag, samples
        if self.delay_samples is not None:
            size = int(math.ceil(float(np.max(self.delay_samples)))) + 2
            self._hist = np.zeros((2, size, n))  # (u, i) x ring position x env
            self._pos = np.zeros(n, dtype=np.int64)  # next write position
            self._count = np.zeros(n, dtype=np.int64)  # entries held (<= size)
        s = params.sensors
        self._i_gain = 1.0 + s.current_gain_error
        self._u_gain = 1.0 + s.voltage_gain_error

    def reset(self, envs: np.ndarray | None = None) -> None:
        if self.delay_samples is not None:
            sel = slice(None) if envs is None else envs
            self._count[sel] = 0
            self._pos[sel] = 0

    def rngs_or_rng(self, k: int) -> np.random.Generator:
        """The Generator that draws environment ``k``'s noise."""
        return self.rng if self.rngs is None else self.rngs[k]

    def history(self, k: int) -> list[tuple[float, float]]:
        """Environment ``k``'s delay line, oldest first: ``[(u, i), ...]`` (empty without delay)."""
        if self.delay_samples is None:
            return []
        size = self._hist.shape[1]
        count, pos = int(self._count[k]), int(self._pos[k])
        return [(float(self._hist[0, (pos - count + m) % size, k]), float(self._hist[1, (pos - count + m) % size, k]))
                for m in range(count)]

    def set_history(self, k: int, entries: list[tuple[float, float]]) -> None:
        """Replace environment ``k``'s delay line (the newest entries that fit are kept)."""
        if self.delay_samples is None:
            return
        size = self._hist.shape[1]
        entries = entries[-size:]
        for m, (u, i) in enumerate(entries):
            self._hist[0, m, k], self._hist[1, m, k] = u, i
        self._count[k] = len(entries)
        self._pos[k] = len(entries) % size

    def _noise(self, envs: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        n = self.p.n if envs is None else len(envs)
        if self.rngs is None:
            return self.rng.standard_normal(n), self.rng.standard_normal(n)
        chosen = self.rngs if envs is None else [self.rngs[k] for k in envs]
        z = np.array([g.standard_normal(2) for g in chosen]).reshape(n, 2)
        return z[:, 0], z[:, 1]

    def _delayed(self, u: np.ndarray, i: np.ndarray, envs: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Push (u, i) into each environment's history and return the lagged values."""
        cols = np.arange(self.p.n) if envs is None else np.asarray(envs)
        size = self._hist.shape[1]
        pos = self._pos[cols]
        self._hist[0, pos, cols] = u
        self._hist[1, pos, cols] = i
        self._pos[cols] = (pos + 1) % size
        count = np.minimum(self._count[cols] + 1, size)
        self._count[cols] = count
        back = np.minimum(self.delay_samples[cols], count - 1)
        k = np.floor(back).astype(np.int64)
        frac = back - k
        newest = pos  # index of the value just written
        newer = (newest - k) % size
        older = (newest - np.minimum(k + 1, count - 1)) % size
        lag = self._hist[:, newer, cols] * (1 - frac) + self._hist[:, older, cols] * frac
        return lag[0], lag[1]

    def read(self, t, phi, psi, u, i, brake, envs: np.ndarray | None = None) -> BatchedReading:
        """Readings of the given true values (arrays over ``envs``, or over the whole batch)."""
        s = self.p.sensors
        sel = slice(None) if envs is None else envs
        if self.delay_samples is not None:
            u_lag, i_lag = self._delayed(u, i, envs)
        else:
            u_lag, i_lag = u, i
        z_i, z_u = self._noise(envs)
        i_meas = self._i_gain[sel] * i_lag + s.current_offset[sel] + s.current_noise[sel] * z_i
        u_meas = self._u_gain[sel] * u_lag + s.voltage_offset[sel] + s.voltage_noise[sel] * z_u
        dtype = np.asarray(phi).dtype
        return BatchedReading(t=np.array(t, dtype=float), phi=quantise_array(phi, s.phi_counts[sel]),
                              psi=quantise_array(psi, s.psi_counts[sel]), u=u_meas.astype(dtype, copy=False),
                              i=i_meas.astype(dtype, copy=False), brake=np.array(brake, dtype=bool))
