"""Closed-form and strip-theory estimates of lambda66 to set beside the BEM.

* **Lamb's ellipsoid** (Lamb, *Hydrodynamics*, art. 114-115): a body with semi-axes
  ``a`` (along x), ``b`` (along y), ``c`` (along z) turning about z in unbounded fluid has
  added inertia ``(1/5) m (a^2 - b^2)^2 (beta0 - alpha0) / [2 (a^2 - b^2) + (a^2 + b^2)(alpha0 - beta0)]``
  with ``m = 4/3 pi rho a b c`` and ``alpha0 = a b c integral_0^inf d lambda / ((a^2 + lambda) D)``,
  ``beta0`` the same with ``b^2``, ``D = sqrt((a^2+lambda)(b^2+lambda)(c^2+lambda))``. For
  ``b = c`` it is the prolate spheroid of :mod:`addedinertia_env.hydro.closed_forms`. A hull of
  length L, beam B and draft T is compared with the ellipsoid ``(L/2, B/2, T)``, the double
  body, halved for the free surface (physics.md section 6) -- Fedotov's triaxial
  ellipsoid (seed 002).
* **Strip theory** (zero frequency, rigid-lid free surface): each section of draft
  ``T(x)`` carries the sway added mass of half an ellipse (or flat plate) of half-height
  ``T(x)``, ``a22(x) = rho pi T(x)^2 / 2``, and ``lambda66 = integral x^2 a22(x) dx``. No
  three-dimensional end correction, so it over-predicts for short hulls.

Units: SI (m, kg/m^3); results in kg m^2.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import integrate

from addedinertia_env.hydro.geometry import HullShape
from addedinertia_env.hydro.water import RHO_WATER


def ellipsoid_coefficients(a: float, b: float, c: float) -> tuple[float, float]:
    """Lamb's ``alpha0`` (x axis, semi-axis a) and ``beta0`` (y axis, semi-axis b)."""
    def d(lam):
        return math.sqrt((a * a + lam) * (b * b + lam) * (c * c + lam))

    alpha0 = a * b * c * integrate.quad(lambda lam: 1.0 / ((a * a + lam) * d(lam)), 0.0, math.inf, limit=200)[0]
    beta0 = a * b * c * integrate.quad(lambda lam: 1.0 / ((b * b + lam) * d(lam)), 0.0, math.inf, limit=200)[0]
    return alpha0, beta0


def ellipsoid_yaw_added_inertia(a: float, b: float, c: float, rho: float = RHO_WATER) -> float:
    """Added inertia (kg m^2) of an ellipsoid (semi-axes a, b, c in m) turning about z in unbounded fluid."""
    if min(a, b, c) <= 0:
        raise ValueError(f"ellipsoid semi-axes {a}, {b}, {c}: expected all > 0 (m)")
    alpha0, beta0 = ellipsoid_coefficients(a, b, c)
    d = beta0 - alpha0
    m = 4.0 / 3.0 * math.pi * rho * a * b * c
    return 0.2 * m * (a * a - b * b) ** 2 * d / (2.0 * (a * a - b * b) - (a * a + b * b) * d)


def lamb_estimate(shape: HullShape, floating: bool = True, rho: float = RHO_WATER) -> float:
    """Lamb's ellipsoid (L/2, B/2, T) for the hull: halved when floating, whole when deep, kg m^2."""
    full = ellipsoid_yaw_added_inertia(0.5 * shape.length, 0.5 * shape.beam, float(shape.draft), rho)
    return 0.5 * full if floating else full


def section_draft(shape: HullShape, x: np.ndarray) -> np.ndarray:
    """Draft T(x) of the section at x (m): constant for the Wigley hull, the local radius for a spheroid."""
    x = np.asarray(x, dtype=float)
    if shape.shape == "wigley":
        return np.full_like(x, float(shape.draft))
    a, b = 0.5 * shape.length, 0.5 * shape.beam
    return b * np.sqrt(np.clip(1.0 - (x / a) ** 2, 0.0, None))


def strip_theory_estimate(shape: HullShape, rho: float = RHO_WATER, n: int = 2001) -> float:
    """Zero-frequency strip-theory lambda66 (kg m^2) of the floating hull: integral x^2 rho pi T(x)^2 / 2 dx."""
    x = np.linspace(-0.5 * shape.length, 0.5 * shape.length, n)
    a22 = 0.5 * rho * math.pi * section_draft(shape, x) ** 2
    return float(np.trapezoid(x * x * a22, x))
