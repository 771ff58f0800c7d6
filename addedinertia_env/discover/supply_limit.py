"""Discovery's word ``supply_limit``: the drive ran out of voltage (issue 28, Build 2).

A current driver on a fixed supply ``u_max`` drives the winding with ``u = R i + L i' + k_t
Omega``; as the flywheel speeds up the back-EMF ``k_t Omega`` eats into the supply, and
where ``R i`` no longer fits in what is left the driver's voltage sits at the supply and the
current falls short of what the controller asked for (the driver saturates). A record
shows it in three columns: the terminal voltage ``u`` pinned at the rail (the record's
``rig.u_max``) for a stretch of samples, the flywheel's rate (from ``psi``) whose back-EMF
takes a share of the supply with the voltage's sign, and, where the record logs it, the
current short of ``i_cmd``.

Named where the runs' controlled phases (hold and reverse stroke) spend at least
:data:`MIN_SATURATED_S` at the rail (stretches of :data:`MIN_STRETCH` samples or more, so a
noise spike is no saturation) with the back-EMF at least :data:`MIN_EMF_SHARE` of the
supply there. A record that states no ``u_max`` cannot tell (the rail is not known). Never
reads ``truth``.

What it does to the estimate: the method books the measured current, so a saturated driver
biases nothing through the bookkeeping; it costs tracking (the hull leaves its mirrored
path while the current is short), and the stroke's energy then differs from the plan's
(docs/ENERGY_METHOD.md, "The drive's flaws in the budget").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from addedinertia_env.records.record import RunRecord

RAIL_FRACTION = 0.97  # |u| at least this share of u_max: at the rail (a driver's PWM tops out at 95-100 %)
MIN_EMF_SHARE = 0.2  # the back-EMF's share of the supply at the rail: the supply limit is the back-EMF's doing
MIN_STRETCH = 3  # samples in a row at the rail
MIN_SATURATED_S = 0.02  # s at the rail over the runs' controlled phases
RATE_WINDOW = 11  # samples of the Savitzky-Golay rate of the flywheel


def _stretches(mask: np.ndarray, min_len: int) -> np.ndarray:
    """``mask`` with its runs of True shorter than ``min_len`` samples cleared."""
    out = np.zeros_like(mask)
    start = None
    for j, m in enumerate(np.append(mask, False)):
        if m and start is None:
            start = j
        elif not m and start is not None:
            if j - start >= min_len:
                out[start:j] = True
            start = None
    return out


def supply_fit(rec: RunRecord) -> dict[str, Any] | str:
    """Where ``rec``'s driver sat at its supply: seconds at the rail with the back-EMF's share, the
    current's shortfall there (where ``i_cmd`` is logged); or why the record cannot tell."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    u_max = rec.known.u_max
    if not u_max:
        return "the record states no supply (rig.u_max): the rail is not known"
    if "u" not in rec.samples or "psi" not in rec.samples:
        return "no voltage or flywheel angle column"
    ph = np.asarray(rec.phase)
    ctl = np.isin(ph, ["hold", "reverse"])
    if ctl.sum() < RATE_WINDOW + 2:
        return "no hold or reverse stroke (no controlled phase)"
    t = np.asarray(rec.t, float)
    dt = float(np.median(np.diff(t)))
    u = np.asarray(rec["u"], float)
    om = savgol_filter(np.asarray(rec["psi"], float), RATE_WINDOW, 2, deriv=1, delta=dt)
    emf = float(rec.known.k_t) * om * np.sign(u)  # the back-EMF against the drive's voltage
    at_rail = ctl & (np.abs(u) >= RAIL_FRACTION * u_max) & (emf >= MIN_EMF_SHARE * u_max)
    at_rail = _stretches(at_rail, MIN_STRETCH)
    out: dict[str, Any] = {"run": rec.name, "u_max": float(u_max), "saturated_s": float(at_rail.sum() * dt),
                           "controlled_s": float(ctl.sum() * dt)}
    if at_rail.any():
        out["emf_share"] = float(np.median(emf[at_rail]) / u_max)
        if "i_cmd" in rec.samples:
            i, ic = np.asarray(rec["i"], float), np.asarray(rec["i_cmd"], float)
            out["shortfall_a"] = float(np.median(np.abs(ic[at_rail]) - np.abs(i[at_rail])))
    return out


def judge(records: list[RunRecord]) -> dict[str, Any]:
    """The word's evidence over ``records``: ``named`` and ``why``, the per-run fits."""
    fits = [supply_fit(r) for r in records]
    runs = [f for f in fits if isinstance(f, dict)]
    ev: dict[str, Any] = {"named": False, "runs": [f if isinstance(f, dict) else {"why": f} for f in fits]}
    if not runs:
        ev["why"] = "no run can tell: " + "; ".join(sorted({f for f in fits if isinstance(f, str)}))
        return ev
    total = sum(f["saturated_s"] for f in runs)
    ev["saturated_s"] = total
    ev["named"] = bool(total >= MIN_SATURATED_S)
    if ev["named"]:
        sat = [f for f in runs if f["saturated_s"] > 0]
        share = float(np.median([f["emf_share"] for f in sat]))
        short = [f["shortfall_a"] for f in sat if "shortfall_a" in f]
        ev["emf_share"] = share
        ev["why"] = (f"the driver sat at its {sat[0]['u_max']:g} V supply for {total * 1e3:.0f} ms in {len(sat)} of "
                     f"{len(runs)} runs, the back-EMF taking {share:.0%} of it"
                     + (f", the current {float(np.median(short)):.2f} A short of its command" if short else ""))
    else:
        ev["why"] = (f"the driver sat at its supply for {total * 1e3:.0f} ms with the back-EMF over "
                     f"{MIN_EMF_SHARE:.0%} of it (named from {MIN_SATURATED_S * 1e3:g} ms)")
    return ev


__all__ = ["judge", "supply_fit", "MIN_SATURATED_S", "MIN_EMF_SHARE", "RAIL_FRACTION"]
