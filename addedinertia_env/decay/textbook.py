"""The textbook's own processing (formulas 6.17 and 6.18), reproduced and checked against its printed columns."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from addedinertia_env.decay.amplitudes import Amplitudes, DecayInputError, read_text


def nu_blagoveshchensky(dtheta, theta_mean):
    """Formula 6.17: nu = 2 dtheta / (pi theta_mean)."""
    return 2.0 * np.asarray(dtheta) / (math.pi * np.asarray(theta_mean))


def nu_logarithmic(dln_theta):
    """Formula 6.18: nu = (2 / pi) d ln(theta)."""
    return 2.0 / math.pi * np.asarray(dln_theta)


def _read_processing(path: Path) -> dict[str, np.ndarray]:
    rows = list(csv.DictReader(read_text(path, "the textbook's processing table (CSV)").splitlines()))
    if not rows:
        raise DecayInputError(f"{path}: no rows; expected the textbook's processing table with a header line")
    need = ("swing", "dtheta_raw_deg", "dtheta_smoothed_deg", "theta_mean_deg", "nu_formula_6_17", "ln_theta",
            "dln_raw", "dln_smoothed", "nu_formula_6_18")
    missing = [c for c in need if c not in rows[0]]
    if missing:
        raise DecayInputError(f"{path}: line 1: missing column(s) {missing} of the textbook processing table")
    out = {}
    for c in need:
        vals = []
        for n, r in enumerate(rows, start=2):
            text = (r[c] or "").strip()
            try:
                vals.append(float(text) if text else math.nan)
            except ValueError:
                raise DecayInputError(f"{path}: line {n}, column '{c}': {text!r} is not a number; expected a finite number") from None
        out[c] = np.array(vals)
    return out


def textbook_processing(amp: Amplitudes, processing: str | Path | None) -> dict:
    """Formulas 6.17 and 6.18 on the raw series; and, with the textbook's table, on its smoothed decrements."""
    th = amp.theta
    dtheta = th[:-1] - th[1:]
    theta_mean = 0.5 * (th[:-1] + th[1:])
    dln = np.log(th[:-1]) - np.log(th[1:])
    out: dict = {"raw": {"swing": amp.swing[1:].tolist(), "dtheta_deg": dtheta.tolist(),
                         "theta_mean_deg": theta_mean.tolist(),
                         "nu_6_17": nu_blagoveshchensky(dtheta, theta_mean).tolist(),
                         "nu_6_18": nu_logarithmic(dln).tolist()}}
    if processing is None:
        out["printed"] = None
        return out
    p = _read_processing(Path(processing))
    rows = ~np.isnan(p["dtheta_smoothed_deg"])
    sw = p["swing"][rows]
    if not np.array_equal(sw, amp.swing[1:][: len(sw)]):
        raise DecayInputError(f"{processing}: swings {sw.tolist()} do not match the amplitude file's "
                              f"{amp.swing[1:].tolist()}")
    nu17 = nu_blagoveshchensky(p["dtheta_smoothed_deg"][rows], p["theta_mean_deg"][rows])
    nu18 = nu_logarithmic(p["dln_smoothed"][rows])
    n = len(sw)

    def cmp(ours, printed):
        d = np.abs(np.asarray(ours) - np.asarray(printed))
        return {"max_abs_diff": float(np.max(d)), "at_swing": int(sw[int(np.argmax(d))])}

    out["printed"] = {
        "file": str(processing), "swing": sw.tolist(),
        "dtheta_smoothed_deg": p["dtheta_smoothed_deg"][rows].tolist(),
        "theta_mean_deg": p["theta_mean_deg"][rows].tolist(),
        "dln_smoothed": p["dln_smoothed"][rows].tolist(),
        "nu_6_17_printed": p["nu_formula_6_17"][rows].tolist(), "nu_6_17_reproduced": nu17.tolist(),
        "nu_6_18_printed": p["nu_formula_6_18"][rows].tolist(), "nu_6_18_reproduced": nu18.tolist(),
        "check_nu_6_17": cmp(nu17, p["nu_formula_6_17"][rows]),
        "check_nu_6_18": cmp(nu18, p["nu_formula_6_18"][rows]),
        "check_dtheta_raw": cmp(dtheta[:n], p["dtheta_raw_deg"][rows]),
        "check_theta_mean": cmp(theta_mean[:n], p["theta_mean_deg"][rows]),
        "check_ln_theta": {"max_abs_diff": float(np.nanmax(np.abs(np.log(th) - p["ln_theta"][: len(th)])))},
        "check_dln_raw": cmp(dln[:n], p["dln_raw"][rows]),
        # The hand-smoothed decrements against the raw ones: how much the author's curve moved them.
        "smoothing_shift_deg": {"mean": float(np.mean(p["dtheta_smoothed_deg"][rows] - dtheta[:n])),
                                "rms": float(np.sqrt(np.mean((p["dtheta_smoothed_deg"][rows] - dtheta[:n]) ** 2)))},
    }
    return out
