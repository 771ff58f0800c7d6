"""Generalised forces of the rig beyond rigid-body inertia: the one source of truth.

Both engines (the MuJoCo model in :mod:`.mujoco_rig` and the batched model in
:mod:`.batched`) call these functions; they work on floats and on numpy arrays alike.

Split of the equations of motion (physics.md section 2)::

    [J_h + lambda66 + J_f   J_f] [phi'']   [-c (phi - phi_n) + Q_w + Q_b]
    [J_f                    J_f] [psi''] = [ k_t i - M_f(Omega)         ]

* inertia (mass matrix, with lambda66 as the hull joint's armature) and the *linear*
  torsion spring live in the engine, evaluated at every integrator stage;
* everything else (hydrodynamic damping with optional fluid memory, bearing and motor
  friction, spring stiffening) is computed here and held over one physics step.
"""

from __future__ import annotations

import numpy as np

from .params import RigParams

# Smoothing rate scale for dry friction, rad/s. Below this speed the friction torque is
# proportional to speed; 1e-3 rad/s is well under one hull-encoder count per 50 ms.
DRY_FRICTION_RATE_SCALE = 1e-3


def true_neutral(p: RigParams) -> float:
    """The torsion rod's real neutral angle, rad (calibrated value + hidden offset)."""
    off = p.effects.neutral_offset
    return p.spring.phi_neutral + (off.offset if off is not None else 0.0)


def true_torque_constant(p: RigParams) -> float:
    """The motor's real torque constant, N m/A (data sheet x hidden ratio)."""
    tc = p.effects.torque_constant
    return p.motor.k_t * (tc.ratio if tc is not None else 1.0)


def centred_rate(w, w_prev):
    """The hull rate at the middle of the coming physics step, rad/s, extrapolated from the
    rate now (``w``) and one step ago (``w_prev``).

    The torques here are held over a physics step. Evaluated at the step's start, a damping
    torque lags the motion by half a step: a decelerating stroke then dissipates more than
    its exact mirror (the accelerating reverse stroke), a false asymmetry of about 0.02 % of
    lambda66 in the energy method at 2 substeps per 1 ms sample. Evaluated at the step's
    middle, the lag is gone to second order.
    """
    return 1.5 * w - 0.5 * w_prev


def hydrodynamic_torque(w, water_rate, p: RigParams):
    """Linear + quadratic damping on the hull's rate relative to the water, N m."""
    v = w - water_rate
    return -p.hull.b1 * v - p.hull.b2 * v * np.abs(v)


def hull_extra_torque(phi, w, water_rate, p: RigParams):
    """All hull torques not native to the engine (everything but the linear spring), N m."""
    q = hydrodynamic_torque(w, water_rate, p)
    bc = p.effects.bearing_coulomb
    if bc is not None:
        q = q - bc.torque * np.tanh(w / DRY_FRICTION_RATE_SCALE)
    st = p.effects.spring_stiffening
    if st is not None:
        d = phi - true_neutral(p)
        q = q - p.spring.c * st.k3 * d**3
    return q


def flywheel_friction_torque(omega, p: RigParams):
    """Rotor bearing friction acting on the flywheel (relative to the hull), N m."""
    m = p.motor
    return -m.friction_viscous * omega - m.friction_coulomb * np.tanh(omega / (10 * DRY_FRICTION_RATE_SCALE))


def water_rate_derivative(w, water_rate, p: RigParams):
    """d(water_rate)/dt of the fluid-memory model (physics.md section 6); 0 when off."""
    fm = p.effects.fluid_memory
    if fm is None:
        return 0.0 * water_rate
    return (fm.beta * w - water_rate) / fm.tau


def potential_energy(phi, p: RigParams):
    """Torsion rod energy, J (including hidden stiffening)."""
    d = phi - true_neutral(p)
    e = 0.5 * p.spring.c * d**2
    st = p.effects.spring_stiffening
    if st is not None:
        e = e + 0.25 * p.spring.c * st.k3 * d**4
    return e


def kinetic_energy(w, omega, p: RigParams):
    """Hull (with added inertia) + flywheel kinetic energy, J."""
    return 0.5 * (p.hull.J_hull + p.hull.lambda66) * w**2 + 0.5 * p.motor.J_flywheel * (w + omega) ** 2
