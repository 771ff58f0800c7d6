"""The compiled loops of sim/kernels.py against the numpy code they replaced (written out here)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from addedinertia_env.sim import effects as E
from addedinertia_env.sim.batched import N_OUT, STATE, substep_matrix
from addedinertia_env.sim.batched_params import BatchedParams
from addedinertia_env.sim.kernels import encoder_reading, linear_substep, noise_uniforms
from addedinertia_env.sim.noise import batch_keys, normal_pairs, uniform_pairs
from addedinertia_env.sim.params import RigParams, SensorParams
from addedinertia_env.sim.sensors import SensorModel


def test_noise_hash_equals_numpy_bit_for_bit():
    keys = batch_keys(7, 50)
    counters = np.arange(50, dtype=np.uint64) * np.uint64(977) + np.uint64(2**40)
    u1, u2 = np.empty(50), np.empty(50)
    noise_uniforms(keys, counters, np.arange(50), u1, u2)
    r1, r2 = uniform_pairs(keys, counters)
    assert np.array_equal(u1, r1) and np.array_equal(u2, r2)
    assert 0.0 < u1.min() and u1.max() < 1.0
    model = SensorModel(BatchedParams.repeat(RigParams(), 50), keys=keys)
    model.counters[:] = counters
    z_i, z_u = model._normals(np.arange(50))
    n_i, n_u = normal_pairs(keys, counters)
    assert np.array_equal(z_i, n_i) and np.array_equal(z_u, n_u)


def test_encoder_reading_is_the_rounding_law():
    q = 2.0 * math.pi / 4096
    for x in (-1.234567, 0.0, 0.5 * q, 3.3 * q, 1e-9, -0.5 * q):
        assert encoder_reading(x, q) == math.floor(x / q + 0.5) * q
    assert encoder_reading(0.1234, 0.0) == 0.1234  # 0 counts: exact


def numpy_reading(model_state, values, z, active, s, delay_samples):
    """The former numpy SensorModel.read (delay line, gain, offset, noise, quantisation) on all environments."""
    hist, pos, count = model_state
    phi, psi, u, i = values
    u_lag, i_lag = u.copy(), i.copy()
    if delay_samples is not None:
        cols = np.nonzero(active)[0]
        size = hist.shape[1]
        p = pos[cols]
        hist[0, p, cols], hist[1, p, cols] = u[cols], i[cols]
        pos[cols] = (p + 1) % size
        c = np.minimum(count[cols] + 1, size)
        count[cols] = c
        back = np.minimum(delay_samples[cols], c - 1)
        k = np.floor(back).astype(np.int64)
        frac = back - k
        newer, older = (p - k) % size, (p - np.minimum(k + 1, c - 1)) % size
        lag = hist[:, newer, cols] * (1 - frac) + hist[:, older, cols] * frac
        u_lag[cols], i_lag[cols] = lag[0], lag[1]
    i_meas = (1.0 + s.current_gain_error) * i_lag + s.current_offset + s.current_noise * z[0]
    u_meas = (1.0 + s.voltage_gain_error) * u_lag + s.voltage_offset + s.voltage_noise * z[1]

    def quantise(x, counts):
        q = 2.0 * math.pi / np.where(counts > 0, counts, 1)
        return np.where(counts > 0, np.floor(x / q + 0.5) * q, x)

    return quantise(phi, s.phi_counts), quantise(psi, s.psi_counts), u_meas, i_meas


@pytest.mark.parametrize("delay", [None, 0.0023])
def test_sensor_reading_equals_the_numpy_model(delay):
    rigs = []
    for k in range(6):
        effects = E.Effects(sensor_delay=E.SensorDelay(delay * (1 + k % 3))) if delay else E.Effects()
        sensors = SensorParams(current_noise=0.01 * (k + 1), voltage_noise=0.02, current_offset=0.003 * k,
                               voltage_gain_error=-0.01 * k, phi_counts=0 if k == 4 else 4096 * (k + 1))
        rigs.append(RigParams(sensors=sensors, effects=effects))
    p = BatchedParams.stack(rigs)
    model = SensorModel(p, seed=list(range(6)))
    size = model._hist.shape[1] if delay else 1
    state = (np.zeros((2, size, 6)), np.zeros(6, dtype=np.int64), np.zeros(6, dtype=np.int64))
    rng = np.random.default_rng(3)
    for step in range(30):
        values = [rng.normal(size=6) for _ in range(4)]
        active = rng.random(6) < 0.7
        z = normal_pairs(model.keys, model.counters)
        counters = model.counters.copy()
        got = model.read(np.zeros(6), *values, np.zeros(6, dtype=bool), active=active)
        want = numpy_reading(state, values, z, active, p.sensors, model.delay_samples)
        for g, w in zip((got.phi, got.psi, got.u, got.i), want):
            assert np.allclose(g, w, rtol=1e-15, atol=1e-15), step
        assert np.array_equal(model.counters, counters + active.astype(np.uint64))


def test_linear_substep_equals_the_map_per_environment():
    n = 7
    rng = np.random.default_rng(5)
    args = (rng.uniform(10, 20, n), rng.uniform(5, 9, n), rng.uniform(0.01, 0.1, n), rng.uniform(0.1, 0.3, n),
            rng.uniform(1, 3, n), rng.uniform(1e-3, 3e-3, n))
    table = np.stack([substep_matrix(5e-4, kind, *args) for kind in range(4)])  # (kind, out, in, n)
    G = np.ascontiguousarray(np.moveaxis(table, -1, 0))
    X = rng.normal(size=(len(STATE), n))
    brake, driven, running = rng.random(n) < 0.5, rng.random(n) < 0.5, rng.random(n) < 0.7
    k_t, q_hull, offset, f2 = (rng.normal(size=n) for _ in range(4))
    w_prev, t = rng.normal(size=n), np.zeros(n)
    want = X.copy()  # a paused environment (not running) keeps its state as it is
    want[5] = np.where(driven | ~running, X[5], k_t * X[3])
    want[4] = np.where(driven | ~running, X[4], 0.0)
    want[6], want[7] = np.where(running, q_hull + offset, X[6]), np.where(running, f2, X[7])
    kind = 2 * brake + driven
    for k in np.nonzero(running)[0]:
        want[:N_OUT, k] = table[kind[k], :, :, k] @ want[:, k]
    w_prev_want = np.where(running, X[1], w_prev)
    linear_substep(X, G, brake, driven, running, k_t, q_hull, offset, f2, w_prev, t, 5e-4)
    assert np.allclose(X, want, rtol=1e-14, atol=1e-14)
    assert np.array_equal(w_prev, w_prev_want)
    assert np.array_equal(t, np.where(running, 5e-4, 0.0))


def test_whole_sample_kernel_equals_the_step_by_step_path(monkeypatch):
    """BatchedRig.step in one rig_sample call (a batch without hull-torque effects) equals the
    numpy forces + linear_substep + sensor_readings path, mixed modes, brakes, pauses and delays."""
    from addedinertia_env.sim.batched import BatchedRig
    from addedinertia_env.sim.params import HullParams, MotorParams

    rigs = [RigParams(), RigParams(hull=HullParams(J_hull=3.0, lambda66=4.0, b1=0.5, b2=10.0),
                                   motor=MotorParams(J_flywheel=0.05, k_t=0.2),
                                   effects=E.Effects(sensor_delay=E.SensorDelay(0.0031),
                                                     neutral_offset=E.NeutralOffset(0.01),
                                                     torque_constant=E.TorqueConstant(1.05))),
            RigParams(hull=HullParams(lambda66=20.0))]
    fast, slow = (BatchedRig(rigs, seed=[1, 2, 3]) for _ in range(2))
    assert fast._plain()
    monkeypatch.setattr(slow, "_plain", lambda: False)
    for rig in (fast, slow):
        rig.reset(phi0=np.array([-0.1, 0.05, 0.2]), brake=False)
    rng = np.random.default_rng(9)
    for k in range(400):
        mode = rng.integers(0, 3, 3)
        value = rng.uniform(-3, 3, 3)
        active = rng.random(3) < 0.8
        if k % 50 == 0:
            brake = rng.random(3) < 0.5
            for rig in (fast, slow):
                rig.set_brake(brake)
        a, b = fast.step(mode, value, active=active), slow.step(mode, value, active=active)
        for name in ("phi", "psi", "u", "i", "t"):
            assert np.allclose(getattr(a, name), getattr(b, name), rtol=1e-12, atol=1e-12), (k, name)
    assert np.allclose(fast._X[:6], slow._X[:6], rtol=1e-12, atol=1e-12)
    assert np.array_equal(fast.sensors.counters, slow.sensors.counters)
