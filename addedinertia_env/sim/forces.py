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

Radiation memory (the optional ``cummins`` hydrodynamic model, :mod:`.radiation`; not a
hidden effect) is a vector state ``x`` per rig: the armature becomes ``A66(inf)``
(:func:`hull_armature`) and the hull feels ``-mu`` with ``mu`` the step's mean memory
moment from :func:`radiation_memory_step` (exact for the hull rate held at the step's
centred value), held over the step like the other torques.
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.sim.effects.registry import active_params
from addedinertia_env.sim.friction import DRY_FRICTION_RATE_SCALE
from addedinertia_env.sim.params import RigParams
from addedinertia_env.hydro.radiation import step_maps, truth_block

__all__ = ["DRY_FRICTION_RATE_SCALE", "channel_delay", "cogging_energy", "drive_torque", "driver_lag", "gear_ratio",
           "has_backlash", "has_drive_torque", "has_driver_lag", "flywheel_friction_torque", "has_channel_delay",
           "has_radiation_memory", "has_water_memory", "hull_armature", "hull_extra_torque", "radiation_energy",
           "radiation_memory_step", "radiation_state_size", "true_lambda66", "truth", "hydrodynamic_torque", "kinetic_energy", "potential_energy",
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


def gear_ratio(p: RigParams):
    """Motor turns per flywheel turn, - (1 without a drive block: direct drive)."""
    drive = getattr(p, "drive", None)
    return 1.0 if drive is None else drive.gear_ratio


def true_torque_constant(p: RigParams) -> float:
    """The motor's real torque per ampere at the flywheel, N m/A (data sheet x hidden ratios x gear ratio;
    also the back-EMF per flywheel rad/s)."""
    return p.motor.k_t * gear_ratio(p) * torque_constant_ratio(p)


def has_drive_torque(p: RigParams) -> bool:
    """Whether the drive puts a torque of its own on the flywheel (mesh friction, gear drag, cogging;
    :mod:`.drive`): the engines then add :func:`drive_torque` to the rotor friction."""
    d = getattr(p, "drive", None)
    if d is None:
        return False
    return bool(np.any(np.asarray(d.gear_efficiency) < 1.0) or np.any(np.asarray(d.gear_drag) > 0)
                or np.any(np.asarray(d.cogging_torque) > 0))


def has_backlash(p: RigParams) -> bool:
    """Whether the gearbox has a gap (``drive.backlash`` > 0): the engines then run the rotor in the
    gap (:func:`~.drive.backlash_step`) and its relative rate in the back-EMF."""
    d = getattr(p, "drive", None)
    return d is not None and bool(np.any(np.asarray(d.backlash) > 0))


def backlash_inertia(p: RigParams):
    """The rotor's inertia at the flywheel, ``N^2 J_rotor``, kg m^2 (scalar or per environment)."""
    d = p.drive
    return np.asarray(d.gear_ratio, dtype=float) ** 2 * np.asarray(d.rotor_inertia, dtype=float)


def has_driver_lag(p: RigParams) -> bool:
    """Whether the current driver has a bandwidth of its own (``drive.driver_time_constant`` > 0)."""
    d = getattr(p, "drive", None)
    return d is not None and bool(np.any(np.asarray(d.driver_time_constant) > 0))


def driver_lag(p: RigParams):
    """The current loop's decay over one sample, ``exp(-sample_dt / tau)``, - (0: the dead-beat loop)."""
    tau = np.asarray(p.drive.driver_time_constant, dtype=float)
    dt = 1.0 / float(getattr(p, "sample_rate", None) or p.sensors.sample_rate)
    with np.errstate(divide="ignore"):
        lag = np.where(tau > 0, np.exp(-dt / np.where(tau > 0, tau, 1.0)), 0.0)
    return float(lag) if lag.ndim == 0 else lag


def drive_torque(psi, omega, i, k_t, p: RigParams):
    """The drive's own torque on the flywheel (relative to the hull), N m (:mod:`.drive`).

    ``psi`` rad and ``omega`` rad/s: the flywheel relative to the hull; ``i`` A, the current
    held over the step; ``k_t`` N m/A at the flywheel (:func:`true_torque_constant`).
    Cogging ``N T_c sin(n N psi + phase)`` (``N`` the gear ratio, ``T_c`` at the motor shaft:
    conservative, its potential ``T_c cos(n N psi + phase) / n``); the gearbox's mesh friction
    ``(1 - efficiency) |k_t i|`` and no-load drag against the relative motion, smoothed as the
    rotor's dry friction (:func:`flywheel_friction_torque`).
    """
    d = p.drive
    n = d.gear_ratio
    cog = n * d.cogging_torque * np.sin(d.cogging_periods * n * psi + d.cogging_phase)
    loss = (1.0 - d.gear_efficiency) * np.abs(k_t * i) + d.gear_drag
    return cog - loss * np.tanh(omega / (10 * DRY_FRICTION_RATE_SCALE))


def cogging_energy(psi, p: RigParams):
    """The cogging potential at flywheel angle ``psi`` (rad), J: ``T_c cos(n N psi + phase) / n`` (0 without cogging)."""
    d = getattr(p, "drive", None)
    if d is None or not np.any(np.asarray(d.cogging_torque) > 0):
        return 0.0 * psi
    return d.cogging_torque * np.cos(d.cogging_periods * d.gear_ratio * psi + d.cogging_phase) / d.cogging_periods


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


def has_radiation_memory(p: RigParams) -> bool:
    """Whether the rig's water has Cummins radiation memory (the ``cummins`` hydrodynamic model)."""
    return getattr(p, "hydrodynamics", None) is not None


def hull_armature(p: RigParams):
    """The added inertia in the hull joint's mass matrix, kg m^2: lambda66 with the constant model,
    ``A66(inf) = lambda66 A66(inf)/A66(0)`` with radiation memory (lambda66 being A66(0))."""
    model = getattr(p, "hydrodynamics", None)
    return p.hull.lambda66 if model is None else p.hull.lambda66 * model.a_inf_ratio


def radiation_state_size(p: RigParams) -> int:
    """Length of the radiation-memory state per rig (0 without memory)."""
    model = getattr(p, "hydrodynamics", None)
    return 0 if model is None else model.order


def radiation_memory_step(x, w, p: RigParams):
    """One physics step of the radiation memory: ``(x_new, mu)``.

    ``x``: state (rad), shape ``(n,)`` or ``(n, envs)``; ``w``: hull rate held over the step
    (rad/s; the centred rate), scalar or ``(envs,)``. ``mu`` (N m) is the memory moment's
    mean over the step (the hull feels ``-mu``); ``x_new`` the state at the step's end.
    Exact for ``w`` held (the maps of :func:`.radiation.step_maps`).
    """
    Phi, Gam, cbar, dbar = step_maps(p.hydrodynamics, float(p.physics_dt))
    if np.ndim(x) == 2:
        x_new = Phi @ x + Gam[:, None] * w
    else:
        x_new = Phi @ x + Gam * w
    mu = p.hull.lambda66 * (cbar @ x + dbar * w)
    return x_new, mu


def radiation_energy(x, p: RigParams):
    """Energy stored in the radiation memory, J: ``lambda66 x'Px / 2`` (the fit's storage
    function, :func:`addedinertia_env.hydro.memory_fit.storage_matrix`); 0 without memory."""
    model = getattr(p, "hydrodynamics", None)
    if model is None:
        return 0.0
    P = np.asarray(model.P)
    x = np.asarray(x, dtype=float)
    return 0.5 * p.hull.lambda66 * np.einsum("i...,ij,j...->...", x, P, x)


def potential_energy(phi, p: RigParams):
    """Torsion rod energy, J (including hidden stiffening)."""
    d = phi - true_neutral(p)
    e = 0.5 * p.spring.c * d**2
    for spec, eff in active_params(p.effects, "spring_energy"):
        e = e + spec.spring_energy(eff, d, p)
    return e


def kinetic_energy(w, omega, p: RigParams):
    """Hull (with its armature, :func:`hull_armature`) + flywheel kinetic energy, J; with radiation
    memory the water's share beyond A66(inf) is :func:`radiation_energy`."""
    return 0.5 * (p.hull.J_hull + hull_armature(p)) * w**2 + 0.5 * p.motor.J_flywheel * (w + omega) ** 2


def truth(p: RigParams, k_t: float) -> dict:
    """A simulated rig's run-record ``truth`` block (scoring only; every engine gives the same).

    ``lambda66`` is A66(0) (spec/run-record.md); with radiation memory ``A66_swing``,
    ``A66_inf`` and a ``hydrodynamics`` block stand beside it (:func:`.radiation.truth_block`).
    """
    h = p.hull
    out = {"lambda66": h.lambda66, "effects": p.effects.to_dict(), "damping": {"b1": h.b1, "b2": h.b2},
           "k_t": k_t, "phi_neutral": true_neutral(p)}
    drive = getattr(p, "drive", None)
    if drive is not None and not drive.ideal:
        out["drive"] = drive.to_dict()
    model = getattr(p, "hydrodynamics", None)
    if model is not None:
        out.update(truth_block(h.J_hull, h.lambda66, p.spring.c, model))
    return out


def true_lambda66(p: RigParams) -> float:
    """The lambda66 a run on this rig is scored against, kg m^2: A66(0), the hull's lambda66,
    with or without radiation memory (spec/run-record.md; :func:`.radiation.truth_block`)."""
    return float(p.hull.lambda66)
