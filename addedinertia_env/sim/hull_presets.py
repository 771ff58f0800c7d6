"""The hull of a rig preset: its ``hull.geometry`` block as a :class:`HullShape`.

A preset names its analytic hull so that its hydrodynamics can be computed from the
shape (``addedinertia hull PRESET``)::

    hull:
      geometry: {shape: wigley, length: 2.0, beam: 0.2, draft: 0.125}   # metres
"""

from __future__ import annotations

from typing import Any

from addedinertia_env.sim.presets import ConfigError, load_preset, load_rig
from addedinertia_env.hydro.geometry import HullShape, shape_from_mapping


def preset_hull(name: str) -> tuple[HullShape, dict[str, Any]]:
    """(shape, facts) of preset ``name``: facts hold the swing frequency (rad/s) and lambda66 in use."""
    data = load_preset(name)
    where = f"{data['_path']}: hull.geometry"
    block = (data.get("hull") or {}).get("geometry")
    if block is None:
        raise ConfigError(f"{data['_path']}: hull.geometry missing; expected e.g. "
                          "{shape: wigley, length: 2.0, beam: 0.2, draft: 0.125} to compute its hydrodynamics")
    shape = shape_from_mapping(block, where)
    rig = load_rig(name)
    ai = (data.get("hull") or {}).get("added_inertia") or {}
    owner = data.get("name", name)
    base = data.get("extends")
    if base and load_preset(base).get("hull") == data.get("hull"):
        owner = load_preset(base).get("name", base)  # a preset that extends another's hull shares its BEM cache
    facts = {"preset": owner, "path": data["_path"],
             "swing_omega": 2.0 * 3.141592653589793 / rig.natural_period,
             "swing_period": rig.natural_period,
             "lambda66": rig.hull.lambda66, "J_hull": rig.hull.J_hull,
             "lambda66_source": ai.get("source") or ai.get("model") or "given"}
    return shape, facts


def bem_lambda66(name: str, at: str = "swing") -> float:
    """The BEM's best lambda66 of preset ``name`` from its cache (kg m^2), no solver needed.

    ``at``: ``'swing'`` (A66 at the rig's undamped swing frequency: what the rig measures),
    ``'zero'`` (rigid-lid limit) or ``'infinite'``. Best: extrapolated from three
    resolutions when they converge monotonically, else the finest.
    """
    from addedinertia_env.hydro.study import cache_path, read_cache, summary  # noqa: PLC0415

    shape, facts = preset_hull(name)
    s = summary(read_cache(cache_path(facts["preset"]), shape), swing_omega=facts["swing_omega"], kernel=False)
    key = {"swing": "A66_swing", "zero": "A66_zero", "infinite": "A66_inf"}.get(at)
    if key is None:
        raise ValueError(f"at = {at!r}: expected 'swing', 'zero' or 'infinite'")
    return float(s["best"][key]["value"])
