"""A BEM solve as Capytaine's own dataset, in NetCDF (``addedinertia hull ... --netcdf FILE``).

Other hydrodynamics tools read Capytaine's dataset (``capytaine.assemble_dataset``: added mass
and radiation damping over ``omega`` with the radiating and influenced degrees of freedom,
and the frequency's other forms), saved by ``capytaine.io.xarray.save_dataset_as_netcdf``
(complex values split into a ``complex`` dimension) and loaded by ``xarray.open_dataset``.
The file holds the yaw radiation problems of the solve (zero frequency, the sweep, infinite
frequency; of the fine resolution for a preset), and as attributes what the project adds: the
hull, the command, and the simulator's fitted radiation-memory model (docs/RADIATION_MEMORY.md)
as JSON in ``addedinertia_memory_model`` with its order and fit error as numbers. Needs
Capytaine (the optional ``[hull]`` extra); the JSON cache is read without it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..atomic import atomic_target
from .bem import require_capytaine


def write_netcdf(path: str | Path, results: list, study: dict[str, Any], command: str) -> Path:
    """Capytaine's dataset of ``results`` (its result objects) with the project's attributes, written
    atomically to ``path``; returns the path."""
    cpt = require_capytaine()
    if not results:
        raise ValueError(f"{path}: no radiation results to write (the solve kept none)")
    ds = cpt.assemble_dataset(results)
    ds.attrs["addedinertia_command"] = command
    ds.attrs["addedinertia_hull"] = json.dumps(study.get("hull") or {"mesh_file": study.get("mesh_file")})
    ds.attrs["addedinertia_floating"] = int(bool(study.get("floating", True)))
    model = study.get("memory_model")
    if model is None:
        try:
            from .memory_fit import memory_model_from_cache  # noqa: PLC0415

            model = memory_model_from_cache(study)
        except (ValueError, KeyError, TypeError, IndexError):
            model = None
    if model is not None:
        ds.attrs["addedinertia_memory_model"] = json.dumps(model, default=float)
        for key in ("order", "fit_error", "a_inf_ratio", "a_swing_ratio"):
            if isinstance(model.get(key), (int, float)):
                ds.attrs[f"addedinertia_memory_{key}"] = model[key]
    path = Path(path)
    with atomic_target(path, suffix=".nc") as tmp:
        cpt.io.xarray.save_dataset_as_netcdf(tmp, ds)
    return path
