"""Compiled per-environment loops of the batched rig (numba): a physics step and a sensor reading.

Every rig built on :class:`~.batched.BatchedRig` (the batched task's pool, the single
view :class:`~.batched_single.BatchedSingleRig`) and every :class:`~.sensors.SensorModel`
(so also :class:`~.mujoco_rig.MujocoRig`'s sensors) runs these loops; there is no second
numpy copy of them. They hold no physics law of their own:

* :func:`rig_sample` is a whole sample period (all physics steps) of a batch whose only
  extra torques are the damping and the rotor friction (no hull-torque effect, no water
  or radiation memory: the whole task's default): the drive's voltage, the torques and the
  step map. The laws are compiled from their one definition (:func:`~.motor.drive_voltage`,
  :func:`~.forces.centred_rate`, :func:`~.forces.hydrodynamic_torque`,
  :func:`~.forces.flywheel_friction_torque`; numba jits those very functions);
* :func:`linear_substep` is one physics step of any other batch: the nonlinear torques
  come in as arrays, computed by :mod:`.forces` before the call; both apply the step map
  ``G`` of :func:`~.batched.substep_matrix` (the linear part of the physics step, built
  from :func:`~.batched.reference_substep`) with :func:`apply_map`, and the open-circuit
  rule of :mod:`.motor`;
* :func:`noise_uniforms` is :func:`~.noise.normal_pairs`'s integer hash (SplitMix64) and
  its two uniforms; the Box-Muller transform stays in numpy (:func:`~.noise.box_muller`)
  so that the normals equal ``normal_pairs`` bit for bit;
* :func:`sensor_readings` is :meth:`~.sensors.SensorModel.read`'s arithmetic (delay line,
  gain, offset, noise, encoder quantisation :func:`encoder_reading`) per environment.

tests/test_kernels.py holds each loop equal to the numpy code it replaced.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

from addedinertia_env.sim import forces, motor

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_C1 = np.uint64(0xBF58476D1CE4E5B9)
_C2 = np.uint64(0x94D049BB133111EB)
_INV_2_32 = 1.0 / 4294967296.0
_LOW32 = np.uint64(0xFFFFFFFF)
_ONE = np.uint64(1)
_S30, _S27, _S31, _S32 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(32)

# rows of the state block (batched.STATE)
_PHI, _W, _PSI, _OMEGA, _I, _U, _F1, _F2 = range(8)

# Columns of the per-environment constants of :func:`rig_sample` (``BatchedRig._constants``).
CONSTANTS = ("k_t", "spring_offset", "b1", "b2", "friction_viscous", "friction_coulomb", "R", "u_max", "i_max",
             "decay")
_K_T, _OFFSET, _B1, _B2, _FV, _FC, _R, _U_MAX, _I_MAX, _DECAY = range(len(CONSTANTS))

# One environment's parameters as the force laws read them (p.hull.b1, p.motor.friction_viscous...).
_Hull = namedtuple("_Hull", "b1 b2")
_Motor = namedtuple("_Motor", "friction_viscous friction_coulomb")
_Rig = namedtuple("_Rig", "hull motor")

# The laws themselves, compiled from their one definition in forces.py and motor.py.
centred_rate = njit(forces.centred_rate, cache=True)
hydrodynamic_torque = njit(forces.hydrodynamic_torque, cache=True)
flywheel_friction_torque = njit(forces.flywheel_friction_torque, cache=True)
drive_voltage = njit(motor.drive_voltage, cache=True)


@njit(cache=True)
def linear_substep(X, G, brake, driven, running, k_t, q_hull, spring_offset, f2, w_prev, t, h):  # pragma: no cover - compiled
    """One physics step of every environment ``k`` in place (the loop of ``BatchedRig.physics_step``).

    ``X`` (8, n): the state block (rows ``phi, w, psi, omega, i, u, F1, F2``); ``G`` (n or 1,
    4, 5, 8): the step maps per environment and kind (``2 brake + driven``); ``brake``,
    ``driven``, ``running`` (n,) bool; ``k_t`` (n,) N m/A; ``q_hull`` (n,) N m, the held hull
    torques without the spring (:func:`~.forces.hull_extra_torque` at ``w_prev``'s centred
    rate, radiation memory included); ``spring_offset`` (n,) N m (``c phi_n``); ``f2`` (n,)
    N m, the rotor friction; ``w_prev`` (n,) rad/s, the hull rate one step ago (updated
    here where running); ``t`` (n,) s, advanced by ``h`` where running.

    Equals, per running environment: open terminals (not driven) show the back-EMF ``k_t Omega``
    and carry no current; ``F1 = q_hull + c phi_n``, ``F2 = f2``; then
    ``(phi, w, psi, omega, i) = G[kind] @ X`` (summed in the order j = 0..7). The others
    (paused) keep their state as it is.
    """
    n = X.shape[1]
    shared = G.shape[0] == 1
    for k in range(n):
        if not running[k]:  # paused: its state as it is (open terminals too)
            continue
        if not driven[k]:
            X[_U, k] = k_t[k] * X[_OMEGA, k]
            X[_I, k] = 0.0
        X[_F1, k] = q_hull[k] + spring_offset[k]
        X[_F2, k] = f2[k]
        w_prev[k] = X[_W, k]
        kind = 2 * np.int64(brake[k]) + np.int64(driven[k])
        col = 0 if shared else k
        apply_map(X, k, G[col, kind])
        t[k] += h


@njit(cache=True, inline="always")
def apply_map(X, k, g):  # pragma: no cover - compiled
    """``(phi, w, psi, omega, i) = g @ X[:, k]`` in place (``g``: one 5 x 8 step map; summed j = 0..7)."""
    x0, x1, x2, x3 = X[0, k], X[1, k], X[2, k], X[3, k]
    x4, x5, x6, x7 = X[4, k], X[5, k], X[6, k], X[7, k]
    for r in range(5):  # every input is read above, so the rows can be written in place
        X[r, k] = (g[r, 0] * x0 + g[r, 1] * x1 + g[r, 2] * x2 + g[r, 3] * x3
                   + g[r, 4] * x4 + g[r, 5] * x5 + g[r, 6] * x6 + g[r, 7] * x7)


@njit(cache=True)
def noise_uniforms(keys, counters, cols, u1, u2):  # pragma: no cover - compiled
    """The two uniforms in (0, 1) of reading ``counters[k]`` of environment ``k = cols[j]``, into
    ``u1[j]``, ``u2[j]``: :func:`~.noise.normal_pairs`'s SplitMix64 hash of
    ``key + (counter + 1) * golden``, high and low 32 bits."""
    for j in range(len(cols)):
        k = cols[j]
        z = keys[k] + (counters[k] + _ONE) * _GOLDEN
        z = (z ^ (z >> _S30)) * _C1
        z = (z ^ (z >> _S27)) * _C2
        z = z ^ (z >> _S31)
        u1[j] = (np.float64(z >> _S32) + 0.5) * _INV_2_32
        u2[j] = (np.float64(z & _LOW32) + 0.5) * _INV_2_32


@njit(cache=True)
def sensor_readings(cols, active, phi, psi, u, i, z_i, z_u, counters,
                    current_gain, current_offset, current_noise, voltage_gain, voltage_offset, voltage_noise,
                    phi_q, psi_q, hist, pos, count, delay, out_phi, out_psi, out_u, out_i):  # pragma: no cover
    """The readings of environments ``k = cols[j]`` from their true values ``phi[j], psi[j]``
    (rad), ``u[j]`` (V), ``i[j]`` (A) and normals ``z_i[j], z_u[j]``, into ``out_*[j]``.

    Per environment (arrays indexed by ``k``): gains (-), offsets (V, A), noise levels,
    encoder quanta ``phi_q``/``psi_q`` (rad; 0: exact reading), and, when ``delay`` is not
    empty, the channel's delay line ``hist`` (2, size, n), its write position ``pos``,
    fill ``count`` and ``delay`` (samples). Where ``active[j]``: the value pair enters the
    delay line, the reading takes the lagged pair, and the noise counter advances; else
    the reading is computed from the undelayed pair and nothing advances.
    Same operations as :meth:`~.sensors.SensorModel.read`.
    """
    has_delay = len(delay) > 0
    size = hist.shape[1]
    for j in range(len(cols)):
        k = cols[j]
        u_lag, i_lag = u[j], i[j]
        if active[j]:
            counters[k] += np.uint64(1)
            if has_delay:
                p = pos[k]
                hist[0, p, k] = u_lag
                hist[1, p, k] = i_lag
                pos[k] = (p + 1) % size
                c = min(count[k] + 1, size)
                count[k] = c
                back = min(delay[k], np.float64(c - 1))
                kk = np.int64(math.floor(back))
                frac = back - kk
                newer = (p - kk + size) % size
                older = (p - min(kk + 1, c - 1) + size) % size
                u_lag = hist[0, newer, k] * (1 - frac) + hist[0, older, k] * frac
                i_lag = hist[1, newer, k] * (1 - frac) + hist[1, older, k] * frac
        out_i[j] = (1.0 + current_gain[k]) * i_lag + current_offset[k] + current_noise[k] * z_i[j]
        out_u[j] = (1.0 + voltage_gain[k]) * u_lag + voltage_offset[k] + voltage_noise[k] * z_u[j]
        out_phi[j] = encoder_reading(phi[j], phi_q[k])
        out_psi[j] = encoder_reading(psi[j], psi_q[k])


@njit(cache=True)
def encoder_reading(x, q):  # pragma: no cover - compiled
    """An encoder's reading of angle ``x`` (rad) with quantum ``q`` (rad; 0: exact): ``floor(x / q + 0.5) q``."""
    return math.floor(x / q + 0.5) * q if q > 0 else x


@njit(cache=True)
def encoder_readings(x, q, out):  # pragma: no cover - compiled
    """:func:`encoder_reading` of ``x[j]`` with quantum ``q[j]`` into ``out[j]``."""
    for j in range(len(x)):
        out[j] = encoder_reading(x[j], q[j])


@njit(cache=True)
def rig_sample(X, G, G_now, kind_now, brake, mode, value, running, const, w_prev, water_rate, t, h, substeps):  # pragma: no cover
    """One sample period of every environment ``k`` in place: ``BatchedRig.physics_step`` for a
    batch whose only extra torques are the damping and the rotor friction.

    Per environment: the drive's voltage (:func:`~.motor.drive_voltage`, where ``mode[k]`` is
    1 current or 2 voltage, command ``value[k]``); then ``substeps`` physics steps of ``h`` s,
    each the torques of :mod:`.forces` (:func:`~.forces.hydrodynamic_torque` at the centred
    rate, :func:`~.forces.flywheel_friction_torque`) held and the step map ``G`` applied, as
    :func:`linear_substep` does; ``G_now`` (n, 5, 8) holds each environment's map of kind
    ``kind_now[k]`` (copied from ``G`` when the kind changes; -1: none). ``const`` (n,
    len(CONSTANTS)): the per-environment constants named by :data:`CONSTANTS`.
    Environments not ``running`` keep their state.
    """
    n = X.shape[1]
    shared = G.shape[0] == 1
    for k in range(n):
        if not running[k]:  # paused: its state as it is (the drive's voltage and open terminals too)
            continue
        c = const[k]
        driven = mode[k] != 0
        if driven:
            X[_U, k] = drive_voltage(mode[k], value[k], X[_I, k], X[_OMEGA, k], c[_R], c[_K_T], c[_U_MAX],
                                     c[_I_MAX], c[_DECAY])
        p = _Rig(_Hull(c[_B1], c[_B2]), _Motor(c[_FV], c[_FC]))
        kind = 2 * np.int64(brake[k]) + np.int64(driven)
        if kind != kind_now[k]:  # this environment's map of its kind, kept beside the table
            G_now[k] = G[0 if shared else k, kind]
            kind_now[k] = kind
        g = G_now[k]
        for _ in range(substeps):
            if not driven:  # open circuit: no current, the terminals show the back-EMF
                X[_U, k] = c[_K_T] * X[_OMEGA, k]
                X[_I, k] = 0.0
            w = X[_W, k]
            X[_F1, k] = hydrodynamic_torque(centred_rate(w, w_prev[k]), water_rate[k], p) + c[_OFFSET]
            X[_F2, k] = flywheel_friction_torque(X[_OMEGA, k], p)
            w_prev[k] = w
            apply_map(X, k, g)
            t[k] += h
