"""``addedinertia hull PRESET --netcdf FILE``: Capytaine's own dataset of the solve, with the
simulator's memory model as attributes, loaded back by xarray and Capytaine (docs/HYDRODYNAMICS.md)."""

from __future__ import annotations

import importlib.util
import json
import math
import sys

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.hydro.study import cache_path, read_cache

HAS_CAPYTAINE = importlib.util.find_spec("capytaine") is not None
needs_capytaine = pytest.mark.skipif(not HAS_CAPYTAINE, reason="Capytaine (optional extra [hull]) not installed")


@needs_capytaine
def test_netcdf_of_a_coarse_solve_loads_with_xarray_and_holds_the_memory_model(tmp_path, capsys):
    import xarray as xr
    from capytaine.io.xarray import merge_complex_values

    path = tmp_path / "wigley.nc"
    assert main(["hull", "wigley-2m", "--panels", "40", "120", "--netcdf", str(path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert [p.name for p in tmp_path.iterdir()] == ["wigley.nc"]  # no temporary file left beside it
    with xr.open_dataset(path) as raw:
        ds = merge_complex_values(raw.load())
    assert set(ds["radiating_dof"].values) == {"Sway", "Yaw"}
    a66 = ds["added_mass"].sel(radiating_dof="Yaw", influenced_dof="Yaw")
    b66 = ds["radiation_damping"].sel(radiating_dof="Yaw", influenced_dof="Yaw")
    omega = ds["omega"].values
    assert omega[0] == 0.0 and math.isinf(omega[-1]) and np.all(np.diff(omega) > 0)
    assert summary["A66_zero"] == pytest.approx(float(a66.sel(omega=0.0)), rel=1e-12)
    # physics: radiation damping is passive (>= 0) where the mesh resolves the waves, and
    # vanishes at zero and infinite frequency
    resolved = b66.sel(omega=omega[(omega > 0) & (omega < float(ds.attrs["mesh_omega_limit"]))]).values
    assert resolved.size >= 10 and resolved.max() > 0.0
    assert np.all(resolved >= -1e-4 * resolved.max())
    assert float(b66.sel(omega=0.0)) == 0.0 and float(b66.sel(omega=math.inf)) == 0.0
    # the coarse mesh (120 panels) is within its convergence of the cached 1,600-panel solve
    cache = read_cache(cache_path("wigley-2m"))
    fine = cache["resolutions"]["fine"]
    assert float(a66.sel(omega=0.0)) == pytest.approx(fine["zero_frequency"]["A66"], rel=0.10)
    assert float(a66.sel(omega=math.inf)) == pytest.approx(fine["infinite_frequency"]["A66"], rel=0.10)
    # the memory model's attributes are the cache's block, and its A66(inf)/A66(0) agrees with this solve
    block = cache["memory_model"]
    attrs = ds.attrs
    assert int(attrs["memory_model_order"]) == block["order"]
    np.testing.assert_array_equal(np.asarray(attrs["memory_model_A"]).reshape(block["order"], -1), block["A"])
    np.testing.assert_array_equal(attrs["memory_model_c"], block["c"])
    assert json.loads(attrs["memory_model_json"]) == block
    ratio = float(a66.sel(omega=math.inf)) / float(a66.sel(omega=0.0))
    assert ratio == pytest.approx(float(attrs["memory_model_a_inf_ratio"]), rel=0.05)
    assert attrs["preset"] == "wigley-2m" and int(attrs["panels"]) == 120


def test_netcdf_without_capytaine_is_refused_and_the_cache_still_reads(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "capytaine", None)  # as if the extra were not installed
    path = tmp_path / "w.nc"
    assert main(["hull", "wigley-2m", "--netcdf", str(path)]) == 2
    err = capsys.readouterr().err
    assert "--netcdf" in err and "addedinertia[hull]" in err and not path.exists()
    assert main(["hull", "wigley-2m", "--json"]) == 0  # the cache needs no Capytaine
    assert json.loads(capsys.readouterr().out)["A66_zero"] > 0


def test_netcdf_of_a_missing_mesh_file_is_refused(tmp_path, capsys):
    missing = tmp_path / "hull.stl"
    assert main(["hull", str(missing), "--netcdf", str(tmp_path / "x.nc")]) == 2
    assert str(missing) in capsys.readouterr().err
