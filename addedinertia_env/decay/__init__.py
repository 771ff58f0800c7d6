"""Damping laws from a series of successive free-decay amplitudes (the textbook's record).

Input: a CSV with columns ``swing`` (successive half-swing numbers, 1, 2, 3, ...) and
``theta_deg`` (amplitude in degrees, > 0); other columns are ignored. This is the form
of ``addedinertia_env/data/textbook/textbook_roll_decay.csv`` (source 004, tables 6.1 and 6.2).

Two things are done with it:

1. **The textbook's procedure reproduced** (``textbook_processing``): formula 6.17
   (Blagoveshchensky) ``nu = 2 dtheta / (pi theta_mean)`` and formula 6.18
   ``nu = (2/pi) d ln(theta)``, on the raw decrements and, where the textbook's own
   processing table is given, on its hand-smoothed decrements, compared with its printed
   columns (maximum absolute difference).
2. **Our own analysis of the raw series** (``fit_laws``): candidate envelope laws
   ``d theta / dN = -f(theta)`` per half swing ``N``, each integrated in closed form and
   fitted to the *amplitudes* by output error (so the reading errors stay independent,
   which they are not in differenced decrements), weighted by the reading resolution:

   ========================  ===============================
   law                        f(theta)
   ========================  ===============================
   ``linear``                 a theta (the nominal law)
   ``quadratic``              b theta^2
   ``coulomb``                c
   ``linear+quadratic``       a theta + b theta^2
   ``linear+coulomb``         a theta + c
   ========================  ===============================

   with chi-square against the resolution, AIC and BIC, parameter 95 % intervals,
   residual runs and lag-1 autocorrelation. For ``linear`` damping ``nu = 2 a / pi`` is
   constant; a nu that falls with the amplitude says quadratic, one that rises says dry.

The amplitude resolution: every printed amplitude is a multiple of 0.1025 deg (0.5 mm of
trace at 0.205 deg/mm, ``addedinertia_env/data/textbook/README.md``), so a rounding error uniform over
one step has a standard deviation 0.1025 / sqrt(12) = 0.0296 deg.
"""

from __future__ import annotations

import math
from pathlib import Path

from addedinertia_env.decay.amplitudes import (
    MIN_AMPLITUDES,
    READING_RESOLUTION_DEG,
    READING_SIGMA_DEG,
    Amplitudes,
    DecayInputError,
    read_amplitudes,
)
from addedinertia_env.decay.figure import plot
from addedinertia_env.decay.laws import LAWS, UNITS, LawFit, envelope, fit_law, fit_laws, law_nu, nested_f_test
from addedinertia_env.decay.textbook import nu_blagoveshchensky, nu_logarithmic, textbook_processing

__all__ = ["MIN_AMPLITUDES", "READING_RESOLUTION_DEG", "READING_SIGMA_DEG", "Amplitudes", "DecayInputError",
           "read_amplitudes", "plot", "LAWS", "UNITS", "LawFit", "envelope", "fit_law", "fit_laws", "law_nu",
           "nested_f_test", "nu_blagoveshchensky", "nu_logarithmic", "textbook_processing", "analyse"]


def analyse(path: str | Path, processing: str | Path | None = None) -> dict:
    """Everything ``addedinertia decay`` reports; ``processing``: the textbook's processing table, if any."""
    amp = read_amplitudes(path)
    if processing is None:
        sibling = Path(path).with_name(Path(path).stem + "_processing.csv")
        processing = sibling if sibling.exists() else None
    fits = fit_laws(amp)
    by = {f.law: f for f in fits}
    best = fits[0]
    lin = by["linear"]
    out = {
        "file": amp.path, "n_amplitudes": int(len(amp.theta)),
        "reading_sigma_deg": READING_SIGMA_DEG,
        "law": best.law,
        "models": [f.to_json() for f in fits],
        "delta_bic_vs_linear": {f.law: lin.bic - f.bic for f in fits},
        "f_test_p": {"linear -> linear+quadratic": nested_f_test(lin, by["linear+quadratic"]),
                     "linear -> linear+coulomb": nested_f_test(lin, by["linear+coulomb"])},
        "nominal_law": {"law": "linear", "nu": float(2 / math.pi * lin.params["a"]),
                        "chi2_per_dof": lin.chi2 / lin.dof, "sign_runs": lin.runs,
                        "sign_runs_expected": lin.runs_expected, "residual_lag1": lin.lag1},
        "textbook": textbook_processing(amp, processing),
    }
    # Sensitivity: the last three decrements are one to three reading steps; drop them.
    if len(amp.theta) > 8:
        short = Amplitudes(path=amp.path, swing=amp.swing[:-3], theta=amp.theta[:-3])
        sf = fit_laws(short)
        out["without_last_three"] = {"law": sf[0].law, "models": [
            {"law": f.law, "params": f.params, "chi2_per_dof": f.chi2 / f.dof, "bic": f.bic} for f in sf]}
    # nu at the record's mean amplitudes for each law, next to the textbook's
    tm = 0.5 * (amp.theta[:-1] + amp.theta[1:])
    out["nu_by_law"] = {"theta_mean_deg": tm.tolist(),
                        **{f.law: law_nu(f.law, f.params, tm).tolist() for f in fits}}
    return out
