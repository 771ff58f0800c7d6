"""Hydrodynamic numbers from closed forms: Lamb's prolate spheroid, the Wigley hull.

Sources: Lamb, *Hydrodynamics* (6th ed., 1932), art. 115 (the spheroid coefficients
``alpha0``, ``beta0`` and the rotational coefficient ``k'``); physics.md section 6 for the
half-body rule (the free surface acts as a rigid lid for horizontal motion at low
frequency, so a hull floating at its waterline gets half the double body's value) and the
Wigley numbers.
"""

from __future__ import annotations

import math

from addedinertia_env.hydro.water import RHO_WATER


def lamb_coefficients(e: float) -> tuple[float, float]:
    """Lamb's ``alpha0`` (along the axis) and ``beta0`` (across) for eccentricity ``e``."""
    if not 0.0 < e < 1.0:
        raise ValueError(f"eccentricity {e!r}: expected 0 < e < 1 (a prolate spheroid, a > b)")
    log = math.log((1.0 + e) / (1.0 - e))
    alpha0 = 2.0 * (1.0 - e * e) / e**3 * (0.5 * log - e)
    beta0 = 1.0 / (e * e) - (1.0 - e * e) / (2.0 * e**3) * log
    return alpha0, beta0


def lamb_rotation_coefficient(length_to_beam: float) -> float:
    """Lamb's ``k'``: added inertia for rotation about a transverse axis / displaced fluid's inertia.

    ``k' = e^4 (beta0 - alpha0) / ((2 - e^2) [2 e^2 - (2 - e^2)(beta0 - alpha0)])``.
    """
    if length_to_beam <= 1.0:
        raise ValueError(f"length/beam = {length_to_beam!r}: expected > 1 for a prolate spheroid")
    e = math.sqrt(1.0 - 1.0 / length_to_beam**2)
    alpha0, beta0 = lamb_coefficients(e)
    d = beta0 - alpha0
    return e**4 * d / ((2.0 - e * e) * (2.0 * e * e - (2.0 - e * e) * d))


def spheroid_displaced_yaw_inertia(a: float, b: float, immersed_fraction: float = 1.0,
                                   rho: float = RHO_WATER) -> float:
    """Yaw inertia of the fluid a spheroid displaces, ``m (a^2 + b^2) / 5``, kg m^2."""
    m = immersed_fraction * 4.0 / 3.0 * math.pi * rho * a * b * b
    return m * (a * a + b * b) / 5.0


def spheroid_added_yaw_inertia(length: float, beam: float, immersion: str = "half",
                               rho: float = RHO_WATER) -> float:
    """lambda66 of a prolate spheroid (``length = 2a``, ``beam = 2b``), kg m^2.

    ``immersion='full'``: deeply submerged; ``'half'``: floating with its axis in the
    waterline, half the double body (physics.md section 6).
    """
    fraction = {"full": 1.0, "half": 0.5}.get(immersion)
    if fraction is None:
        raise ValueError(f"immersion {immersion!r}: expected 'full' or 'half'")
    a, b = 0.5 * length, 0.5 * beam
    return lamb_rotation_coefficient(a / b) * spheroid_displaced_yaw_inertia(a, b, fraction, rho)


def quadratic_yaw_damping(length: float, draft: float, drag_coefficient: float, rho: float = RHO_WATER) -> float:
    """Cross-flow drag in yaw at zero speed: ``b2 = rho Cd T L^4 / 64``, N m s^2 (physics.md s6)."""
    return 0.5 * rho * drag_coefficient * draft * length**4 / 32.0
