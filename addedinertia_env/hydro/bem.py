"""BEM radiation solve of a hull in yaw (and sway) with Capytaine (optional dependency).

Capytaine (https://github.com/capytaine/capytaine) solves the linear potential-flow
radiation problem with a constant-panel boundary-element method. Choices made here, and
why (they are recorded in every result):

* **Direct method** (Green's identity for the potential), not the default indirect
  (source) one: on a deeply submerged prolate spheroid the direct method is within 0.2 %
  of Lamb at 800 panels where the indirect one is 4 to 7 % high (measured, docs/HYDRODYNAMICS.md).
* **Zero frequency** ``omega = 0``: the free-surface condition becomes ``dphi/dz = 0``, a
  rigid lid, i.e. the double body in unbounded fluid, halved. Solved in *infinite depth*
  on purpose: Capytaine's finite-depth Green function refuses ``kh < 0.1`` (and panel
  codes in general lose accuracy there), which is exactly where this rig lives
  (swing periods 3 to 6 s in a tank 1 to 2 m deep). The tank bottom's effect is then
  reported separately, at the swing frequency, where ``kh`` is large enough.
* **Infinite frequency** ``omega = inf``: ``phi = 0`` on the free surface.
* **Deeply submerged** bodies: no free surface at all (``free_surface = inf``), the
  unbounded-fluid problem of Lamb's closed forms.
* **Irregular frequencies**: the first one is estimated (Capytaine's formula for a box of
  the waterplane's size and the draft); frequencies above 80 % of it (of the one with the
  lid, when a lid is added) are flagged, and when
  the range reaches them a lid is added inside the hull below the waterline (Capytaine's
  extended boundary-integral method), which moves them out of range.
* Symmetric meshes (the generated quarter hulls) are solved as such, which is four times
  cheaper.

Units: SI. Added inertia kg m^2 (A66) or kg (A22) or kg m (A26), radiation damping
N m s (B66). The yaw axis is the vertical through the origin of the mesh.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from addedinertia_env.hydro.geometry import QuarterMesh
from addedinertia_env.hydro.mesh_checks import check_mesh
from addedinertia_env.hydro.water import GRAVITY, RHO_WATER

INSTALL_HINT = "pip install 'addedinertia[hull]'  (or: pip install capytaine==3.0.0)"


class CapytaineMissing(RuntimeError):
    """The optional BEM solver is not installed; the message says how to install it."""


def require_capytaine():
    """The ``capytaine`` module, or :class:`CapytaineMissing` with the install command."""
    try:
        import capytaine  # noqa: PLC0415 - optional dependency
    except ImportError:
        raise CapytaineMissing("the BEM solver Capytaine is not installed; install it with "
                               f"{INSTALL_HINT}. Cached results (configs/rigs/*.bem.json) are read without it.") from None
    return capytaine


def capytaine_version() -> str | None:
    """The installed Capytaine version, or None."""
    try:
        return require_capytaine().__version__
    except CapytaineMissing:
        return None


def _quiet(cpt) -> None:
    cpt.set_logging("ERROR")


def capytaine_mesh(source: QuarterMesh | Any):
    """A Capytaine mesh from a :class:`QuarterMesh` (doubly symmetric) or a Capytaine mesh."""
    cpt = require_capytaine()
    if isinstance(source, QuarterMesh):
        quarter = cpt.Mesh(source.vertices, source.faces, name="quarter")
        return cpt.ReflectionSymmetricMesh(cpt.ReflectionSymmetricMesh(quarter, plane="xOz"), plane="yOz")
    return source


def mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """(vertices, faces, symmetry planes) of the *stored* part of a Capytaine mesh.

    A ReflectionSymmetricMesh is unwrapped to the half (or quarter) it mirrors, so that
    :func:`check_mesh` can look for panels lying in the symmetry planes.
    """
    planes: list[str] = []
    m = mesh
    while hasattr(m, "half") and hasattr(m, "plane"):
        planes.append(m.plane)
        m = m.half
    return np.asarray(m.vertices, dtype=float), np.asarray(m.faces, dtype=int), tuple(planes)


def load_user_mesh(path: str, *, floating: bool):
    """Load and check a mesh file in a format Capytaine reads; raises MeshError / ValueError.

    Returns ``(capytaine_mesh, MeshReport)``.
    """
    cpt = require_capytaine()
    _quiet(cpt)
    try:
        mesh = cpt.load_mesh(path)
    except Exception as e:  # noqa: BLE001 - any reader failure is a bad-input message
        raise ValueError(f"{path}: cannot read the mesh ({type(e).__name__}: {e}); expected a mesh file "
                         "Capytaine reads (.stl, .obj, .gdf, .pnl, .msh, .nem, .hst, ...)") from None
    v, f, planes = mesh_arrays(mesh)
    report = check_mesh(v, f, floating=floating, symmetry_planes=planes, where=path)
    return mesh, report


def _body(cpt, mesh, *, lid_z: float | None):
    lid = mesh.generate_lid(z=lid_z) if lid_z is not None else None
    body = cpt.FloatingBody(mesh=mesh, lid_mesh=lid, dofs=cpt.rigid_body_dofs(rotation_center=(0.0, 0.0, 0.0)))
    return body.with_only_dofs(["Sway", "Yaw"])


def solve_yaw(source, omegas, *, floating: bool = True, water_depth: float = math.inf,
              rho: float = RHO_WATER, g: float = GRAVITY, extra_depths: tuple[float, ...] = (),
              depth_omega: float | None = None) -> dict[str, Any]:
    """Radiation solve of a hull in yaw: A66, B66 over ``omegas`` (rad/s) and the limits.

    ``source``: a generated :class:`QuarterMesh` or a Capytaine mesh (already checked).
    ``floating``: free surface at z = 0 (else deeply submerged, no free surface).
    ``water_depth`` (m): depth of the frequency sweep (inf: deep water).
    ``extra_depths``, ``depth_omega``: A66 at ``depth_omega`` in water of each of these
    depths (the tank bottom's effect), each flagged when Capytaine cannot evaluate it.
    Returns a JSON-ready dict (see docs/HYDRODYNAMICS.md for the fields).
    """
    cpt = require_capytaine()
    _quiet(cpt)
    t0 = time.perf_counter()
    mesh = capytaine_mesh(source)
    v, f, planes = mesh_arrays(mesh)
    report = check_mesh(v, f, floating=floating, symmetry_planes=planes,
                        where=f"mesh of {getattr(source, 'shape', None) and source.shape.shape or 'hull'}")
    solver = cpt.BEMSolver(method="direct")
    omegas = [float(w) for w in omegas]
    out: dict[str, Any] = {
        "capytaine_version": cpt.__version__,
        "bem_method": "direct (potential) formulation, Delhommeau Green function, constant panels",
        "rho": rho, "g": g,
        "floating": floating,
        "water_depth": None if math.isinf(water_depth) else water_depth,
        "mesh": {**report.as_dict(), "symmetry_planes": list(planes)},
        "yaw_axis": "vertical through the mesh origin",
    }
    if isinstance(source, QuarterMesh):
        out["mesh"].update(source="generated", hull=source.shape.as_dict(), nx=source.nx, nz=source.nz,
                           submergence=source.submergence)

    def solve(dof: str, omega: float, *, body, depth: float = math.inf) -> tuple[dict, dict]:
        kw: dict[str, Any] = {"omega": omega, "rho": rho, "g": g}
        if floating:
            kw["water_depth"] = depth
        else:
            kw["free_surface"] = math.inf
        res = solver.solve(cpt.RadiationProblem(body=body, radiating_dof=dof, **kw), keep_details=False,
                           _check_wavelength=False)
        return ({k: float(np.real(x)) for k, x in res.added_mass.items()},
                {k: float(np.real(x)) for k, x in res.radiation_damping.items()})

    plain = _body(cpt, mesh, lid_z=None)
    if not floating:
        a, _ = solve("Yaw", 1.0, body=plain)
        a2, _ = solve("Sway", 1.0, body=plain)
        out.update(zero_frequency={"A66": a["Yaw"], "A22": a2["Sway"], "A26": a["Sway"],
                                   "method": "no free surface (deeply submerged, unbounded fluid)"},
                   infinite_frequency=None, omega=[], A66=[], B66=[], irregular_frequency=None, mesh_omega_limit=None,
                   flagged_omegas=[], failed=[], lid=None)
        out["seconds"] = time.perf_counter() - t0
        return out

    w_irr = float(plain.first_irregular_frequency_estimate(g=g))
    finite = [w for w in omegas if 0.0 < w < math.inf]
    w_max = max(finite) if finite else 0.0
    lid_z = None
    body = plain
    if w_max > 0.8 * w_irr:
        lid_z = float(mesh.lowest_lid_position(1.25 * w_max, g=g))
        body = _body(cpt, mesh, lid_z=lid_z)
    out["irregular_frequency"] = w_irr
    out["lid"] = None if lid_z is None else {"z": lid_z, "irregular_frequency_with_lid": float(
        body.first_irregular_frequency_estimate(g=g))}
    w_mesh = math.sqrt(2.0 * math.pi * g / float(plain.minimal_computable_wavelength))
    out["mesh_omega_limit"] = w_mesh
    # with a lid the irregular frequencies move up: flag against the one that applies
    w_eff = out["lid"]["irregular_frequency_with_lid"] if lid_z is not None else w_irr
    out["flagged_omegas"] = (
        [{"omega": w, "reason": f"above 80 % of the first irregular frequency {w_eff:.3g} rad/s"
          + (" (with the lid)" if lid_z is not None else "")} for w in finite if w > 0.8 * w_eff]
        + [{"omega": w, "reason": f"waves shorter than 8 panel radii (mesh valid to {w_mesh:.3g} rad/s)"}
           for w in finite if w > w_mesh])

    a0, _ = solve("Yaw", 0.0, body=plain)
    s0, _ = solve("Sway", 0.0, body=plain)
    ainf, _ = solve("Yaw", math.inf, body=plain)
    out["zero_frequency"] = {"A66": a0["Yaw"], "A22": s0["Sway"], "A26": a0["Sway"],
                             "method": "omega = 0: rigid-lid free surface (double body, halved), infinite depth"}
    out["infinite_frequency"] = {"A66": ainf["Yaw"], "method": "omega = inf: phi = 0 on the free surface, infinite depth"}
    A, B, W, failed = [], [], [], []
    for w in finite:
        try:
            a, b = solve("Yaw", w, body=body, depth=water_depth)
        except Exception as e:  # noqa: BLE001 - recorded, never silently dropped
            failed.append({"omega": w, "error": f"{type(e).__name__}: {e}"})
            continue
        W.append(w)
        A.append(a["Yaw"])
        B.append(b["Yaw"])
    out.update(omega=W, A66=A, B66=B, failed=failed)
    if depth_omega is not None:
        rows = []
        for h in extra_depths:
            try:
                a, _ = solve("Yaw", depth_omega, body=plain, depth=h)
                rows.append({"water_depth": h, "omega": depth_omega, "A66": a["Yaw"]})
            except Exception as e:  # noqa: BLE001
                rows.append({"water_depth": h, "omega": depth_omega, "A66": None,
                             "error": f"{type(e).__name__}: {e}"})
        a, _ = solve("Yaw", depth_omega, body=plain)
        out["at_depth_omega"] = {"omega": depth_omega, "A66_deep_water": a["Yaw"], "depths": rows}
    out["seconds"] = time.perf_counter() - t0
    return out
