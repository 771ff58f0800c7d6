"""Sensor noise as a counter-based stream: reading ``k`` of environment ``e`` has its own numbers.

The noise of a reading is a pure function of the environment's key (from its seed) and
the reading's index, not of the order in which a program draws it. So one environment
gives the same noise whether it is simulated alone (:class:`~.mujoco_rig.MujocoRig`,
one array element), in a batch of thousands, paused while others run, or moved to
another slot of a batch: the property that lets the batched task equal the single one.

Each reading's pair of standard normals (current channel, voltage channel) comes from
one 64-bit SplitMix64 hash of ``key + (k + 1) * golden``, split into two 32-bit
uniforms and turned into two independent normals by the Box-Muller transform (tails
reach 6.6 sigma; sensor noise needs no more).
"""

from __future__ import annotations

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_C1 = np.uint64(0xBF58476D1CE4E5B9)
_C2 = np.uint64(0x94D049BB133111EB)
_TWO_PI = 2.0 * np.pi
_INV_2_32 = 1.0 / 4294967296.0
_LOW32 = np.uint64(0xFFFFFFFF)


def _mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser on uint64 arrays (wrapping arithmetic)."""
    z = (z ^ (z >> np.uint64(30))) * _C1
    z = (z ^ (z >> np.uint64(27))) * _C2
    return z ^ (z >> np.uint64(31))


def noise_key(seed) -> np.uint64:
    """One environment's 64-bit noise key from ``seed``: an int, a SeedSequence, a Generator or None
    (fresh entropy)."""
    if isinstance(seed, np.random.Generator):
        return np.uint64(seed.integers(0, 2**63, dtype=np.uint64))
    if not isinstance(seed, np.random.SeedSequence):
        seed = np.random.SeedSequence(seed)
    return seed.generate_state(1, dtype=np.uint64)[0]


def batch_keys(seed, n: int) -> np.ndarray:
    """``n`` distinct keys: one per seed if ``seed`` is a sequence, else derived from one seed."""
    if seed is not None and not np.isscalar(seed) and not isinstance(seed, (np.random.SeedSequence,
                                                                           np.random.Generator)):
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"{len(seeds)} seeds for {n} environments; give one per environment or a single seed")
        return np.array([noise_key(s) for s in seeds], dtype=np.uint64)
    base = noise_key(seed)
    return _mix(base + np.arange(n, dtype=np.uint64) * _GOLDEN)


def uniform_pairs(keys: np.ndarray, counters: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two uniforms in (0, 1) of readings ``counters`` of ``keys`` (the high and low 32 bits of
    one SplitMix64 hash each; :func:`~.kernels.noise_uniforms` is the same per element)."""
    z = _mix(keys + (counters.astype(np.uint64) + np.uint64(1)) * _GOLDEN)
    u1 = ((z >> np.uint64(32)).astype(np.float64) + 0.5) * _INV_2_32  # in (0, 1)
    u2 = ((z & _LOW32).astype(np.float64) + 0.5) * _INV_2_32
    return u1, u2


def box_muller(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two independent standard normals per element from two uniforms in (0, 1) (Box-Muller)."""
    r = np.sqrt(-2.0 * np.log(u1))
    angle = _TWO_PI * u2
    return r * np.cos(angle), r * np.sin(angle)


def normal_pairs(keys: np.ndarray, counters: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two independent standard normals per element for readings ``counters`` of ``keys``."""
    return box_muller(*uniform_pairs(keys, counters))
