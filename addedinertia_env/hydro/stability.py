"""Course stability of the ship from its added masses: the linear sway-yaw model.

The number the rig measures, lambda66, is the yaw inertia of every manoeuvring model
(Fedotov 2003, seed 002). Here it is put to that use. With the sway velocity ``v`` and
yaw rate ``r`` of a ship at speed ``U`` (centre of gravity amidships, controls fixed):

    (m + lambda22) v' + lambda26 r' - Y_v v + (m U - Y_r) r = 0
    lambda26 v' + (I_z + lambda66) r' - N_v v - N_r r = 0

The added masses ``lambda22 = -Y_v'``, ``lambda26 = -Y_r' = -N_v'``, ``lambda66 = -N_r'`` come
from the BEM at zero frequency (rigid-lid free surface, the manoeuvring limit). The
velocity derivatives ``Y_v, Y_r, N_v, N_r`` come from the regression of Clarke, Gedling and
Hine (1983), *The application of manoeuvring criteria in hull design using linear theory*,
Trans. RINA 125, 45-68, for a hull of length L, beam B, draft T and block coefficient C_B:

    Y_v' = -pi (T/L)^2 (1 + 0.40 C_B B/T)          Y_r' = -pi (T/L)^2 (-1/2 + 2.2 B/L - 0.080 B/T)
    N_v' = -pi (T/L)^2 (1/2 + 2.4 T/L)             N_r' = -pi (T/L)^2 (1/4 + 0.039 B/T - 0.56 B/L)

made dimensional with ``1/2 rho L^2 U`` (Y_v), ``1/2 rho L^3 U`` (Y_r, N_v), ``1/2 rho L^4 U``
(N_r). Clarke's added-mass regressions are reported beside the BEM's for comparison.

The characteristic equation ``A s^2 + B s + C = 0`` (``A = det M``, ``C = det N``) is stable
by Hurwitz when A, B and C are all positive; written as Fedotov's
``psi'' + 2 n psi' + p^2 psi = 0``, ``2n = B/A`` and ``p^2 = C/A``. ``C`` holds no inertia at
all, so lambda66 cannot change *whether* the ship is course-stable, only *how fast* it
answers: it moves the roots and the time constants ``-1/s``.

Units: SI; roots in 1/s, time constants in s.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from addedinertia_env.hydro.water import GRAVITY, RHO_WATER


@dataclasses.dataclass(frozen=True)
class Ship:
    """A ship (or the rig's hull as one): L, B, T in m, block coefficient, speed U in m/s."""

    length: float
    beam: float
    draft: float
    block_coefficient: float
    speed: float
    radius_of_gyration: float | None = None  # m; default 0.25 L
    rho: float = RHO_WATER

    @property
    def mass(self) -> float:
        """Displaced mass, kg: ``rho * C_B * L * B * T``."""
        return self.rho * self.block_coefficient * self.length * self.beam * self.draft

    @property
    def yaw_inertia(self) -> float:
        """Yaw moment of inertia of the ship's mass, kg m^2: ``mass * k^2`` (``k`` the radius of gyration, default ``L / 4``)."""
        k = self.radius_of_gyration if self.radius_of_gyration is not None else 0.25 * self.length
        return self.mass * k * k


def clarke_derivatives(ship: Ship) -> dict[str, float]:
    """Clarke et al. (1983) derivatives, dimensional (SI), and their added masses for comparison."""
    L, B, T, cb, U = ship.length, ship.beam, ship.draft, ship.block_coefficient, ship.speed
    s = math.pi * (T / L) ** 2
    q = 0.5 * ship.rho
    nd = {
        "Yv": -s * (1.0 + 0.40 * cb * B / T),
        "Yr": -s * (-0.5 + 2.2 * B / L - 0.080 * B / T),
        "Nv": -s * (0.5 + 2.4 * T / L),
        "Nr": -s * (0.25 + 0.039 * B / T - 0.56 * B / L),
        "Yvdot": -s * (1.0 + 0.16 * cb * B / T - 5.1 * (B / L) ** 2),
        "Yrdot": -s * (0.67 * B / L - 0.0033 * (B / T) ** 2),
        "Nvdot": -s * (1.1 * B / L - 0.041 * B / T),
        "Nrdot": -s * (1.0 / 12.0 + 0.017 * cb * B / T - 0.33 * B / L),
    }
    return {
        "Yv": nd["Yv"] * q * L**2 * U, "Yr": nd["Yr"] * q * L**3 * U,
        "Nv": nd["Nv"] * q * L**3 * U, "Nr": nd["Nr"] * q * L**4 * U,
        "lambda22": -nd["Yvdot"] * q * L**3, "lambda26": -0.5 * (nd["Yrdot"] + nd["Nvdot"]) * q * L**4,
        "lambda66": -nd["Nrdot"] * q * L**5,
        "nondimensional": nd,
    }


def characteristic(ship: Ship, lambda22: float, lambda26: float, lambda66: float,
                   derivs: dict[str, float] | None = None) -> dict[str, Any]:
    """Hurwitz criterion, roots and time constants of the sway-yaw model for these added masses."""
    d = derivs or clarke_derivatives(ship)
    m, Iz, U = ship.mass, ship.yaw_inertia, ship.speed
    M = np.array([[m + lambda22, lambda26], [lambda26, Iz + lambda66]])
    N = np.array([[-d["Yv"], m * U - d["Yr"]], [-d["Nv"], -d["Nr"]]])
    A = float(np.linalg.det(M))
    B = float(M[0, 0] * N[1, 1] + M[1, 1] * N[0, 0] - M[0, 1] * N[1, 0] - M[1, 0] * N[0, 1])
    C = float(np.linalg.det(N))
    roots = np.roots([A, B, C])
    q = 0.5 * ship.rho
    L = ship.length
    nd = d.get("nondimensional") or {}
    m_nd = m / (q * L**3)
    c_nd = (nd["Yv"] * nd["Nr"] - nd["Nv"] * (nd["Yr"] - m_nd)) if nd else None
    real = [complex(r) for r in roots]
    return {
        "lambda22": lambda22, "lambda26": lambda26, "lambda66": lambda66,
        "hurwitz": {"A": A, "B": B, "C": C, "stable": bool(A > 0 and B > 0 and C > 0)},
        "stability_index_C_nondimensional": c_nd,
        "fedotov": {"two_n": B / A, "p2": C / A},
        "roots": [{"re": r.real, "im": r.imag} for r in real],
        "time_constants": sorted((-1.0 / r.real for r in real if r.imag == 0 and r.real != 0), reverse=True),
    }


def stability(ship: Ship, added: dict[str, float], lambda66_range: tuple[float, float] | None = None) -> dict[str, Any]:
    """The model with ``added`` (lambda22, lambda26, lambda66 in SI) and over a lambda66 interval.

    Returns the nominal characteristic, the one with Clarke's own added masses, and (if
    ``lambda66_range``) the characteristic at the interval's ends with the spread of the
    time constants.
    """
    d = clarke_derivatives(ship)
    nominal = characteristic(ship, added["lambda22"], added["lambda26"], added["lambda66"], d)
    out: dict[str, Any] = {
        "ship": {**dataclasses.asdict(ship), "mass": ship.mass, "yaw_inertia": ship.yaw_inertia,
                 "froude_number": ship.speed / math.sqrt(GRAVITY * ship.length)},
        "derivatives": {k: v for k, v in d.items() if k != "nondimensional"},
        "derivatives_nondimensional": d["nondimensional"],
        "source": "Y_v, Y_r, N_v, N_r: Clarke, Gedling & Hine (1983) Trans. RINA 125; added masses: BEM (zero frequency)",
        "nominal": nominal,
        "with_clarke_added_masses": characteristic(ship, d["lambda22"], d["lambda26"], d["lambda66"], d),
        "note": "C = det(N) holds no inertia: lambda66 changes the roots and time constants, not the criterion",
    }
    if lambda66_range is not None:
        lo, hi = lambda66_range
        ends = [characteristic(ship, added["lambda22"], added["lambda26"], v, d) for v in (lo, hi)]
        tc = [e["time_constants"] for e in ends]
        out["lambda66_range"] = {
            "lambda66": [lo, hi], "at_ends": ends,
            "stable_throughout": all(e["hurwitz"]["stable"] for e in ends),
            "time_constants_span": [[min(a, b), max(a, b)] for a, b in zip(*tc)] if all(len(t) == 2 for t in tc) else None,
            "two_n_span": sorted(e["fedotov"]["two_n"] for e in ends),
        }
    return out
