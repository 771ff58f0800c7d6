"""Generalised forces of the rig beyond rigid-body inertia: the one source of truth.

Both engines (the MuJoCo model in :mod:`.mujoco_rig` and the batched model in
:mod:`.batched`) call these functions; they work on floats and on numpy arrays alike.

Split of the equations of motion (physics.md section 2)::

    [J_h + lambda66 + J_f   J_f] [phi'']   [-c (phi - phi_n) + Q_w + Q_b]
    [J_f                    J_f] [psi''] = [ k_t i - M_f(Omega)         ]

* inertia (mass matrix, with lambda66 as the hull joint's armature) and the *linear*
  torsion spring live in the engine, evaluated at every integrator stage;
* everything else (hydrodynamic damping with optional fluid memory, motor friction, and
  each hidden effect's terms, read from the effect registry ``effects/``) is computed here
  and held over one physics step.
"""

from __future__ import annotations

import numpy as np

from .effects.registry import active_params
from .friction import DRY_FRICTION_RATE_SCALE
from .params import RigParams

__all__ = ["DRY_FRICTION_RATE_SCALE", "channel_delay", "flywheel_friction_torque", "has_channel_delay",
           "has_water_memory", "hull_extra_torque", "hydrodynamic_torque", "kinetic_energy", "potential_energy",
           "torque_constant_ratio", "true_neutral", "true_torque_constant", "water_rate_after_rest", "water_rate_derivative"]


def _sum(hook: str, active, *args):
    """Sum of ``hook`` over the active effects (floats or arrays); ``None`` when none is on."""
    total = None
    for spec, e in active:
        term = getattr(spec, hook)(e, *args)
        total = term if total is None else total + term
    return total


def true_neutral(p: RigParams) -> float:
    """The torsion rod's real neutral angle, rad (calibrated value + hidden offsets)."""
    active = active_params(p.effects, "neutral_shift")
    shift = _sum("neutral_shift", active) if active else None
    return p.spring.phi_neutral + (shift if shift is not None else 0.0)


def torque_constant_ratio(p: RigParams):
    """True / data-sheet torque constant, - (1 without a torque-constant effect)."""
    ratio = None
    for spec, e in active_params(p.effects, "torque_ratio"):
        ratio = spec.torque_ratio(e) if ratio is None else ratio * spec.torque_ratio(e)
    return ratio if ratio is not None else 1.0


def true_torque_constant(p: RigParams) -> float:
    """The motor's real torque constant, N m/A (data sheet x hidden ratios)."""
    return p.motor.k_t * torque_constant_ratio(p)


def channel_delay(p: RigParams):
    """Lag of the current and voltage channel behind the encoders, s (0 without a delay effect)."""
    delay = _sum("channel_delay", active_params(p.effects, "channel_delay"))
    return delay if delay is not None else 0.0


def has_channel_delay(p: RigParams) -> bool:
    """Whether any effect delays the current and voltage channel."""
    return bool(active_params(p.effects, "channel_delay"))


def has_water_memory(p: RigParams) -> bool:
    """Whether any effect carries a water-rate state (the engines then integrate it)."""
    return bool(active_params(p.effects, "water_rate_derivative"))


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
    """All hull torques not native to the engine (everything but the linear spring), N m:
    the damping and each active effect's ``hull_torque``."""
    q = hydrodynamic_torque(w, water_rate, p)
    active = active_params(p.effects, "hull_torque")
    if active:
        d = phi - true_neutral(p)
        for spec, e in active:
            q = q + spec.hull_torque(e, d, w, p)
    return q


def flywheel_friction_torque(omega, p: RigParams):
    """Rotor bearing friction acting on the flywheel (relative to the hull), N m."""
    m = p.motor
    return -m.friction_viscous * omega - m.friction_coulomb * np.tanh(omega / (10 * DRY_FRICTION_RATE_SCALE))


def water_rate_derivative(w, water_rate, p: RigParams):
    """d(water_rate)/dt, rad/s^2, of the effects with a water state (physics.md section 6); 0 when off."""
    active = active_params(p.effects, "water_rate_derivative")
    if not active:
        return 0.0 * water_rate
    return _sum("water_rate_derivative", active, w, water_rate)


def water_rate_after_rest(water_rate, seconds, p: RigParams):
    """The water rate, rad/s, after ``seconds`` with the hull held still (the brake hold)."""
    for spec, e in active_params(p.effects, "water_rate_after_rest"):
        water_rate = spec.water_rate_after_rest(e, water_rate, seconds)
    return water_rate


def potential_energy(phi, p: RigParams):
    """Torsion rod energy, J (including hidden stiffening)."""
    d = phi - true_neutral(p)
    e = 0.5 * p.spring.c * d**2
    for spec, eff in active_params(p.effects, "spring_energy"):
        e = e + spec.spring_energy(eff, d, p)
    return e


def kinetic_energy(w, omega, p: RigParams):
    """Hull (with added inertia) + flywheel kinetic energy, J."""
    return 0.5 * (p.hull.J_hull + p.hull.lambda66) * w**2 + 0.5 * p.motor.J_flywheel * (w + omega) ** 2
