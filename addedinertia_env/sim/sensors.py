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

from addedinertia_env.sim import forces
from addedinertia_env.sim.kernels import encoder_readings, noise_uniforms, sensor_readings
from addedinertia_env.sim.noise import batch_keys, box_muller
from addedinertia_env.rig.signals import Reading


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
    ``step``: :func:`encoder_step` of ``counts``, if already known (:func:`~.kernels.encoder_reading`)."""
    q, _ = step if step is not None else encoder_step(counts)
    x = np.asarray(x)
    out = np.empty(x.shape, dtype=x.dtype)
    q = np.broadcast_to(np.where(np.asarray(counts) > 0, q, 0.0), x.shape).reshape(-1)
    encoder_readings(x.reshape(-1), np.ascontiguousarray(q), out.reshape(-1))
    return out


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
        self._hist = None
        self._cols = np.arange(n)  # every environment's column
        self._all = np.ones(n, dtype=bool)
        self._update_params()

    # --- per-environment state ----------------------------------------------------------
    def _update_params(self) -> None:
        """Encoder quanta and delay (in samples) per environment from the parameters; allocates the delay line."""
        s = self.p.sensors
        self._phi_step, self._psi_step = encoder_step(s.phi_counts), encoder_step(s.psi_counts)
        # the quanta as the compiled reading takes them: 0 where an encoder reads exactly
        self._phi_q = np.where(s.phi_counts > 0, self._phi_step[0], 0.0)
        self._psi_q = np.where(s.psi_counts > 0, self._psi_step[0], 0.0)
        n = self.p.n
        if not forces.has_channel_delay(self.p):
            self.delay_samples = None
            self._hist = None
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
    _NO_DELAY = (np.zeros((2, 1, 1)), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), np.zeros(0))

    def _normals(self, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pair of normals (current, voltage) of the next reading of environments ``cols``
        (:func:`~.noise.normal_pairs` at their counters: the hash compiled, Box-Muller in numpy)."""
        u1, u2 = np.empty(len(cols)), np.empty(len(cols))
        noise_uniforms(self.keys, self.counters, cols, u1, u2)
        return box_muller(u1, u2)

    def delay_line(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The channel delay line as the compiled reading takes it: ``(hist, pos, count, delay)``
        (empty ``delay`` when there is none)."""
        if self.delay_samples is None:
            return self._NO_DELAY
        return self._hist, self._pos, self._count, self.delay_samples

    def read(self, t, phi, psi, u, i, brake, envs: np.ndarray | None = None,
             active: np.ndarray | None = None) -> BatchedReading:
        """Readings of the given true values: arrays over ``envs`` (indices), or over all.

        ``active`` (bool over the same environments): only those take a reading (their
        noise counter and delay line advance); the others' values are computed from the
        undelayed ``u``, ``i`` and their next noise (stale). The arithmetic is
        :func:`~.kernels.sensor_readings`.
        """
        s = self.p.sensors
        if envs is None:
            cols = self._cols
        else:
            cols = np.asarray(envs, dtype=np.int64).reshape(-1)
        m = len(cols)
        active = (self._all if m == self.p.n else np.ones(m, dtype=bool)) if active is None \
            else np.asarray(active, dtype=bool)
        dtype = np.asarray(phi).dtype
        z_i, z_u = self._normals(cols)
        out = [np.empty(m, dtype=dtype) for _ in range(4)]
        hist, pos, count, delay = self.delay_line()
        sensor_readings(cols, active, *(np.asarray(x).reshape(-1) for x in (phi, psi, u, i)), z_i, z_u,
                        self.counters, s.current_gain_error, s.current_offset, s.current_noise,
                        s.voltage_gain_error, s.voltage_offset, s.voltage_noise, self._phi_q, self._psi_q,
                        hist, pos, count, delay, *out)
        return BatchedReading(t=np.array(t, dtype=float), phi=out[0], psi=out[1], u=out[2], i=out[3],
                              brake=np.array(brake, dtype=bool))


class Sensors:
    """The sensor model of one rig (``n = 1``) with scalar readings; ``seed`` as for :class:`SensorModel`."""

    def __init__(self, params, seed=None):
        from addedinertia_env.sim.batched_params import BatchedParams  # noqa: PLC0415 - batched_params imports this module's users

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
