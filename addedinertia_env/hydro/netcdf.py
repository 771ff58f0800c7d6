"""Capytaine's own dataset of a hull's radiation solve, as NetCDF (``addedinertia hull ... --netcdf FILE``).

Other hydrodynamics tools read Capytaine's dataset (``capytaine.io.xarray``): added mass
and radiation damping over ``omega`` x ``radiating_dof`` x ``influenced_dof``, with the
problem's ``rho``, ``g``, ``water_depth`` as coordinates. This module solves the radiation
problems of a mesh in sway and yaw (the rig's degrees of freedom, rotation about the
vertical through the mesh origin, as :func:`.bem.solve_yaw`) at zero frequency, the
frequencies of the cache's sweep and infinite frequency, assembles them with
``capytaine.assemble_dataset`` and writes them with ``capytaine.io.xarray.export_dataset``
(complex values split into a ``complex`` = re, im dimension, as Capytaine does).

Attributes added to the dataset (NetCDF attributes are numbers, strings or 1-D arrays):
``addedinertia_version``, ``hull`` (JSON of the shape), ``panels``, ``yaw_axis``, ``lid_z``,
``mesh_omega_limit`` (rad/s: above it the waves are shorter than 8 panel radii and the
mesh's values are not to be trusted, as the cache's ``flagged_omegas`` say),
``irregular_frequency`` (rad/s, without the lid)
and, where the preset's cache has one, the simulator's fitted radiation-memory model
(docs/RADIATION_MEMORY.md) as ``memory_model_*``: its ``order``, ``fit_error``,
``a_inf_ratio``, ``a_swing_ratio``, ``swing_omega`` (rad/s), ``d``, ``b``, ``c`` and ``A``
(row-major, ``order`` x ``order``), normalised to A66(0) = 1 as in the cache, and the whole
block as JSON in ``memory_model_json``. The model was fitted to the cache's sweep
(``memory_model_fitted_to``), not to this solve when the panel counts differ.

The write is atomic (a temporary file beside FILE, renamed). Reading the cache never needs
Capytaine; writing this file does (the optional ``[hull]`` extra).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env import __version__
from addedinertia_env.foundation.atomic import atomic_target
from addedinertia_env.hydro.bem import GRAVITY, RHO_WATER, _body, _quiet, capytaine_mesh, require_capytaine

DOFS = ("Sway", "Yaw")


def solve_dataset(source, omegas, *, rho: float = RHO_WATER, g: float = GRAVITY):
    """Capytaine's dataset (xarray) of the floating mesh ``source`` in sway and yaw at 0, ``omegas`` and inf (rad/s).

    A lid against irregular frequencies is added, as in :func:`.bem.solve_yaw`, when the
    highest frequency passes 80 % of the first irregular frequency; its height is the
    ``lid_z`` attribute (nan without a lid)."""
    cpt = require_capytaine()
    _quiet(cpt)
    mesh = capytaine_mesh(source)
    plain = _body(cpt, mesh, lid_z=None)
    finite = sorted(float(w) for w in omegas if 0.0 < float(w) < math.inf)
    lid_z = math.nan
    body = plain
    if finite and max(finite) > 0.8 * float(plain.first_irregular_frequency_estimate(g=g)):
        lid_z = float(mesh.lowest_lid_position(1.25 * max(finite), g=g))
        body = _body(cpt, mesh, lid_z=lid_z)
    problems = [cpt.RadiationProblem(body=body if 0.0 < w < math.inf else plain, radiating_dof=dof, omega=w,
                                     rho=rho, g=g, water_depth=math.inf)
                for w in (0.0, *finite, math.inf) for dof in DOFS]
    solver = cpt.BEMSolver(method="direct")
    results = solver.solve_all(problems, keep_details=False, progress_bar=False, _check_wavelength=False)
    ds = cpt.assemble_dataset(results)
    w_mesh = math.sqrt(2.0 * math.pi * g / float(plain.minimal_computable_wavelength))
    ds.attrs.update({"addedinertia_version": __version__, "capytaine_version": cpt.__version__,
                     "mesh_omega_limit": w_mesh,  # rad/s: above it waves are shorter than 8 panel radii
                     "irregular_frequency": float(plain.first_irregular_frequency_estimate(g=g)),
                     "yaw_axis": "vertical through the mesh origin (z up, free surface z = 0)",
                     "lid_z": lid_z, "bem_method": "direct (potential) formulation, Delhommeau Green function"})
    return ds


def memory_attributes(block: dict[str, Any] | None, fitted_to: str) -> dict[str, Any]:
    """The fitted memory model (cache block ``memory_model``) as NetCDF-ready attributes; {} without one."""
    if not block:
        return {}
    n = int(block["order"])
    attrs: dict[str, Any] = {
        "memory_model_format": str(block.get("format", "")),
        "memory_model_order": n,
        "memory_model_normalised_to": str(block.get("normalised_to", "")),
        "memory_model_fitted_to": fitted_to,
        "memory_model_json": json.dumps(block, sort_keys=True),
    }
    for key in ("fit_error", "a_inf_ratio", "a_swing_ratio", "swing_omega", "d", "K0_ratio"):
        if block.get(key) is not None:
            attrs[f"memory_model_{key}"] = float(block[key])
    for key in ("b", "c"):
        attrs[f"memory_model_{key}"] = np.asarray(block[key], dtype=float)
    attrs["memory_model_A"] = np.asarray(block["A"], dtype=float).reshape(n * n)
    return attrs


def write_netcdf(ds, path: str | Path) -> Path:
    """Write Capytaine's dataset ``ds`` to ``path`` with ``capytaine.io.xarray.export_dataset``, atomically."""
    from capytaine.io.xarray import export_dataset  # noqa: PLC0415

    path = Path(path)
    with atomic_target(path, suffix=".nc") as tmp:
        export_dataset(tmp, ds, format="netcdf")
    return path


def export(target: str, path: str | Path, *, panels: int | None = None, preset_hull=None) -> dict[str, Any]:
    """Solve the preset or mesh file ``target`` and write its dataset to ``path``; returns a summary.

    A preset is meshed at ``panels`` (default: the cache's fine resolution) and solved at
    the cache's frequencies (:data:`.study.DEFAULT_OMEGAS`), with the cache's memory model
    as attributes where there is one; a mesh file is solved as given. ``preset_hull``: the
    function that gives a preset's hull shape and facts (``hull.presets.preset_hull``, passed by
    the caller, so hydrodynamics needs nothing of the simulator's presets). Raises
    :class:`.bem.CapytaineMissing` without Capytaine, ``ValueError`` (and
    :class:`.mesh_checks.MeshError`) for a mesh that cannot be used."""
    from addedinertia_env.hydro import study as st  # noqa: PLC0415
    from addedinertia_env.hydro.bem import load_user_mesh  # noqa: PLC0415

    suffix = Path(target).suffix.lower()
    attrs: dict[str, Any] = {}
    if suffix in ("", ".yaml", ".yml"):
        from addedinertia_env.hydro.geometry import quarter_mesh  # noqa: PLC0415
        if preset_hull is None:
            raise ValueError(f"{target}: a preset needs the caller's preset_hull (hull.presets.preset_hull)")

        shape, facts = preset_hull(target)
        n = panels or st.DEFAULT_PANELS[1]
        source = quarter_mesh(shape, n, "floating")
        attrs.update(preset=str(facts["preset"]), hull=json.dumps(shape.as_dict(), sort_keys=True))
        cache = st.cache_path(facts["preset"])
        if cache.exists():
            data = st.read_cache(cache, shape)
            fine = data["resolutions"]["fine"]["mesh"]["panels"]
            attrs.update(memory_attributes(data.get("memory_model"),
                                           f"{cache.name}: the cached sweep at {fine} panels"))
    else:
        source, _ = load_user_mesh(target, floating=True)
        attrs["mesh_file"] = str(target)
    ds = solve_dataset(source, st.DEFAULT_OMEGAS)
    attrs["panels"] = int(ds.attrs.get("panels", 0)) or _panels(source)
    ds.attrs.update(attrs)
    write_netcdf(ds, path)
    a66 = ds["added_mass"].sel(radiating_dof="Yaw", influenced_dof="Yaw")
    return {"netcdf": str(path), "panels": attrs["panels"], "omegas": int(ds.sizes["omega"]),
            "A66_zero": float(a66.sel(omega=0.0)), "A66_inf": float(a66.sel(omega=math.inf)),
            "memory_model": "memory_model_order" in attrs}


def _panels(source) -> int:
    from addedinertia_env.hydro.bem import mesh_arrays  # noqa: PLC0415

    if hasattr(source, "nb_faces_full"):
        return int(source.nb_faces_full)
    return int(getattr(capytaine_mesh(source), "nb_faces", 0) or len(mesh_arrays(source)[1]))
