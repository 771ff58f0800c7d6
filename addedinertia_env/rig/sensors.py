"""What the rig's instruments report: one array-based sensor model for one or many rigs.

:class:`SensorModel` maps the true state of ``n`` environments (arrays) to readings:
encoder quantisation ``floor(x / q + 0.5) q`` (``q = 2 pi / counts``; 0 counts: exact),
current and voltage gain, offset and noise, and the hidden ``sensor_delay`` of the
current/voltage channel behind the encoders (linear interpolation in a short
per-environment history). The single rig (:class:`Sensors`, used by
:class:`~.mujoco_rig.MujocoRig`) is the same model with ``n = 1``; the batched rig uses
it with ``n`` environments, so both compute every reading with the same operations.

Noise is counter-based (:mod:`.noise`): reading ``k`` of an environment draws the pair
of normals of its key at index ``k`` (current first, voltage second). An environment
that is not ``active`` in a reading keeps its counter and its delay line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import forces
from .noise import batch_keys, normal_pairs


@dataclass(frozen=True)
class Reading:
    """One sample as the data acquisition sees it (SI units)."""

    t: float
    phi: float  # rad, hull encoder
    psi: float  # rad, motor encoder (flywheel relative to hull), unwrapped
    u: float  # V, terminal voltage
    i: float  # A, motor current
    brake: bool


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


def quantise(x: float, counts: int) -> float:
    """Encoder reading of angle ``x`` (rad) for ``counts`` counts per turn (0: exact)."""
    return float(quantise_array(np.array([x]), np.array([counts]))[0])


def encoder_step(counts: np.ndarray) -> tuple[np.ndarray, bool]:
    """Encoder quantum ``2 pi / counts`` (rad; 1 where ``counts`` is 0) and whether every encoder counts."""
    return 2.0 * math.pi / np.where(counts > 0, counts, 1), bool(np.all(counts > 0))


def quantise_array(x: np.ndarray, counts: np.ndarray, step: tuple[np.ndarray, bool] | None = None) -> np.ndarray:
    """Encoder reading of angles ``x`` (rad) for ``counts`` counts per turn (0: exact);
    ``step``: :func:`encoder_step` of ``counts``, if already known."""
    q, all_count = step if step is not None else encoder_step(counts)
    y = np.floor(x / q + 0.5) * q
    if all_count:
        return y.astype(x.dtype, copy=False)
    return np.where(counts > 0, y, x).astype(x.dtype, copy=False)


NOISE_BLOCK = 32  # readings of noise drawn at a time per environment (one vectorised hash call)


class SensorModel:
    """Readings of ``params.n`` environments (``params``: a :class:`~.batched_params.BatchedParams`).

    ``seed``: one seed (keys derived per environment) or one seed per environment (each
    environment then reads exactly as a single rig with that seed).
    """

    def __init__(self, params, seed=None, keys: np.ndarray | None = None):
        self.p = params
        n = params.n
        self.keys = np.asarray(keys, dtype=np.uint64) if keys is not None else batch_keys(seed, n)
        if self.keys.shape != (n,):
            raise ValueError(f"SensorModel: {self.keys.shape} noise keys for {n} environments")
        self.counters = np.zeros(n, dtype=np.uint64)  # readings taken so far
        # Noise drawn NOISE_BLOCK readings ahead per environment: z[channel, k - base, env].
        self._z = np.zeros((2, NOISE_BLOCK, n))
        self._z_base = np.full(n, np.iinfo(np.int64).max // 2, dtype=np.int64)
        self._hist = None
        self._cols: np.ndarray | None = None  # 0..n-1, kept (every environment's column)
        self._update_params()

    # --- per-environment state ----------------------------------------------------------
    def _update_params(self) -> None:
        """Encoder quanta and delay (in samples) per environment from the parameters; allocates the delay line."""
        s = self.p.sensors
        self._phi_step, self._psi_step = encoder_step(s.phi_counts), encoder_step(s.psi_counts)
        n = self.p.n
        if not forces.has_channel_delay(self.p):
            self.delay_samples = None
            return
        self.delay_samples = self.p.per_env(forces.channel_delay(self.p)).astype(float) * self.p.sample_rate  # samples
        size = max(16, int(math.ceil(float(np.max(self.delay_samples)))) + 2)
        if self._hist is None or self._hist.shape[1] < size or self._hist.shape[2] != n:
            old = [self.history(e) for e in range(n)] if self._hist is not None and self._hist.shape[2] == n else None
            self._hist = np.zeros((2, size, n))  # (u, i) x ring position x env
            self._pos = np.zeros(n, dtype=np.int64)  # next write position
            self._count = np.zeros(n, dtype=np.int64)  # entries held (<= size)
            if old is not None:
                for e, entries in enumerate(old):
                    self.set_history(e, entries)

    def set_envs(self, envs: np.ndarray, keys: np.ndarray) -> None:
        """Environments ``envs`` start anew (their parameters already replaced in ``p``): new
        noise keys, counters at 0, empty delay lines."""
        self.keys[envs] = keys
        self.counters[envs] = 0
        self._z_base[envs] = np.iinfo(np.int64).max // 2
        self._update_params()
        self.reset(envs)

    def reset(self, envs: np.ndarray | None = None) -> None:
        """Empty the delay lines of ``envs`` (all by default); the noise streams go on."""
        if self.delay_samples is not None:
            sel = slice(None) if envs is None else envs
            self._count[sel] = 0
            self._pos[sel] = 0

    def history(self, k: int) -> list[tuple[float, float]]:
        """Environment ``k``'s delay line, oldest first: ``[(u, i), ...]`` (empty without delay)."""
        if self.delay_samples is None or self._hist is None:
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

    # --- readings -----------------------------------------------------------------------
    def _delayed(self, u, i, cols: np.ndarray):
        """Push (u, i) into the histories of ``cols`` and return the lagged values."""
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
        newer = (pos - k) % size
        older = (pos - np.minimum(k + 1, count - 1)) % size
        lag = self._hist[:, newer, cols] * (1 - frac) + self._hist[:, older, cols] * frac
        return lag[0], lag[1]

    def _normals(self, counters: np.ndarray, envs: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The pairs of normals of readings ``counters`` (of ``envs``), from the blocks drawn ahead.

        When some environment's block is used up, every environment past half of its block
        draws anew too, so that the batch's blocks stay in step (few draws per sample)."""
        n = self.p.n
        if envs is None:
            if self._cols is None or len(self._cols) != n:
                self._cols = np.arange(n)
            cols, z_base = self._cols, self._z_base
        else:
            cols = np.asarray(envs)
            z_base = self._z_base[cols]
        offset = counters.astype(np.int64) - z_base
        stale = (offset < 0) | (offset >= NOISE_BLOCK)
        if stale.any():
            redo_sel = np.nonzero(stale | (offset >= NOISE_BLOCK // 2))[0]
            redo = cols[redo_sel]
            base = counters[redo_sel].astype(np.int64)
            k = base[None, :] + np.arange(NOISE_BLOCK)[:, None]
            z_i, z_u = normal_pairs(np.broadcast_to(self.keys[redo], k.shape), k)
            self._z[0][:, redo], self._z[1][:, redo] = z_i, z_u
            self._z_base[redo] = base
            offset[redo_sel] = 0
        flat = offset * n + cols
        return self._z[0].ravel().take(flat), self._z[1].ravel().take(flat)

    def read(self, t, phi, psi, u, i, brake, envs: np.ndarray | None = None,
             active: np.ndarray | None = None) -> BatchedReading:
        """Readings of the given true values: arrays over ``envs`` (indices), or over all.

        ``active`` (bool over the same environments): only those take a reading (their
        noise counter and delay line advance); the others' values are computed but stale.
        """
        s = self.p.sensors
        sel = slice(None) if envs is None else envs
        if self.delay_samples is not None:
            cols = np.arange(self.p.n) if envs is None else np.asarray(envs)
            u_lag, i_lag = u.copy(), i.copy()
            take = cols if active is None else cols[active]
            if len(take):
                ul, il = self._delayed(u if active is None else u[active], i if active is None else i[active], take)
                if active is None:
                    u_lag, i_lag = ul, il
                else:
                    u_lag[active], i_lag[active] = ul, il
        else:
            u_lag, i_lag = u, i
        counters = self.counters[sel]
        z_i, z_u = self._normals(counters, envs)
        if active is None:
            self.counters[sel] = counters + np.uint64(1)
        else:
            self.counters[sel] = counters + active.astype(np.uint64)
        i_meas = (1.0 + s.current_gain_error[sel]) * i_lag + s.current_offset[sel] + s.current_noise[sel] * z_i
        u_meas = (1.0 + s.voltage_gain_error[sel]) * u_lag + s.voltage_offset[sel] + s.voltage_noise[sel] * z_u
        dtype = np.asarray(phi).dtype
        if envs is None:
            phi_q = quantise_array(phi, s.phi_counts, self._phi_step)
            psi_q = quantise_array(psi, s.psi_counts, self._psi_step)
        else:
            phi_q, psi_q = quantise_array(phi, s.phi_counts[sel]), quantise_array(psi, s.psi_counts[sel])
        return BatchedReading(t=np.array(t, dtype=float), phi=phi_q, psi=psi_q, u=u_meas.astype(dtype, copy=False),
                              i=i_meas.astype(dtype, copy=False), brake=np.array(brake, dtype=bool))


class Sensors:
    """The sensor model of one rig (``n = 1``) with scalar readings; ``seed`` as for :class:`SensorModel`."""

    def __init__(self, params, seed=None):
        from .batched_params import BatchedParams  # noqa: PLC0415 - batched_params imports this module's users

        self.p = params
        self.model = SensorModel(BatchedParams.repeat(params, 1), seed=[seed])

    def reset(self) -> None:
        """Empty the sensor delay lines (a new run); the noise streams go on."""
        self.model.reset()

    def read(self, t: float, phi: float, psi: float, u: float, i: float, brake: bool) -> Reading:
        """What the instruments report at time ``t`` (s) for the true state of one rig.

        ``phi`` and ``psi`` in rad, ``u`` in V, ``i`` in A, ``brake`` engaged or not. Returns
        a :class:`Reading` of plain floats.
        """
        return self.model.read(np.array([t]), np.array([phi]), np.array([psi]), np.array([u]), np.array([i]),
                               np.array([brake])).single(0)
