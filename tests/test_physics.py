"""Physics of the simulated rig (MujocoRig), checked against physics, not against itself.

Every check uses the simulator's own bookkeeping (``TrueState``) or an independent
integration of the equations of physics.md section 2; every tolerance is stated where
it is used, with the reason for its size. Simulations are short (a few seconds of rig
time, about 0.1 ms of CPU per sample).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid, solve_ivp

from addedinertia_env.sim.effects import (
    BearingCoulomb,
    Effects,
    FluidMemory,
    NeutralOffset,
    SensorDelay,
    SpringStiffening,
    TorqueConstant,
)
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams, SensorParams

PASSIVE = MotorCommand("passive")
FIELDS = ("t", "phi", "w", "psi", "omega", "i", "u", "water_rate", "energy", "motor_work", "dissipated_hull",
          "dissipated_flywheel", "electric_energy", "ohmic_loss")


def ideal_rig(**changes) -> RigParams:
    """The default rig (physics.md section 7) with ideal sensors, plus ``changes``."""
    return RigParams(sensors=SensorParams.ideal()).replace(**changes)


def without_damping(p: RigParams) -> RigParams:
    """No hydrodynamic damping and no rotor-bearing friction: nothing dissipates."""
    return p.replace(hull=dataclasses.replace(p.hull, b1=0.0, b2=0.0),
                     motor=dataclasses.replace(p.motor, friction_viscous=0.0, friction_coulomb=0.0))


def simulate(p: RigParams, seconds: float, command=lambda t: PASSIVE, phi0: float = -0.1, omega0: float = 0.0,
             brake: bool = False) -> dict[str, np.ndarray]:
    """Run the rig for ``seconds``; every TrueState field and the readings, one row per sample."""
    rig = MujocoRig(p, seed=0)
    readings = [rig.reset(phi0=phi0, omega0=omega0, brake=brake)]
    states = [rig.true_state()]
    for k in range(int(round(seconds / rig.dt))):
        readings.append(rig.step(command(k * rig.dt)))
        states.append(rig.true_state())
    out = {f: np.array([getattr(s, f) for s in states]) for f in FIELDS}
    out["read_phi"] = np.array([r.phi for r in readings])
    out["read_i"] = np.array([r.i for r in readings])
    out["read_u"] = np.array([r.u for r in readings])
    return out


def sinusoidal_current(amplitude: float = 8.0, frequency: float = 1.3, bias: float = 0.0):
    return lambda t: MotorCommand("current", bias + amplitude * math.sin(2 * math.pi * frequency * t))


def angular_momentum(p: RigParams, s: dict[str, np.ndarray]) -> np.ndarray:
    """Hull + flywheel angular momentum about the yaw axis, (J_h + lambda66) w + J_f (w + Omega)."""
    return (p.hull.J_hull + p.hull.lambda66) * s["w"] + p.motor.J_flywheel * (s["w"] + s["omega"])


def extremes(x: np.ndarray) -> np.ndarray:
    """Values of ``x`` at its interior turning points."""
    k = np.nonzero((x[1:-1] - x[:-2]) * (x[2:] - x[1:-1]) < 0)[0] + 1
    return x[k]


def zero_crossings(t: np.ndarray, x: np.ndarray, level: float = 0.0) -> np.ndarray:
    """Times where ``x`` crosses ``level`` (either way), linearly interpolated between samples."""
    k = np.nonzero(np.signbit(x[:-1] - level) != np.signbit(x[1:] - level))[0]
    return t[k] + (level - x[k]) * (t[k + 1] - t[k]) / (x[k + 1] - x[k])


def swing_period(p: RigParams, amplitude: float) -> float:
    """Period of an undamped swing released at ``-amplitude``: twice the time between the
    first two neutral crossings (exact for any odd restoring law), s."""
    s = simulate(p, 0.8 * p.natural_period, phi0=p.spring.phi_neutral - amplitude)
    crossings = zero_crossings(s["t"], s["phi"], p.spring.phi_neutral)
    assert len(crossings) == 2
    return 2.0 * float(crossings[1] - crossings[0])


# --- energy and angular momentum -------------------------------------------------------

def test_energy_is_conserved_without_damping_motor_passive():
    p = without_damping(ideal_rig())
    s = simulate(p, 2 * p.natural_period, omega0=5.0)  # two periods, flywheel spinning freely
    drift = np.max(np.abs(s["energy"] - s["energy"][0]))
    # RK4's local energy error is about (w h)^5 E = (1.6 rad/s x 0.5 ms)^5 E ~ 3e-16 E per
    # step; 16000 steps stay far under 1e-9 E. A missing or doubled term (a coupling, a
    # friction left on) would change E by whole percents.
    assert drift < 1e-9 * s["energy"][0], drift
    assert np.all(s["motor_work"] == 0.0) and np.all(s["electric_energy"] == 0.0)  # passive: no electric work


@pytest.fixture(scope="module")
def driven_undamped():
    """6 s of a sinusoidal motor current on the undamped rig (a few swings of the hull)."""
    p = without_damping(ideal_rig())
    return p, simulate(p, 6.0, sinusoidal_current())


def test_motor_cannot_change_total_angular_momentum(driven_undamped):
    p, s = driven_undamped
    H = angular_momentum(p, s)
    spring_impulse = cumulative_trapezoid(-p.spring.c * (s["phi"] - p.spring.phi_neutral), s["t"], initial=0.0)
    motor_impulse = float(np.trapezoid(np.abs(p.motor.k_t * s["i"]), s["t"]))
    hull_momentum = (p.hull.J_hull + p.hull.lambda66) * s["w"]
    # The trapezoid rule on 1 ms samples integrates the spring torque to about
    # T c |phi''| h^2 / 12 = 6 s x 43.4 x 0.2 x 1e-6 / 12 ~ 4e-6 N m s. The motor's own
    # angular impulse is ~8 N m s: had it leaked onto the total, the error would be O(1).
    assert motor_impulse > 5.0
    assert np.max(np.abs(H - H[0] - spring_impulse)) < 2e-5
    # ... while the motor does move momentum between hull and flywheel (the test can fail):
    assert np.max(np.abs(hull_momentum - hull_momentum[0] - spring_impulse)) > 0.1


def test_energy_change_equals_motor_work_without_damping(driven_undamped):
    p, s = driven_undamped
    # The torque k_t <i> is held over each 0.5 ms step, so its work k_t <i> dpsi is exact;
    # the spring is integrated by RK4 (error ~1e-14 J here). 1e-8 J is 1e-8 of the work done.
    assert np.max(np.abs(s["motor_work"])) > 0.5
    assert np.max(np.abs(s["energy"] - s["energy"][0] - s["motor_work"])) < 1e-8
    # Sign convention: motor_work = integral(k_t i Omega dt) (positive when the motor drives
    # the flywheel's relative motion). Inside each sample the current is an exponential, not
    # the straight line of the trapezoid rule: they agree to ~1 %; a flipped sign is 200 %.
    work = cumulative_trapezoid(p.motor.k_t * s["i"] * s["omega"], s["t"], initial=0.0)
    assert np.max(np.abs(work - s["motor_work"])) < 2e-2 * np.max(np.abs(s["motor_work"]))


def test_electric_energy_is_ohmic_loss_plus_motor_work_plus_magnetic_energy(driven_undamped):
    p, s = driven_undamped
    magnetic = 0.5 * p.motor.L * (s["i"] ** 2 - s["i"][0] ** 2)
    residual = s["electric_energy"] - s["ohmic_loss"] - s["motor_work"] - magnetic
    # u i = R i^2 + d(L i^2/2)/dt + k_t i Omega holds exactly for the exponential current
    # update when Omega is the step's mean; MuJoCo's mean Omega is predicted to O(h^2), leaving
    # ~1e-6 J after 6 s. Holding Omega at the step start instead costs k_t i Omega' h/2 per
    # step, ~0.03 J here (2.5 % of the motor work): the test tells the two apart.
    assert np.max(np.abs(residual)) < 2e-5
    assert np.all(np.diff(s["ohmic_loss"]) >= 0.0)  # R i^2 >= 0: losses only grow
    assert s["ohmic_loss"][-1] > 0.0 and s["electric_energy"][-1] > s["motor_work"][-1]


def test_energy_balance_with_damping_and_friction():
    eff = Effects(bearing_coulomb=BearingCoulomb(0.05), fluid_memory=FluidMemory(tau=10.0, beta=0.2))
    p = ideal_rig(effects=eff)
    s = simulate(p, 4.0, sinusoidal_current(bias=2.0))
    balance = s["motor_work"] + s["dissipated_hull"] + s["dissipated_flywheel"]
    # Non-spring torques are held over each step, so their work (torque x increment) is
    # exact; the remainder is RK4's error on the spring (~1e-14 J).
    assert np.max(np.abs(s["energy"] - s["energy"][0] - balance)) < 1e-8
    assert s["dissipated_hull"][-1] < -0.05  # damping and dry friction take energy out
    assert s["dissipated_flywheel"][-1] < 0.0
    assert np.all(np.diff(s["dissipated_flywheel"]) <= 1e-15)  # rotor friction never gives energy


# --- period, independent integration, brake ------------------------------------------

def test_undamped_free_decay_period_with_free_flywheel():
    p = without_damping(ideal_rig())
    period = swing_period(p, 0.1)
    locked = 2 * math.pi * math.sqrt(p.J_total / p.spring.c)
    # Zero crossings are where phi'' = 0, so linear interpolation is exact to O(h^3);
    # RK4's phase error is ~(w h)^4 / 120 per radian. 1e-6 relative is far below the
    # 0.3 % between a free and a locked flywheel, which the test must tell apart.
    assert abs(period / p.natural_period - 1.0) < 1e-6
    assert abs(locked / p.natural_period - 1.0) > 1e-3
    # The free flywheel keeps its inertial orientation: w + Omega stays at its start value 0.
    s = simulate(p, 1.0)
    assert np.max(np.abs(s["w"])) > 0.05 and np.max(np.abs(s["w"] + s["omega"])) < 1e-12


def _equations_of_motion(p: RigParams):
    """physics.md section 2, written out: state (phi, w, psi, Omega, i), voltage u held."""
    J, J_f, m = p.hull.J_hull + p.hull.lambda66, p.motor.J_flywheel, p.motor
    dry_scale = 0.01  # rad/s: the rotor's dry friction is smoothed as f_c tanh(Omega / 0.01)

    def rhs(t, y, u):
        phi, w, psi, omega, i = y
        hull = -p.spring.c * (phi - p.spring.phi_neutral) - p.hull.b1 * w - p.hull.b2 * w * abs(w)
        rotor = m.k_t * i - m.friction_viscous * omega - m.friction_coulomb * math.tanh(omega / dry_scale)
        # [J + J_f, J_f; J_f, J_f] [phi''; psi''] = [hull; rotor]
        phi_acc = (hull - rotor) / J
        psi_acc = rotor / J_f - phi_acc
        return [w, phi_acc, omega, psi_acc, (u - m.R * i - m.k_t * omega) / m.L]

    return rhs


def test_mujoco_agrees_with_an_independent_integration():
    p = ideal_rig()  # damping (b1, b2) and rotor friction on
    seconds = 1.0
    s2 = simulate(p, seconds, sinusoidal_current(amplitude=6.0, frequency=0.7, bias=2.0))
    # Same input for the ODE: the terminal voltage the drive held over each sample.
    rhs = _equations_of_motion(p)
    y = np.array([s2["phi"][0], s2["w"][0], s2["psi"][0], s2["omega"][0], 0.0])
    ode = [y]
    for k in range(len(s2["t"]) - 1):
        sol = solve_ivp(rhs, (s2["t"][k], s2["t"][k + 1]), y, method="DOP853", rtol=1e-10, atol=1e-12,
                        args=(s2["u"][k + 1],))
        y = sol.y[:, -1]
        ode.append(y)
    ode = np.array(ode)
    # The same voltages replayed with twice the physics sub-steps.
    volts = s2["u"]
    s4 = simulate(p.replace(physics_substeps=4), seconds,
                  lambda t: MotorCommand("voltage", float(volts[int(round(t / p.sensors.dt)) + 1])))
    names = ("phi", "w", "psi", "omega", "i")
    err2 = {n: float(np.max(np.abs(s2[n] - ode[:, k]))) for k, n in enumerate(names)}
    err4 = {n: float(np.max(np.abs(s4[n] - ode[:, k]))) for k, n in enumerate(names)}
    # MuJoCo holds damping, friction and motor torque over each 0.5 ms step (a lag of h/2
    # in forces of ~1 N m changing at ~10 N m/s): ~1e-6 rad and rad/s after 1 s. Bounds
    # are a few times that and well under one 17-bit hull count (4.8e-5 rad); the current
    # bound is a tenth of the 10 mA current-sensor noise (physics.md section 7).
    bounds = {"phi": 2e-5, "w": 2e-5, "psi": 2e-5, "omega": 5e-5, "i": 1e-3}
    for n in names:
        assert err2[n] < bounds[n], (n, err2[n])
    # The disagreement is discretisation, not a model difference: it shrinks with the step.
    for n in ("phi", "w", "i"):
        assert err4[n] < 0.7 * err2[n], (n, err2[n], err4[n])


def test_brake_holds_the_hull_while_the_motor_spins_the_flywheel():
    p = ideal_rig()
    square = lambda t: MotorCommand("current", 10.0 if int(t) % 2 == 0 else -10.0)  # noqa: E731
    s = simulate(p, 3.0, square, phi0=-0.1, brake=True)
    # The motor reaction (2.5 N m) and the twisted rod (4.3 N m) push on the brake; the
    # flywheel reaches ~25 rad/s. A 1e-7 rad bound is 1/500 of a 17-bit hull count.
    assert np.max(np.abs(s["omega"])) > 20.0
    assert np.max(np.abs(s["phi"] + 0.1)) < 1e-7
    assert abs(s["phi"][-1] - s["phi"][1000]) < 1e-9  # no creep from 1 s to 3 s


# --- hidden effects (physics.md section 8) ----------------------------------------------

def _decay_centres(phi: np.ndarray) -> np.ndarray:
    """Centre of a decaying swing from three successive extremes, (x1 + 2 x2 + x3) / 4."""
    x = extremes(phi)
    return (x[:-2] + 2.0 * x[1:-1] + x[2:]) / 4.0


def test_neutral_offset_shifts_the_decay_centre():
    offset = 0.01
    plain = _decay_centres(simulate(ideal_rig(), 6.5)["read_phi"])
    offset_rig = ideal_rig(effects=Effects(neutral_offset=NeutralOffset(offset)))
    shifted = _decay_centres(simulate(offset_rig, 6.5)["read_phi"])
    # The three-extreme centre removes a decrement that changes linearly; the quadratic
    # damping's curvature leaves < 1 mrad. The offset (10 mrad) moves the centre by itself.
    assert len(plain) >= 1 and len(shifted) >= 1
    assert np.all(np.abs(plain) < 1e-3)
    assert np.all(np.abs(shifted - plain - offset) < 1e-3)


def test_spring_stiffening_shortens_the_period_at_large_amplitude():
    k3 = 8.0
    p = without_damping(ideal_rig(effects=Effects(spring_stiffening=SpringStiffening(k3))))
    periods = {amplitude: swing_period(p, amplitude) for amplitude in (0.02, 0.1)}
    for amplitude, period in periods.items():
        # Duffing oscillator to first order (Lindstedt): w^2 = w0^2 (1 + 3/4 k3 A^2); the
        # next order is (k3 A^2)^2 ~ 0.006 of the shift at A = 0.1 rad: 1e-4 relative.
        expected = 1.0 / math.sqrt(1.0 + 0.75 * k3 * amplitude**2)
        assert abs(period / p.natural_period - expected) < 2e-4, amplitude
    assert periods[0.1] < 0.98 * periods[0.02]


def test_torque_constant_scales_the_motor_torque():
    def torque_scale(effects: Effects) -> float:
        # Hull braked, constant current: J_f Omega' = k_t_true i (rotor friction off).
        p = without_damping(ideal_rig(effects=effects))
        s = simulate(p, 0.5, lambda t: MotorCommand("current", 5.0), brake=True)
        impulse = p.motor.k_t * np.trapezoid(s["read_i"], s["t"])  # data-sheet k_t, measured current
        return p.motor.J_flywheel * (s["omega"][-1] + s["w"][-1] - s["omega"][0]) / impulse

    nominal = torque_scale(Effects())
    scaled = torque_scale(Effects(torque_constant=TorqueConstant(1.06)))
    # The trapezoid rule misses the first sample's current ramp (~2e-4 relative, same in both).
    assert abs(nominal - 1.0) < 1e-3
    assert abs(scaled / nominal - 1.06) < 1e-4


@pytest.mark.parametrize("delay", [0.0, 0.0065])
def test_sensor_delay_delays_the_current_channel(delay):
    eff = Effects(sensor_delay=SensorDelay(delay)) if delay else Effects()
    s = simulate(ideal_rig(effects=eff), 0.6, sinusoidal_current(amplitude=5.0, frequency=3.0), brake=False)
    t = s["t"]
    lags = np.arange(0.0, 0.015, 1e-4)
    misfit = [np.sum((np.interp(t[50:] - lag, t, s["i"]) - s["read_i"][50:]) ** 2) for lag in lags]
    best = lags[int(np.argmin(misfit))]
    # The channel is delayed by linear interpolation in the sample history, so the best lag
    # on a 0.1 ms grid is the delay itself; the encoders are not delayed.
    assert abs(best - delay) < 1.5e-4
    assert np.max(np.abs(s["read_phi"] - s["phi"])) == 0.0
    lagged_u = np.interp(t[50:] - delay, t, s["u"])
    assert np.max(np.abs(lagged_u - s["read_u"][50:])) < 1e-9 * np.max(np.abs(s["u"]))


def test_bearing_coulomb_gives_a_constant_amplitude_decrement():
    torque = 0.05
    p = without_damping(ideal_rig(effects=Effects(bearing_coulomb=BearingCoulomb(torque))))
    s = simulate(p, 6.5, phi0=-0.1)
    decrement = -np.diff(np.abs(np.concatenate([[s["phi"][0]], extremes(s["phi"])])))
    # Dry friction T takes 2 T / c off each half swing whatever the amplitude (here from
    # 0.1 rad down to 0.093 rad); the tanh smoothing (below 1e-3 rad/s) acts only near the
    # turning points: < 1 % of it. Linear damping would shrink the decrement with the
    # amplitude, by 7 % over these swings.
    assert len(decrement) == 3
    assert np.all(np.abs(decrement / (2 * torque / p.spring.c) - 1.0) < 0.01)


def test_fluid_memory_makes_the_water_rate_follow_the_hull():
    tau, beta = 10.0, 0.2
    s = simulate(ideal_rig(effects=Effects(fluid_memory=FluidMemory(tau=tau, beta=beta))), 3.0)
    # r' = (beta w - r) / tau, r(0) = 0: r(t) = integral beta w(s) exp(-(t - s)/tau) ds / tau.
    t, w = s["t"], s["w"]
    expected = np.array([np.trapezoid(beta * w[:k + 1] * np.exp(-(t[k] - t[:k + 1]) / tau), t[:k + 1]) / tau
                         for k in range(0, len(t), 100)])
    got = s["water_rate"][::100]
    # Explicit Euler on r with h = 0.5 ms: relative error ~ h / tau plus the trapezoid's.
    assert np.max(np.abs(got)) > 1e-3
    assert np.max(np.abs(got - expected)) < 1e-3 * np.max(np.abs(expected))
    assert np.all(simulate(ideal_rig(), 0.5)["water_rate"] == 0.0)  # off by default
