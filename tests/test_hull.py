"""Hull hydrodynamics from geometry (addedinertia_env/hydro, `addedinertia hull`).

The BEM tests need Capytaine (the optional ``[hull]`` extra) and are skipped without it;
everything else (meshes and their checks, closed forms, the retardation function, course
stability, the cached preset results) runs without it.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
import time

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.hydro import estimates, retardation, stability
from addedinertia_env.hydro.geometry import SUBMERGENCE, HullShape, full_mesh, quarter_mesh, reversed_faces
from addedinertia_env.hydro.mesh_checks import MeshError, check_mesh
from addedinertia_env.hydro.study import cache_path, read_cache, richardson
from addedinertia_env.hydro import closed_forms as hydro

HAS_CAPYTAINE = importlib.util.find_spec("capytaine") is not None
needs_capytaine = pytest.mark.skipif(not HAS_CAPYTAINE, reason="Capytaine (optional extra [hull]) not installed")

WIGLEY = HullShape("wigley", 2.0, 0.2, 0.125)


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# --- meshes and their checks (numpy only) ---------------------------------------------

@pytest.mark.parametrize("shape", [WIGLEY, HullShape("spheroid", 2.0, 0.4)], ids=["wigley", "spheroid"])
@pytest.mark.parametrize("sub", SUBMERGENCE)
def test_generated_meshes_are_closed_outward_and_converge_in_volume(shape, sub):
    errors = []
    for panels in (200, 800):
        q = quarter_mesh(shape, panels, sub)
        rep_q = check_mesh(q.vertices, q.faces, floating=sub == "floating", symmetry_planes=("xOz", "yOz"))
        v, f = full_mesh(q)
        rep = check_mesh(v, f, floating=sub == "floating")
        assert rep.free_edges == 0 and rep.inconsistent_edges == 0 and rep.lid_panels == 0
        assert rep_q.volume == pytest.approx(rep.volume, rel=1e-9)
        errors.append(abs(rep.volume / shape.displaced_volume(sub) - 1.0))
    # flat panels inscribed in a convex hull lose volume, less and less as they shrink
    assert errors[1] < errors[0] < 0.1 and errors[1] < 0.025


def test_mesh_checks_catch_flipped_normals_holes_lids_and_dry_panels():
    q = quarter_mesh(WIGLEY, 200, "floating")
    v, f = full_mesh(q)
    with pytest.raises(MeshError, match="normals must point out"):
        check_mesh(v, reversed_faces(f), floating=True)
    with pytest.raises(MeshError, match="free edge"):
        check_mesh(v, f[1:], floating=True)
    flipped_one = f.copy()
    flipped_one[5] = reversed_faces(flipped_one[5:6])[0]
    with pytest.raises(MeshError, match="disagree on orientation"):
        check_mesh(v, flipped_one, floating=True)
    # a panel lying in the symmetry plane y = 0 of a half mesh: an internal lid
    lid_v = np.vstack([q.vertices, [[0.1, 0.0, -0.01], [0.2, 0.0, -0.01], [0.2, 0.0, -0.05], [0.1, 0.0, -0.05]]])
    n = len(q.vertices)
    lid_f = np.vstack([q.faces, [[n, n + 1, n + 2, n + 3]]])
    with pytest.raises(MeshError, match="internal lid"):
        check_mesh(lid_v, lid_f, floating=True, symmetry_planes=("xOz", "yOz"))
    raised = v.copy()
    raised[:, 2] += 0.05
    with pytest.raises(MeshError, match="above the waterline"):
        check_mesh(raised, f, floating=True)


def test_hull_shape_refuses_bad_dimensions():
    with pytest.raises(ValueError, match="draft"):
        HullShape("wigley", 2.0, 0.2)
    with pytest.raises(ValueError, match="prolate"):
        HullShape("spheroid", 0.2, 0.4)
    with pytest.raises(ValueError, match="shape"):
        HullShape("barge", 2.0, 0.4, 0.1)


# --- closed forms ---------------------------------------------------------------------

@pytest.mark.parametrize("ratio", [2.0, 5.0, 7.0, 12.0])
def test_lamb_ellipsoid_reduces_to_the_spheroid(ratio):
    a, b = 1.0, 1.0 / ratio
    assert estimates.ellipsoid_yaw_added_inertia(a, b, b) == pytest.approx(
        hydro.spheroid_added_yaw_inertia(2 * a, 2 * b, "full"), rel=1e-7)


def test_ellipsoid_added_inertia_vanishes_for_a_body_of_revolution_about_z():
    # an oblate body round in plan (a = b) turning about z pushes no water
    assert estimates.ellipsoid_yaw_added_inertia(1.0, 1.0 - 1e-9, 0.3) < 1e-6


def test_strip_theory_of_a_spheroid_is_the_slender_body_limit():
    # strip theory gives m a^2 / 5 (the displaced fluid's inertia about the waterline axis, no end
    # correction); Lamb's k' (a^2 + b^2)/a^2 approaches 1 as the spheroid gets slender
    for ratio, tol in ((7.0, 0.25), (30.0, 0.03)):
        s = HullShape("spheroid", 2.0, 2.0 / ratio)
        strip, lamb = estimates.strip_theory_estimate(s), estimates.lamb_estimate(s)
        assert strip > lamb and strip / lamb - 1 < tol


# --- retardation function --------------------------------------------------------------

def test_retardation_function_matches_a_closed_form_transform():
    # B(w) = w^2 exp(-w^2): (2/pi) int B cos(wt) dw = (1/(4 sqrt(pi))) (2 - t^2) exp(-t^2/4)
    w = np.linspace(0.05, 6.0, 240)
    t = np.linspace(0.0, 8.0, 81)
    K = retardation.retardation_function(w, w**2 * np.exp(-w**2), t)["K"]
    exact = (2 - t**2) * np.exp(-t**2 / 4) / (4 * math.sqrt(math.pi))
    assert np.max(np.abs(K - exact)) < 2e-3 * np.max(np.abs(exact))


def test_ogilvie_rebuilds_added_inertia_from_the_kernel():
    # a one-pole radiation model: K(t) = k exp(-t/tau) gives B(w) = k tau / (1 + (w tau)^2) and
    # A(w) = A_inf - k tau^2 / (1 + (w tau)^2)
    k, tau, a_inf = 50.0, 0.4, 6.0
    t = np.linspace(0.0, 12.0, 6001)
    w = np.array([1.0, 2.0, 5.0])
    A = retardation.added_inertia_from_kernel(t, k * np.exp(-t / tau), a_inf, w)
    assert A == pytest.approx(a_inf - k * tau**2 / (1 + (w * tau) ** 2), rel=1e-4)


def test_richardson_recovers_a_first_order_limit():
    vals = [10.0 + 4.0 * h for h in (1.0, 0.5, 0.25)]
    r = richardson(*vals)
    assert r["order"] == pytest.approx(1.0) and r["value"] == pytest.approx(10.0)
    assert richardson(1.0, 2.0, 1.5)["value"] is None  # not monotone: no extrapolation


# --- course stability --------------------------------------------------------------------

def _ship():
    return stability.Ship(2.0, 0.2, 0.125, 4.0 / 9.0, 0.2 * math.sqrt(9.81 * 2.0))


def test_lambda66_moves_the_roots_but_not_the_criterion():
    ship = _ship()
    added = {"lambda22": 40.0, "lambda26": 0.0}
    lo = stability.characteristic(ship, lambda66=8.0, **added)
    hi = stability.characteristic(ship, lambda66=16.0, **added)
    assert lo["hurwitz"]["C"] == pytest.approx(hi["hurwitz"]["C"])
    assert lo["hurwitz"]["stable"] and hi["hurwitz"]["stable"]
    # more yaw inertia: a slower answer (longer time constants), the sum of 1/T_i = B/A falls
    assert hi["time_constants"][0] > lo["time_constants"][0]
    assert sum(1 / t for t in hi["time_constants"]) < sum(1 / t for t in lo["time_constants"])
    # the roots solve A s^2 + B s + C = 0
    h = hi["hurwitz"]
    for r in hi["roots"]:
        s = complex(r["re"], r["im"])
        assert abs(h["A"] * s * s + h["B"] * s + h["C"]) < 1e-9 * h["C"]


def test_an_unstable_hull_has_a_positive_root_and_fails_hurwitz():
    ship = _ship()
    d = dict(stability.clarke_derivatives(ship))
    d["Nr"] = 0.05 * d["Nr"]  # little yaw damping: the destabilising Munk moment wins
    c = stability.characteristic(ship, 40.0, 0.0, 11.7, d)
    assert not c["hurwitz"]["stable"] and c["hurwitz"]["C"] < 0
    assert max(r["re"] for r in c["roots"]) > 0


# --- the cached preset results (no solver needed) ----------------------------------------

@pytest.mark.parametrize("preset", ["wigley-2m", "spheroid-7"])
def test_cached_study_is_physical_and_converged(preset):
    from addedinertia_env.sim.hull_presets import preset_hull
    from addedinertia_env.hydro.study import summary

    shape, facts = preset_hull(preset)
    data = read_cache(cache_path(preset), shape)
    s = summary(data, swing_omega=facts["swing_omega"])
    # infinite frequency about half the zero-frequency value; the swing value a little above it
    assert 0.35 < s["A66_inf"] / s["A66_zero"] < 0.65
    assert 0.0 < s["free_surface_effect_at_swing"] < 0.05
    assert abs(s["convergence"]["relative_change_coarse_to_fine"]["A66_zero"]) < 0.05
    assert s["retardation"]["ogilvie_max_rel_error"] < 0.1
    # the preset's lambda66 (given or Lamb's) against the BEM's rigid-lid value
    assert s["A66_zero"] == pytest.approx(facts["lambda66"], rel=0.06)
    assert s["A26_zero"] == pytest.approx(0.0, abs=1e-6 * s["A66_zero"])  # fore-aft symmetric hulls


def test_hull_cli_answers_from_the_cache_without_capytaine(capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "capytaine", None)  # as if the extra were not installed
    t0 = time.perf_counter()
    code, out, err = run_cli(capsys, "hull", "wigley-2m", "--json")
    assert code == 0, err
    assert time.perf_counter() - t0 < 10.0
    obj = json.loads(out)
    for key in ("A66_swing", "A66_zero", "A66_inf", "swing_omega"):
        assert math.isfinite(obj[key])
    assert obj["resolution"]["panels"] > 1000 and obj["source"].endswith("wigley-2m.bem.json")
    assert obj["A66_inf"] < obj["A66_zero"] < obj["A66_swing"]
    code, out, err = run_cli(capsys, "hull", "wigley-2m", "--solve")
    assert code == 2 and "pip install 'addedinertia[hull]'" in err and out == ""


def test_hull_cli_stability_over_an_interval(capsys):
    code, out, err = run_cli(capsys, "hull", "wigley-2m", "--stability", "--json",
                             "--lambda66-range", "10", "13")
    assert code == 0, err
    st = json.loads(out)["stability"]
    assert st["nominal"]["hurwitz"]["stable"] in (True, False)
    ends = st["lambda66_range"]["at_ends"]
    assert [e["lambda66"] for e in ends] == [10.0, 13.0]
    assert ends[0]["hurwitz"]["C"] == pytest.approx(ends[1]["hurwitz"]["C"])
    span = st["lambda66_range"]["time_constants_span"][0]
    assert span[0] < span[1]


def test_hull_cli_bad_input_is_one_line_exit_2(capsys, tmp_path):
    code, out, err = run_cli(capsys, "hull", "no-such-preset", "--json")
    assert code == 2 and out == "" and err.count("\n") == 1
    code, out, err = run_cli(capsys, "hull", "wigley-2m", "--stability", "--froude", "3")
    assert code == 2 and "--froude" in err
    bad = tmp_path / "wigley-2m.yaml"
    bad.write_text((cache_path("wigley-2m").parent / "wigley-2m.yaml").read_text().replace("beam: 0.2,", "beam: -0.2,"))
    code, out, err = run_cli(capsys, "hull", str(bad), "--json")
    assert code == 2 and "beam" in err


def test_hull_cli_stability_from_a_record(capsys, realistic_record_path):
    code, out, err = run_cli(capsys, "hull", "wigley-2m", "--from-record", realistic_record_path, "--json")
    assert code == 0, err
    st = json.loads(out)["stability"]
    fr = st["from_record"]
    lo, hi = fr["ci95_measured"]
    assert lo <= fr["lambda66_measured"] <= hi
    # identify()'s lambda66 is A66(0) by definition: taken as it is, no BEM ratio between record and ship
    assert st["lambda66_range"]["lambda66"] == [lo, hi] and fr["lambda66_used"] == fr["lambda66_measured"]
    assert fr["lambda66_is"].startswith("A66(0)")
    # and it is the record's truth (A66(0)) to the method's accuracy, where the old swing-to-zero
    # rescaling (BEM A66(0)/A66(swing) = 0.983) put it 1.7 % low
    truth = json.loads(realistic_record_path.with_suffix(".json").read_text())["truth"]["lambda66"]
    assert abs(fr["lambda66_used"] / truth - 1.0) < 5e-3
    code, out, err = run_cli(capsys, "hull", "wigley-2m", "--from-record", realistic_record_path, "--method", "magic")
    assert code == 2 and "--method" in err


# --- BEM against closed forms (Capytaine) ------------------------------------------------

def _deep_spheroid_error(ratio: float, panels: int) -> float:
    from addedinertia_env.hydro.bem import solve_yaw

    s = HullShape("spheroid", 2.0, 2.0 / ratio)
    r = solve_yaw(quarter_mesh(s, panels, "deep"), [], floating=False)
    return r["zero_frequency"]["A66"] / hydro.spheroid_added_yaw_inertia(2.0, 2.0 / ratio, "full") - 1.0


@needs_capytaine
@pytest.mark.parametrize("ratio", [3.0, 5.0, 7.0, 10.0])
def test_bem_deep_spheroid_within_3_percent_of_lamb(ratio):
    # the issue asks for 3 %; the direct formulation does much better at 400 panels (-0.33 % at
    # worst, docs/HYDRODYNAMICS.md), so hold it to 1 %
    assert abs(_deep_spheroid_error(ratio, 400)) < 0.01


@needs_capytaine
@pytest.mark.slow
@pytest.mark.parametrize("ratio", [3.0, 5.0, 7.0, 10.0])
def test_bem_deep_spheroid_fine_within_a_quarter_percent_of_lamb(ratio):
    assert abs(_deep_spheroid_error(ratio, 3200)) < 0.0025


@needs_capytaine
def test_bem_rigid_lid_halves_the_double_body():
    # zero frequency at the waterline = half the deeply submerged double body (physics.md s6)
    from addedinertia_env.hydro.bem import solve_yaw

    s = HullShape("spheroid", 2.0, 2.0 / 7.0)
    floating = solve_yaw(quarter_mesh(s, 400, "floating"), [1.57], floating=True)
    assert floating["zero_frequency"]["A66"] == pytest.approx(estimates.lamb_estimate(s, floating=True), rel=0.03)
    assert floating["infinite_frequency"]["A66"] < floating["zero_frequency"]["A66"] < floating["A66"][0]


# --- the prior in use -------------------------------------------------------------------

def test_bem_prior_replaces_the_stroke_estimate_in_the_controller_context():
    import dataclasses

    from addedinertia_env.experiment.protocol import Experiment
    from addedinertia_env.sim.hull_presets import bem_lambda66
    from addedinertia_env.sim.mujoco_rig import MujocoRig
    from addedinertia_env.sim.params import SensorParams
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping
    from addedinertia_env.experiment.protocol import plan_from_preset

    data = load_preset("wigley-2m")
    params = rig_from_mapping(data, sensors=SensorParams.ideal())
    plan = plan_from_preset(data)
    lam = bem_lambda66("wigley-2m", "swing")
    priors = []
    for p in (plan, dataclasses.replace(plan, lambda66_prior=lam)):
        exp = Experiment(MujocoRig(params, seed=0), p)
        exp.start()
        priors.append(exp.inertia_prior)
    J_true = params.hull.J_hull + params.hull.lambda66
    assert priors[1] == pytest.approx(params.hull.J_hull + lam)
    # both priors are within a few percent of the truth; they differ (they are not the same number)
    assert abs(priors[0] / J_true - 1) < 0.05 and abs(priors[1] / J_true - 1) < 0.05 and priors[0] != priors[1]
    with pytest.raises(ValueError, match="lambda66_prior"):
        dataclasses.replace(plan, lambda66_prior=-1.0)


@needs_capytaine
def test_user_mesh_round_trip_and_lid_refused(capsys, tmp_path):
    from addedinertia_env.hydro.geometry import gdf_text

    q = quarter_mesh(WIGLEY, 100, "floating")
    good = tmp_path / "wigley.gdf"
    good.write_text(gdf_text(q))
    code, out, err = run_cli(capsys, "hull", good, "--json")
    assert code == 0, err
    obj = json.loads(out)
    assert obj["mesh_check"]["symmetry_planes"] and obj["resolution"]["panels"] == 4 * len(q.faces)
    assert obj["A66_inf"] < obj["A66_zero"] < obj["A66_swing"]
    # the same quarter with a panel lying in the centreplane: an internal lid under symmetry
    n = len(q.vertices)
    v = np.vstack([q.vertices, [[0.1, 0.0, -0.01], [0.2, 0.0, -0.01], [0.2, 0.0, -0.05], [0.1, 0.0, -0.05]]])
    f = np.vstack([q.faces, [[n, n + 1, n + 2, n + 3]]])
    lidded = tmp_path / "lidded.gdf"
    lidded.write_text(gdf_text(type(q)(v, f, q.nx, q.nz, q.shape, q.submergence)))
    code, out, err = run_cli(capsys, "hull", lidded, "--json")
    assert code == 2 and "internal lid" in err and out == ""


# --- radiation memory as a state-space system -----------------------------------------

def test_state_space_fit_recovers_a_known_rational_kernel():
    from addedinertia_env.hydro.radiation_ss import fit_radiation_ss

    # Kh(s) = 40 s / (s^2 + 3 s + 50): a damped resonance at ~7 rad/s, Kh(0) = 0
    w = np.linspace(0.2, 30.0, 150)
    s = 1j * w
    K = 40 * s / (s**2 + 3 * s + 50)
    a_inf = 5.0
    ss = fit_radiation_ss(w, a_inf + (K.imag / w), K.real, a_inf, tolerance=0.01)
    assert ss.order == 2 and ss.fit_error < 1e-3
    assert np.all(np.linalg.eigvals(ss.A).real < 0)
    t = np.linspace(0.0, 3.0, 31)
    # K(t) of 40 s/(s^2 + 3 s + 50): 40 e^{-1.5 t} (cos(wd t) - 1.5/wd sin(wd t)), wd = sqrt(50 - 2.25)
    wd = math.sqrt(50 - 2.25)
    exact = 40 * np.exp(-1.5 * t) * (np.cos(wd * t) - 1.5 / wd * np.sin(wd * t))
    assert np.max(np.abs(ss.kernel(t) - exact)) < 1e-2 * 40


def test_state_space_fit_of_the_cached_wigley_is_small_and_stable():
    from addedinertia_env.hydro.radiation_ss import fit_radiation_ss

    fine = read_cache(cache_path("wigley-2m"))["resolutions"]["fine"]
    ss = fit_radiation_ss(fine["omega"], fine["A66"], fine["B66"], fine["infinite_frequency"]["A66"], tolerance=0.05)
    assert ss.order <= 6 and ss.fit_error < 0.05
    assert np.all(np.linalg.eigvals(ss.A).real < 0)


def test_export_mesh_writes_a_gdf_quarter(capsys, tmp_path):
    out = tmp_path / "w.gdf"
    code, stdout, err = run_cli(capsys, "hull", "spheroid-7", "--export-mesh", out, "--panels", "100", "400", "--json")
    assert code == 0, err
    assert json.loads(stdout)["panels"] == 4 * int(out.read_text().splitlines()[3])
    lines = out.read_text().splitlines()
    assert lines[2].split() == ["1", "1"]  # both symmetry flags
    n = int(lines[3])
    assert len(lines) == 4 + 4 * n and abs(4 * n - 400) <= 40
    xyz = np.array([[float(v) for v in line.split()] for line in lines[4:]])
    assert xyz[:, 0].min() >= 0 and xyz[:, 1].min() >= 0 and xyz[:, 2].max() <= 1e-12  # the wetted quarter
