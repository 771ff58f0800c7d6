"""``spring_stiffening``: the torsion rod stiffens with twist, torque = -c (d + k3 d^3)."""

from __future__ import annotations

from dataclasses import dataclass

from addedinertia_env.sim.effects.registry import EffectSpec, FitRange, Param, register


@dataclass(frozen=True)
class SpringStiffening:
    """Parameters of ``spring_stiffening``: ``k3`` (1/rad^2) in the rod torque ``-c (d + k3 d^3)``, ``d = phi - phi_neutral``."""

    k3: float  # 1/rad^2, torque = -c (d + k3 d^3), d = phi - phi_neutral


def hull_torque(e, d, w, p):
    """The cubic part of the rod torque at twist ``d`` (rad from the true neutral); N m."""
    return -(p.spring.c * e.k3 * d**3)


def spring_energy(e, d, p):
    """The cubic part's energy at twist ``d`` (rad); J."""
    return 0.25 * p.spring.c * e.k3 * d**4


SPEC = register(EffectSpec(
    name="spring_stiffening",
    summary="the torsion rod stiffens with twist (cubic term)",
    params_type=SpringStiffening,
    params=(Param("k3", "1/rad^2", "relative cubic stiffness", realistic=(3.0, 10.0), neutral=0.0,
                  fit=FitRange(0.0, -100.0, 100.0, 1.0)),),
    size_param="k3",
    min_size=1.0,  # 1/rad^2: 1 % stiffening at 0.1 rad
    hull_torque=hull_torque,
    spring_energy=spring_energy,
))
