"""``addedinertia hull PRESET|MESH [--json] [--plot FILE] [--stability] [--from-record RUN.csv]``.

Hydrodynamics of a hull from its geometry (docs/HYDRODYNAMICS.md): A66 and B66 over
frequency by BEM (Capytaine, the optional ``[hull]`` extra), the zero- and
infinite-frequency limits, the value at the rig's swing frequency, the convergence check,
Cummins' retardation function, and (``--stability``) the ship's course stability from the
same added masses. A preset answers from its cache ``configs/rigs/PRESET.bem.json``;
``--solve`` recomputes (and ``--write-cache`` stores) it.
"""

from __future__ import annotations

import math
from pathlib import Path

from addedinertia_env.cli.common import BadInput, emit_json, info, positive_int

MEMORY_KEYS = ("memory", "A66_swing", "A66_swing_ci95", "A66_inf", "A66_inf_ci95")  # identify()'s, passed on
SOLVE_HELP = "recompute with the BEM even when a cache exists (needs Capytaine: pip install 'addedinertia[hull]')"


def register(sub) -> None:
    """Add the ``hull`` subcommand and its options to the subparsers ``sub`` (``addedinertia hull --help``)."""
    p = sub.add_parser("hull", help="hull hydrodynamics from geometry: BEM A66(omega), limits, memory, stability",
                       description="A66 and B66 of a hull in yaw from its shape (BEM), at the rig's swing "
                                   "frequency and at zero and infinite frequency, with a convergence check; "
                                   "presets answer from their cache (docs/HYDRODYNAMICS.md).")
    p.add_argument("hull", metavar="PRESET|MESH", help="a rig preset with hull.geometry, or a mesh file Capytaine reads")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--plot", metavar="FILE", default=None, help="figure of A66(omega), B66(omega) and K(t) (PNG)")
    p.add_argument("--solve", action="store_true", help=SOLVE_HELP)
    p.add_argument("--write-cache", action="store_true", help="with --solve on a preset: store the result beside the preset")
    p.add_argument("--panels", type=positive_int, nargs=2, metavar=("COARSE", "FINE"), default=None,
                   help="panel counts of the two resolutions when solving (default 400 1600)")
    p.add_argument("--deep", action="store_true", help="deeply submerged (no free surface) instead of floating")
    p.add_argument("--swing-omega", type=float, default=None, metavar="RAD_S",
                   help="frequency to report A66 at (default: the preset's undamped swing frequency; 1.57 for a mesh)")
    p.add_argument("--stability", action="store_true", help="course stability of the ship with these added masses")
    p.add_argument("--froude", type=float, default=0.2, help="Froude number of the ship for --stability (default 0.2)")
    p.add_argument("--lambda66-range", type=float, nargs=2, metavar=("LO", "HI"), default=None,
                   help="lambda66 interval (kg m^2) for --stability (default: BEM zero frequency +-5 %%)")
    p.add_argument("--from-record", metavar="RUN.csv", nargs="+", default=None,
                   help="take lambda66 = A66(0) and its 95 %% interval from run record(s) as identify() gives them "
                        "(implies --stability; overrides --lambda66-range)")
    p.add_argument("--method", default="energy", help="identification method for --from-record (default energy)")
    p.add_argument("--fit-memory", action="store_true",
                   help="only fit the simulator's radiation-memory model (passive state space, docs/RADIATION_MEMORY.md) "
                        "to a preset's cached sweep and store it in the cache as 'memory_model', and stop (no BEM solve)")
    p.add_argument("--export-mesh", metavar="FILE.gdf", default=None,
                   help="only write a preset's generated quarter mesh (fine resolution, or --panels FINE) in WAMIT GDF "
                        "format, and stop (nothing is solved)")
    p.add_argument("--netcdf", metavar="FILE.nc", default=None,
                   help="only solve (a preset at its fine resolution, or --panels FINE; a mesh as given) and write "
                        "Capytaine's own dataset as NetCDF, with the cached memory model as attributes, and stop "
                        "(needs Capytaine; docs/DATASETS.md)")
    p.set_defaults(func=run)


def _study_for(args) -> tuple[dict, dict]:
    """(study, facts) for the target: cached or solved."""
    from addedinertia_env.hydro import study as st  # noqa: PLC0415
    from addedinertia_env.hydro.bem import CapytaineMissing  # noqa: PLC0415

    target = args.hull
    suffix = Path(target).suffix.lower()
    is_mesh = suffix not in ("", ".yaml", ".yml")
    if is_mesh and not Path(target).is_file():
        raise BadInput(f"{target}: no such mesh file; expected a rig preset name or a mesh file Capytaine reads")
    if is_mesh:
        return _study_mesh(args), {"preset": None, "swing_omega": args.swing_omega or 1.57}
    from addedinertia_env.sim.hull_presets import preset_hull  # noqa: PLC0415

    shape, facts = preset_hull(target)
    if args.swing_omega is not None:
        facts["swing_omega"] = args.swing_omega
    path = st.cache_path(facts["preset"])
    floating = not args.deep
    if not args.solve and not args.panels and path.exists() and floating:
        data = st.read_cache(path, shape)
        facts["cache"] = str(path)
        return data, facts
    if not args.solve:
        why = "a deeply submerged study is not cached" if args.deep else (
            "--panels asks for a new solve" if args.panels else f"no cache at {path}")
        info(f"{why}: solving with the BEM (a few minutes on 2 cores)")
    panels = tuple(args.panels) if args.panels else st.DEFAULT_PANELS
    try:
        data = st.study(shape, swing_omega=facts["swing_omega"], panels=panels, floating=floating, progress=info)
    except CapytaineMissing as e:
        raise BadInput(f"{target}: {e}") from None
    data["preset"] = facts["preset"]
    data["command"] = f"addedinertia hull {facts['preset']} --solve --write-cache"
    if args.write_cache:
        if not floating or panels != st.DEFAULT_PANELS:
            raise BadInput("--write-cache: the cache holds the floating hull at the default panels (400 1600); "
                           "drop --deep/--panels")
        st.write_cache(path, data)
        info(f"cache written to {path}")
        facts["cache"] = str(path)
    return data, facts


def _study_mesh(args) -> dict:
    from addedinertia_env.hydro import study as st  # noqa: PLC0415
    from addedinertia_env.hydro.bem import CapytaineMissing, load_user_mesh, solve_yaw  # noqa: PLC0415
    from addedinertia_env.hydro.mesh_checks import MeshError  # noqa: PLC0415

    if args.write_cache or args.panels:
        raise BadInput(f"{args.hull}: --write-cache and --panels apply to presets; a mesh is solved as given")
    floating = not args.deep
    try:
        mesh, report = load_user_mesh(args.hull, floating=floating)
        w = args.swing_omega or 1.57
        r = solve_yaw(mesh, st.DEFAULT_OMEGAS if floating else [], floating=floating, depth_omega=None)
    except CapytaineMissing as e:
        raise BadInput(f"{args.hull}: {e}") from None
    except (MeshError, ValueError) as e:
        raise BadInput(str(e)) from None
    info(f"{args.hull}: {report.panels} panels, volume {report.volume:.4g} m^3; one resolution only "
         "(give a finer mesh and compare for convergence)")
    return {"format": st.FORMAT, "hull": None, "mesh_file": args.hull, "floating": floating, "swing_omega": w,
            "capytaine_version": r["capytaine_version"], "resolutions": {"coarse": r, "fine": r},
            "convergence": {"levels": []}}


def run(args) -> int:
    """Run ``addedinertia hull`` with the parsed ``args``; prints the radiation study of the hull (added inertia A66 in kg m^2 and damping over frequency, convergence) from its cache or solved now, or with ``--export-mesh`` writes the mesh only; returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.hydro import study as st  # noqa: PLC0415

    if args.export_mesh:  # write the mesh and stop: nothing is solved
        written = _export(args)
        if args.json:
            emit_json(written)
        return 0
    if args.netcdf:  # solve, write Capytaine's dataset and stop
        written = _netcdf(args)
        if args.json:
            emit_json(written)
        return 0
    if args.fit_memory:  # fit the memory model to the cached sweep and stop
        fitted = _fit_memory(args)
        if args.json:
            emit_json(fitted)
        return 0

    data, facts = _study_for(args)
    if data.get("hull") is None:
        out = _mesh_summary(data)
    else:
        out = st.summary(data, swing_omega=facts.get("swing_omega"))
    out["source"] = facts.get("cache") or "solved now"
    if facts.get("preset"):
        out["preset"] = {"name": facts["preset"], "lambda66": facts["lambda66"],
                         "lambda66_source": facts["lambda66_source"], "swing_period": facts["swing_period"]}
    if args.plot:
        from addedinertia_env.hydro.figures import plot_study  # noqa: PLC0415

        out["plot"] = str(plot_study(data, args.plot, swing_omega=facts.get("swing_omega")))
        info(f"figure written to {out['plot']}")
    if args.stability or args.from_record:
        out["stability"] = _stability(args, data, out)
    if args.json:
        emit_json(out)
    else:
        print("\n".join(_lines(out)))
    return 0


def _fit_memory(args) -> dict:
    """Fit the simulator's memory model to a preset's cached sweep and store it in the cache."""
    from addedinertia_env.hydro import study as st  # noqa: PLC0415
    from addedinertia_env.hydro.memory_fit import memory_model_from_cache  # noqa: PLC0415
    from addedinertia_env.sim.hull_presets import preset_hull  # noqa: PLC0415

    if args.solve or args.deep or args.panels:
        raise BadInput("--fit-memory fits the cached floating-hull sweep: drop --solve/--deep/--panels "
                       "(re-solve first with --solve --write-cache if the cache is stale)")
    shape, facts = preset_hull(args.hull)
    path = st.cache_path(facts["preset"])
    if not path.exists():
        raise BadInput(f"{path}: no BEM cache to fit; expected one written by "
                       f"'addedinertia hull {facts['preset']} --solve --write-cache'")
    data = st.read_cache(path, shape)
    try:
        block = memory_model_from_cache(data)
    except ValueError as e:
        raise BadInput(f"{path}: {e}") from None
    block["command"] = f"addedinertia hull {facts['preset']} --fit-memory"
    data["memory_model"] = block
    st.write_cache(path, data)
    info(f"{path}: memory model of order {block['order']} (fit error {100 * block['fit_error']:.1f} %, "
         f"A66(inf)/A66(0) {block['a_inf_ratio']:.4f}, A66(swing)/A66(0) {block['a_swing_ratio']:.4f}) stored")
    return {"cache": str(path), **{k: block[k] for k in ("order", "fit_error", "a_inf_ratio", "a_swing_ratio",
                                                            "swing_omega", "poles", "min_B_on_grid")}}


def _netcdf(args) -> dict:
    from addedinertia_env.hydro.bem import CapytaineMissing  # noqa: PLC0415
    from addedinertia_env.hydro.mesh_checks import MeshError  # noqa: PLC0415
    from addedinertia_env.hydro.netcdf import export  # noqa: PLC0415
    from addedinertia_env.sim.hull_presets import preset_hull  # noqa: PLC0415

    if args.deep or args.solve or args.write_cache:
        raise BadInput("--netcdf solves the floating hull and writes only the NetCDF file: drop --deep/--solve/--write-cache")
    if Path(args.hull).suffix.lower() not in ("", ".yaml", ".yml") and not Path(args.hull).is_file():
        raise BadInput(f"{args.hull}: no such mesh file; expected a rig preset name or a mesh file Capytaine reads")
    try:
        out = export(args.hull, args.netcdf, panels=args.panels[1] if args.panels else None, preset_hull=preset_hull)
    except CapytaineMissing as e:
        raise BadInput(f"{args.hull}: --netcdf: {e}") from None
    except (MeshError, ValueError) as e:
        raise BadInput(str(e)) from None
    info(f"Capytaine dataset written to {out['netcdf']} ({out['panels']} panels, {out['omegas']} frequencies"
         f"{', memory model as attributes' if out['memory_model'] else ''})")
    return out


def _export(args) -> dict:
    from addedinertia_env.foundation.atomic import atomic_write_text  # noqa: PLC0415
    from addedinertia_env.hydro import study as st  # noqa: PLC0415
    from addedinertia_env.hydro.geometry import gdf_text, quarter_mesh  # noqa: PLC0415
    from addedinertia_env.sim.hull_presets import preset_hull  # noqa: PLC0415

    shape, facts = preset_hull(args.hull)
    n = args.panels[1] if args.panels else st.DEFAULT_PANELS[1]
    q = quarter_mesh(shape, n, "deep" if args.deep else "floating")
    atomic_write_text(args.export_mesh, gdf_text(q, f"{facts['preset']} {q.submergence}, {q.nb_faces_full} panels"))
    info(f"mesh written to {args.export_mesh} ({q.nb_faces_full} panels, quarter with both symmetries)")
    return {"mesh": str(args.export_mesh), "panels": q.nb_faces_full, "nx": q.nx, "nz": q.nz,
            "submergence": q.submergence, "hull": shape.as_dict(), "format": "gdf"}


def _mesh_summary(data: dict) -> dict:
    from addedinertia_env.hydro import study as st  # noqa: PLC0415

    r = data["resolutions"]["fine"]
    w = data["swing_omega"]
    out = {"mesh_file": data["mesh_file"], "floating": data["floating"], "capytaine_version": data["capytaine_version"],
           "swing_omega": w, "A66_zero": r["zero_frequency"]["A66"],
           "A66_inf": (r.get("infinite_frequency") or {}).get("A66"),
           "A22_zero": r["zero_frequency"]["A22"], "A26_zero": r["zero_frequency"]["A26"],
           "A66_swing": st._interp(r["omega"], r["A66"], w) if r["omega"] else r["zero_frequency"]["A66"],
           "resolution": {"panels": r["mesh"]["panels"]}, "mesh_check": r["mesh"],
           "irregular_frequency": r.get("irregular_frequency"), "flagged_omegas": r.get("flagged_omegas"),
           "convergence": None}
    return out


def _stability(args, data: dict, out: dict) -> dict:
    from addedinertia_env.hydro.geometry import HullShape  # noqa: PLC0415
    from addedinertia_env.hydro.stability import GRAVITY, Ship, stability  # noqa: PLC0415

    if data.get("hull") is None:
        raise BadInput("--stability needs the hull's L, B, T and block coefficient: use a preset with hull.geometry")
    shape = HullShape(**data["hull"])
    if not (0.0 < args.froude < 1.0):
        raise BadInput(f"--froude {args.froude}: expected 0 < Fn < 1")
    ship = Ship(shape.length, shape.beam, float(shape.draft), shape.block_coefficient(),
                args.froude * math.sqrt(GRAVITY * shape.length))
    added = {"lambda22": out["A22_zero"], "lambda26": out["A26_zero"], "lambda66": out["A66_zero"]}
    rng = tuple(args.lambda66_range) if args.lambda66_range else (0.95 * added["lambda66"], 1.05 * added["lambda66"])
    measured = None
    if args.from_record:
        from addedinertia_env.identify import METHODS, identify  # noqa: PLC0415
        from addedinertia_env.records.record import read_record  # noqa: PLC0415

        if args.method not in METHODS:
            raise BadInput(f"--method {args.method!r}: expected one of {', '.join(METHODS)}")
        res = identify([read_record(p) for p in args.from_record], method=args.method)
        # identify()'s lambda66 is A66(0) by definition (spec/run-record.md), the zero-frequency value
        # manoeuvring needs: used as it is, with its interval; no BEM ratio (the records alone decide)
        rng = (float(res.ci95[0]), float(res.ci95[1]))
        added["lambda66"] = float(res.lambda66)
        measured = {"records": args.from_record, "method": res.method, "lambda66_measured": res.lambda66,
                    "ci95_measured": list(res.ci95), "lambda66_is": "A66(0), identify()'s lambda66",
                    "lambda66_used": added["lambda66"], "ci95_used": list(rng)}
        for key in MEMORY_KEYS:  # what the identification says of the water's memory, when it says it
            if key in res.details:
                measured[key] = res.details[key]
    if rng[0] <= 0 or rng[1] <= rng[0]:
        raise BadInput(f"--lambda66-range {rng[0]} {rng[1]}: expected 0 < LO < HI (kg m^2)")
    result = stability(ship, added, rng)
    if measured:
        result["from_record"] = measured
    return result


def _fmt(v, spec=".4g") -> str:
    return "n/a" if v is None else format(v, spec)


def _lines(out: dict) -> list[str]:
    name = (out.get("preset") or {}).get("name") or out.get("mesh_file")
    res = out["resolution"]
    lines = [f"{name}: A66 at the swing frequency {out['swing_omega']:.3g} rad/s = {_fmt(out['A66_swing'])} kg m^2 "
             f"({res['panels']} panels, {out.get('source')})",
             f"  zero frequency (rigid lid) A66 = {_fmt(out['A66_zero'])}, infinite frequency A66 = {_fmt(out['A66_inf'])} kg m^2"]
    conv = out.get("convergence")
    if conv:
        ch = conv["relative_change_coarse_to_fine"]
        lines.append(f"  convergence {conv['coarse_panels']} -> {conv['fine_panels']} panels: A66(0) "
                     f"{_fmt(100 * ch['A66_zero'], '+.2f')} %, A66(swing) {_fmt(ch['A66_swing'] and 100 * ch['A66_swing'], '+.2f')} %")
        b = out.get("best") or {}
        if b:
            lines.append("  best estimates: " + ", ".join(
                f"{k} {v['value']:.4g} ({v['how']})" for k, v in b.items() if v.get("value") is not None))
    if out.get("free_surface_effect_at_swing") is not None:
        lines.append(f"  free-surface effect at the swing frequency: {100 * out['free_surface_effect_at_swing']:+.2f} %")
    est = out.get("estimates")
    if est:
        lines.append(f"  Lamb ellipsoid {_fmt(est['lamb_ellipsoid'])}, strip theory {_fmt(est['strip_theory'])} kg m^2")
    if out.get("preset"):
        lines.append(f"  preset lambda66 = {out['preset']['lambda66']:.4g} kg m^2 ({out['preset']['lambda66_source']})")
    if out.get("flagged_omegas"):
        lines.append(f"  flagged frequencies: {len(out['flagged_omegas'])} (see --json)")
    rt = out.get("retardation")
    if rt:
        lines.append(f"  retardation K(0) = {rt['K0']:.4g} N m, memory {rt['memory_time_5pct']:.2f} s, "
                     f"Ogilvie check {100 * rt['ogilvie_max_rel_error']:.2f} %")
    ss = out.get("radiation_state_space")
    if ss:
        lines.append(f"  radiation memory as a state-space system: order {ss['order']}, fit error {100 * ss['fit_error']:.1f} %")
    stab = out.get("stability")
    if stab:
        n = stab["nominal"]
        lines.append(f"  course stability (Fn {stab['ship']['froude_number']:.2f}): stable = {n['hurwitz']['stable']}, "
                     f"C' = {stab['stability_index_C_nondimensional'] if 'stability_index_C_nondimensional' in stab else n['stability_index_C_nondimensional']:.3g}, "
                     f"time constants {', '.join(f'{t:.3g}' for t in n['time_constants'])} s")
        r = stab.get("lambda66_range")
        if r and r.get("time_constants_span"):
            lines.append(f"  over lambda66 in [{r['lambda66'][0]:.4g}, {r['lambda66'][1]:.4g}]: stable throughout = "
                         f"{r['stable_throughout']}, slow time constant {r['time_constants_span'][0][0]:.3g} .. "
                         f"{r['time_constants_span'][0][1]:.3g} s")
    return lines
