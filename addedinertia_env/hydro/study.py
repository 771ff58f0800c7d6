"""A hull's full hydrodynamic study and its cache beside the rig preset.

:func:`study` runs the BEM (Capytaine needed) at a coarse and a fine resolution over a
frequency sweep, and the zero-frequency, infinite-frequency and swing-frequency values at
three resolutions for the convergence check. The result is written to
``configs/rigs/<preset>.bem.json`` (:func:`write_cache`), with the Capytaine version, the
mesh parameters and the command that made it, so that ``addedinertia hull PRESET`` answers
from the file in well under a second and no test or demo re-solves it.

:func:`summary` turns a study (from the cache or fresh) into the numbers the command prints.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.atomic import atomic_write_text
from addedinertia_env.foundation.config_io import RIG_DIR, ConfigError
from addedinertia_env.hydro import estimates
from addedinertia_env.hydro.geometry import HullShape, quarter_mesh
from addedinertia_env.hydro.retardation import kernel_summary

FORMAT = "addedinertia-hull-bem/1"
DEFAULT_PANELS = (400, 1600)  # coarse, fine (whole-hull panel counts)
CONVERGENCE_FACTOR = 4  # the convergence table adds fine * 4
#: Frequencies of the sweep, rad/s: dense where the swing lives (0.25 to 3), then to where
#: wave radiation has died down again (24 rad/s).
DEFAULT_OMEGAS = tuple(np.round(np.concatenate([np.geomspace(0.25, 3.0, 9), np.linspace(3.75, 24.0, 28)]), 4))
DEPTHS_IN_DRAFTS = (12.0, 4.0, 2.4)  # water depth / draft for the tank-bottom rows


def cache_path(preset: str) -> Path:
    """Where a preset's BEM cache lives: ``configs/rigs/<preset>.bem.json``."""
    return RIG_DIR / f"{preset}.bem.json"


def read_cache(path: Path, shape: HullShape | None = None) -> dict[str, Any]:
    """A cache file, checked for format and (if given) that it was made for ``shape``."""
    try:
        data = json.loads(Path(path).read_text())
    except json.JSONDecodeError as e:
        raise ConfigError(f"{path}: not valid JSON ({e}); expected a BEM cache written by "
                          "'addedinertia hull PRESET --solve --write-cache'") from None
    if data.get("format") != FORMAT:
        raise ConfigError(f"{path}: format = {data.get('format')!r}; expected {FORMAT!r} (re-solve with --solve --write-cache)")
    if shape is not None and data.get("hull") != shape.as_dict():
        raise ConfigError(f"{path}: made for hull {data.get('hull')}, but the preset's hull is {shape.as_dict()}; "
                          "the cache is stale: re-solve with 'addedinertia hull PRESET --solve --write-cache'")
    return data


def write_cache(path: Path, data: dict[str, Any]) -> Path:
    """Write a study ``data`` (strict JSON) to the cache file ``path`` atomically; returns the path."""
    atomic_write_text(path, json.dumps(data, indent=1, allow_nan=False) + "\n")
    return Path(path)


def richardson(coarse: float, fine: float, finer: float) -> dict[str, float | None]:
    """Extrapolation from three resolutions (panels x4 each, panel size h / 2 each).

    Observed order ``p = log2((coarse - fine) / (fine - finer))`` and the limit
    ``finer + (finer - fine) / (2^p - 1)``; p is clipped to [0.5, 3] so a noisy level cannot
    send the limit far away. Returns ``{"order", "value"}`` (None when the levels do not
    converge monotonically).
    """
    d1, d2 = coarse - fine, fine - finer
    if d1 == 0 or d2 == 0 or d1 * d2 < 0:
        return {"order": None, "value": None}
    p = min(3.0, max(0.5, math.log2(d1 / d2)))
    return {"order": p, "value": finer - d2 / (2.0**p - 1.0)}


def study(shape: HullShape, *, swing_omega: float, panels: tuple[int, int] = DEFAULT_PANELS,
          omegas=DEFAULT_OMEGAS, floating: bool = True, convergence: bool = True,
          progress=None) -> dict[str, Any]:
    """The full BEM study of ``shape`` (see module docstring); JSON-ready dict."""
    from addedinertia_env.hydro.bem import solve_yaw  # noqa: PLC0415 - needs the optional Capytaine

    say = progress or (lambda *_: None)
    sub = "floating" if floating else "deep"
    depths = tuple(k * float(shape.draft) for k in DEPTHS_IN_DRAFTS)
    res = {}
    for label, n in zip(("coarse", "fine"), panels):
        say(f"{label}: {n} panels, {len(omegas)} frequencies")
        res[label] = solve_yaw(quarter_mesh(shape, n, sub), omegas if floating else [], floating=floating,
                               extra_depths=depths if floating else (), depth_omega=swing_omega if floating else None)
        say(f"  done in {res[label]['seconds']:.1f} s")
    levels = []
    if convergence:
        for n in (*panels, CONVERGENCE_FACTOR * panels[1]):
            say(f"convergence: {n} panels")
            r = solve_yaw(quarter_mesh(shape, n, sub), [swing_omega] if floating else [], floating=floating)
            levels.append({"panels": r["mesh"]["panels"], "A66_zero": r["zero_frequency"]["A66"],
                           "A66_inf": (r["infinite_frequency"] or {}).get("A66"),
                           "A66_swing": r["A66"][0] if r["A66"] else None, "seconds": r["seconds"]})
    conv: dict[str, Any] = {"levels": levels}
    if len(levels) == 3:
        for key in ("A66_zero", "A66_inf", "A66_swing"):
            vals = [lv[key] for lv in levels]
            if None not in vals:
                conv[key] = richardson(*vals)
    from addedinertia_env.foundation import machine  # noqa: PLC0415

    return {"format": FORMAT, "hull": shape.as_dict(), "floating": floating, "swing_omega": swing_omega,
            "capytaine_version": res["fine"]["capytaine_version"],
            "created_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "machine": machine.machine_line(), "resolutions": res, "convergence": conv}


def _interp(omega: list[float], values: list[float], w: float) -> float | None:
    if not omega or w < omega[0] or w > omega[-1]:
        return None
    return float(np.interp(w, omega, values))


def summary(data: dict[str, Any], *, swing_omega: float | None = None, kernel: bool = True) -> dict[str, Any]:
    """What ``addedinertia hull`` prints, from a study: values at the swing frequency and the limits.

    ``swing_omega`` (rad/s): where to read A66 and B66 (default: the study's own).
    """
    shape = HullShape(**data["hull"])
    w = float(swing_omega if swing_omega is not None else data["swing_omega"])
    fine, coarse = data["resolutions"]["fine"], data["resolutions"]["coarse"]
    floating = data.get("floating", True)

    def values(r):
        zf = r["zero_frequency"]
        inf = r.get("infinite_frequency") or {}
        return {"panels": r["mesh"]["panels"], "A66_zero": zf["A66"], "A66_inf": inf.get("A66"),
                "A66_swing": _interp(r["omega"], r["A66"], w) if floating else zf["A66"],
                "B66_swing": _interp(r["omega"], r["B66"], w) if floating else 0.0,
                "A22_zero": zf["A22"], "A26_zero": zf["A26"]}

    f, c = values(fine), values(coarse)
    change = {k: (f[k] / c[k] - 1.0) if isinstance(f[k], float) and c[k] not in (None, 0.0) else None
              for k in ("A66_zero", "A66_inf", "A66_swing")}
    out: dict[str, Any] = {
        "hull": data["hull"], "floating": floating, "capytaine_version": data.get("capytaine_version"),
        "bem_method": fine.get("bem_method"), "created_utc": data.get("created_utc"),
        "swing_omega": w, "swing_period": 2.0 * math.pi / w,
        **{k: f[k] for k in ("A66_swing", "B66_swing", "A66_zero", "A66_inf", "A22_zero", "A26_zero")},
        "resolution": {"panels": f["panels"], "nx": fine["mesh"].get("nx"), "nz": fine["mesh"].get("nz"),
                       "symmetry_planes": fine["mesh"].get("symmetry_planes")},
        "limits": {"zero": fine["zero_frequency"]["method"],
                   "infinite": (fine.get("infinite_frequency") or {}).get("method")},
        "convergence": {"coarse_panels": c["panels"], "fine_panels": f["panels"],
                        "relative_change_coarse_to_fine": change,
                        "extrapolated": {k: v for k, v in data.get("convergence", {}).items() if k != "levels"},
                        "levels": data.get("convergence", {}).get("levels", [])},
        "estimates": {"lamb_ellipsoid": estimates.lamb_estimate(shape, floating),
                      "strip_theory": estimates.strip_theory_estimate(shape) if floating else None},
    }
    # best estimates: Richardson-extrapolated where the three levels converge monotonically,
    # else the finest level (then the spread of the levels says how converged it is)
    levels = data.get("convergence", {}).get("levels", [])
    best = {}
    for key in ("A66_zero", "A66_inf", "A66_swing"):
        ex = (data.get("convergence", {}).get(key) or {}).get("value")
        vals = [lv[key] for lv in levels if lv.get(key) is not None]
        spread = (max(vals) - min(vals)) / abs(vals[-1]) if len(vals) >= 2 else None
        best[key] = {"value": ex if ex is not None else (vals[-1] if vals else out[key]),
                     "how": "extrapolated" if ex is not None else (
                         f"finest level, {levels[-1]['panels']} panels" if vals else "fine sweep"),
                     "levels_spread": spread}
    out["best"] = best
    if floating and out["A66_swing"] is not None:
        out["free_surface_effect_at_swing"] = out["A66_swing"] / out["A66_zero"] - 1.0
        out["irregular_frequency"] = fine["irregular_frequency"]
        out["mesh_omega_limit"] = fine.get("mesh_omega_limit")
        out["flagged_omegas"] = fine["flagged_omegas"]
        out["failed_omegas"] = fine["failed"]
        out["frequency_range"] = [fine["omega"][0], fine["omega"][-1]] if fine["omega"] else None
        dep = fine.get("at_depth_omega")
        if dep:
            out["tank_bottom_at_swing"] = {
                "omega": dep["omega"],
                "rows": [{"water_depth": r["water_depth"], "depth_over_draft": r["water_depth"] / float(shape.draft),
                          "A66": r["A66"], "change_vs_deep_water": (r["A66"] / dep["A66_deep_water"] - 1.0)
                          if r["A66"] is not None else None, **({"error": r["error"]} if "error" in r else {})}
                         for r in dep["depths"]]}
        if kernel and len(fine["omega"]) >= 3 and out["A66_inf"] is not None:
            k = kernel_summary(fine["omega"], fine["A66"], fine["B66"], out["A66_inf"])
            out["retardation"] = {key: k[key] for key in ("K0", "memory_time_5pct", "clipped_negative_B66",
                                                           "tail_fraction", "ogilvie_max_rel_error")}
            from addedinertia_env.hydro.radiation_ss import fit_radiation_ss  # noqa: PLC0415

            ss = fit_radiation_ss(fine["omega"], fine["A66"], fine["B66"], out["A66_inf"], tolerance=0.05)
            poles = np.linalg.eigvals(ss.A)
            out["radiation_state_space"] = {
                "order": ss.order, "fit_error": ss.fit_error, "tolerance": 0.05,
                "poles": [{"re": float(z.real), "im": float(z.imag)} for z in poles],
                "A": ss.A.tolist(), "b": ss.b.tolist(), "c": ss.c.tolist(),
                "how": "Kh(j w) = B66 + j w (A66 - A66(inf)) fitted by P(s)/Q(s), smallest order with error < 5 %"}
    return out
