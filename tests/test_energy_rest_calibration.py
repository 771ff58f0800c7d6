"""The energy method's rest after the brake's release and its torque scale on a smooth current (issue 26).

- The rest after the release: a hull released from rest under its spring while a motor's current ramps up
  (a feedback controller's, within milliseconds), integrated finely, sampled and quantised: the fit with
  the law of motion's shape reads the known rest angle to a few hundredths of a count; the quadratic in
  time (constant acceleration) reads it off by tenths, the same way every time.
- The torque scale on a ``pd`` run, whose smooth current lets the flywheel calibration's lag and scale
  trade: fitted alone at the current's sampling rule, it recovers a drawn current-sensor gain within
  its own interval.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from addedinertia_env.identify.energy_rest import REST_FIT_S, crossings_fit, released_fit


def _release(rest: float, J: float, c: float, k_t: float, ramp_s: float, amps: float, fs: float = 1000.0,
             sub: int = 200):
    """Angle and current after a release from rest at ``rest``: ``J phi'' = -c phi - k_t i(t)``, ``i`` rising
    linearly to ``amps`` over ``ramp_s`` then held; integrated with ``sub`` steps a sample (velocity Verlet)."""
    n = int(round(0.2 * fs))
    dt = 1.0 / fs / sub
    phi, w = rest, 0.0
    t_s, phi_s, i_s = [], [], []

    def current(t):
        return amps * min(t / ramp_s, 1.0)

    def acc(t, p):
        return (-c * p - k_t * current(t)) / J

    t = 0.0
    for k in range(n):
        t_s.append(k / fs)
        phi_s.append(phi)
        i_s.append(current(k / fs))
        for _ in range(sub):
            a0 = acc(t, phi)
            phi += w * dt + 0.5 * a0 * dt * dt
            w += 0.5 * (a0 + acc(t + dt, phi)) * dt
            t += dt
    return np.array(t_s), np.array(phi_s), np.array(i_s)


def test_rest_after_release_is_read_without_bias_where_a_quadratic_is_not():
    J, c, k_t, counts = 12.0, 23.0, 0.24, 2**20  # a 20-bit encoder, as drawn hulls have
    q = 2.0 * np.pi / counts
    rng = np.random.default_rng(7)
    law, quad = [], []
    for _ in range(12):
        rest = 0.05 + rng.uniform(0.0, q)  # a rest anywhere within a count
        t, phi, i = _release(rest, J, c, k_t, ramp_s=0.01, amps=0.8)
        # the brake held the hull at ``rest`` for a while before: samples -50..-1 read the same angle
        pre = 50
        t = np.concatenate([np.arange(-pre, 0) / 1000.0, t])
        phi = np.concatenate([np.full(pre, rest), phi])
        i = np.concatenate([np.zeros(pre), i])
        read = np.round(phi / q) * q
        k = pre  # the last braked sample
        torque = -c * read - k_t * i
        fit = released_fit(t, read, k, REST_FIT_S, q, torque)
        assert fit is not None
        law.append((fit.rest - rest) / q)
        quad.append((crossings_fit(t, read, k, REST_FIT_S, q)[0] - rest) / q)
        assert fit.inverse_inertia == pytest.approx(1.0 / J, rel=0.02)
    law, quad = np.array(law), np.array(quad)
    print("law", law.mean(), np.abs(law).max(), "quadratic", quad.mean())
    assert abs(law.mean()) < 0.05, law  # counts
    assert np.abs(law).max() < 0.15, law
    # the constant-acceleration model's error is the one removed: tenths of a count, one sign
    assert abs(quad.mean()) > 5 * abs(law.mean()) and abs(quad.mean()) > 0.1, quad


def test_released_fit_refuses_without_a_torque_to_shape_it():
    t = np.arange(200) / 1000.0
    phi = np.round((1e-3 + 0.5 * t**2) / 1e-5) * 1e-5
    assert released_fit(t, phi, 0, REST_FIT_S, 1e-5, np.zeros_like(t)) is None


def test_pd_run_torque_scale_recovers_a_drawn_current_gain_within_its_interval():
    """A ``pd`` run (smooth current: the lag-and-scale calibration refuses) with a current-sensor gain 0.8 %
    high: the scale fitted alone must be 1 / 1.008 within three of its own sigmas, and that sigma must be
    well under the sensor's 0.5 % gain uncertainty it replaces."""
    from addedinertia_env.apps.simulate import simulate_run
    from addedinertia_env.experiment.scenarios import make_scenario
    from addedinertia_env.identify.energy_balance import CURRENT_GAIN_UNCERTAINTY, RunBalance

    sc = make_scenario(3, "wigley-2m")
    gain = 0.008
    rig = dataclasses.replace(sc.rig, sensors=dataclasses.replace(sc.rig.sensors, current_gain_error=gain))
    rec = simulate_run(rig, "pd", sc.plan, seed=17)
    balance = RunBalance(rec.without_truth())
    assert not balance.current_lag_calibrated  # the lag is not pinned on this smooth current
    assert balance.scale_sigma is not None
    assert balance.scale_sigma < 0.3 * CURRENT_GAIN_UNCERTAINTY
    true_scale = 1.0 / (1.0 + gain)
    assert abs(balance.torque_scale - true_scale) < 3.0 * balance.scale_sigma, (balance.torque_scale, balance.scale_sigma)


def _coast(w: float, omega0: float = 0.023, J_f: float = 0.13, f_visc: float = 1e-4, f_coul: float = 2e-3,
           seconds: float = 1.0, fs: float = 1000.0, sub: int = 20):
    """A flywheel coasting from ``omega0`` under ``J_f Omega' = -f_visc Omega - f_coul tanh(Omega / w)``, sampled."""
    n = int(seconds * fs)
    dt = 1.0 / fs / sub
    psi, omega, out = 0.0, omega0, []
    for _ in range(n):
        out.append(psi)
        for _ in range(sub):
            a = -(f_visc * omega + f_coul * np.tanh(omega / w)) / J_f
            psi += omega * dt + 0.5 * a * dt * dt
            omega = max(omega + a * dt, 0.0)
    return np.arange(n) / fs, np.array(out)


@pytest.mark.parametrize("w", [0.004, 0.01, 0.03])
def test_the_dry_frictions_law_near_rest_is_read_from_a_coast(w):
    from addedinertia_env.identify.rotor_friction import creep_rate_scale

    t, psi = _coast(w)
    got = creep_rate_scale(t, psi, np.zeros_like(t), 0, len(t) - 1, 0.13, 1e-4, 2e-3, 0.24, 0.0)
    assert got == pytest.approx(w, rel=0.05)


def test_a_sign_like_dry_friction_or_a_driven_flywheel_is_not_read_as_a_smoothed_law():
    from addedinertia_env.identify.rotor_friction import creep_rate_scale

    t, psi = _coast(1e-5, omega0=0.05)  # a constant deceleration (it would stop after 3.3 s)
    assert creep_rate_scale(t, psi, np.zeros_like(t), 0, len(t) - 1, 0.13, 1e-4, 2e-3, 0.24, 0.0) is None
    t, psi = _coast(0.01)
    current = np.full_like(t, 0.05)  # a motor driving it: its balance is not the coast's
    assert creep_rate_scale(t, psi, current, 0, len(t) - 1, 0.13, 1e-4, 2e-3, 0.24, 0.0) is None
