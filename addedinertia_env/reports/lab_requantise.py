"""Another lab's reverse runs re-quantised at random encoder offsets: is its interval sized to its quantisation?

A lab's records give one quantisation draw per run, and the runs of one case are not independent draws: a
deterministic simulator (or a repeatable rig) started from the same angle at the same instants records the same
free stroke to the bit (foreign-lab's ``run-03`` and ``run-04`` of every case do), so their errors move together.
This report makes the draws the records cannot: each hull angle channel is smoothed within each moving phase (a
quintic Savitzky-Golay filter over 101 samples; braked phases continue the neighbouring stroke's angle) and read
again through the record's own encoder (its ``encoder_counts``, its sample instants) with the grid shifted by a
random fraction of a count. Every other channel is the record's own. ``identify(records, "energy", memory=True)``
then gives one estimate and one per-run sigma budget per offset.

The smoothed angle is not the lab's truth: what is left of the original reading's quantisation in it (a
fraction of a count) is common to every offset and shifts the mean, not the scatter; near a turning point it can
make the re-read angle step back and forth a few times where the lab's reading stepped once, so the scatter is an
upper bound of the quantisation's. Scoring code: it reads the archive's ``answers.json`` (the errors only).

    python -m addedinertia_env.reports.lab_requantise ARCHIVE.tar.xz --runs case-02/run-03,case-04/run-05 \\
        --offsets 40 --seed 7
"""

from __future__ import annotations

import argparse
import json
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

SMOOTH_SAMPLES = 101  # Savitzky-Golay window (samples): 0.1 s at 1 kHz, a tenth of a free swing's half period
SMOOTH_ORDER = 5
Z95 = 1.959963984540054


def smooth_angle(phi: np.ndarray, phase: np.ndarray, q: float) -> np.ndarray:
    """The hull angle (rad) smoothed within each moving phase; a braked phase (spanning under three counts)
    takes the angle where the neighbouring moving phase ends (or, first in the record, begins)."""
    from scipy.signal import savgol_filter  # noqa: PLC0415

    phi = np.asarray(phi, dtype=float)
    out = phi.copy()
    edges = np.nonzero(phase[1:] != phase[:-1])[0] + 1
    segs = list(zip(np.r_[0, edges].tolist(), np.r_[edges, len(phi)].tolist()))
    moving = [b - a > SMOOTH_SAMPLES and np.ptp(phi[a:b]) > 3 * q for a, b in segs]
    for (a, b), m in zip(segs, moving):
        if m:
            out[a:b] = savgol_filter(phi[a:b], SMOOTH_SAMPLES, SMOOTH_ORDER, mode="interp")
    for j, (a, b) in enumerate(segs):
        if moving[j]:
            continue
        if j > 0 and moving[j - 1]:
            out[a:b] = out[a - 1]
        elif j + 1 < len(segs) and moving[j + 1]:
            out[a:b] = out[b]
    return out


def requantise(angle: np.ndarray, q: float, offset: float) -> np.ndarray:
    """``angle`` (rad) read by an encoder of step ``q`` (rad) whose grid is shifted by ``offset`` counts (0-1)."""
    return q * (np.round(np.asarray(angle, dtype=float) / q + offset) - offset)


def requantised_runs(case_dir: Path, run: str, offsets: np.ndarray) -> list[dict]:
    """Identify ``case_dir/run`` (with the case's free decays) once per encoder offset: lambda66 and its parts."""
    from addedinertia_env.identify import identify  # noqa: PLC0415
    from addedinertia_env.records.record import read_record  # noqa: PLC0415
    from addedinertia_env.records.run_record import RunRecord  # noqa: PLC0415

    rev = read_record(case_dir / f"{run}.csv")
    decays = [read_record(p) for p in sorted(case_dir.glob("*.csv"))
              if json.loads(p.with_suffix(".json").read_text())["experiment"]["kind"] == "free-decay"]
    counts = rev.known.phi_counts
    q = 2.0 * np.pi / counts
    smooth = smooth_angle(rev["phi"], np.asarray(rev["phase"]), q)
    out = []
    for u in offsets.tolist():
        rec = RunRecord(samples={**rev.samples, "phi": requantise(smooth, q, u)}, meta=rev.meta, path=rev.path,
                        gaps=rev.gaps)
        res = identify([rec, *decays], "energy", memory=True).to_json()
        parts = {k: float(v) for k, v in res["per_run_sigma_parts"][0].items() if k != "slope_noise"}
        out.append({"offset": u, "lambda66": float(res["lambda66"]), "parts": parts,
                    "sigma": float(np.sqrt(sum(v * v for v in parts.values())))})
    return out


def summary(errors: np.ndarray, sigmas: np.ndarray) -> dict:
    """Ratio of the median half-width to the median |error|, coverage, and the errors over their own sigma."""
    e, s = np.abs(np.asarray(errors, dtype=float)), np.asarray(sigmas, dtype=float)
    z = e / s
    return {"n": len(e), "ratio": float(np.median(Z95 * s) / np.median(e)), "covered": float(np.mean(e < Z95 * s)),
            "median_abs_z": float(np.median(z)), "rms_z": float(np.sqrt(np.mean(z**2))),
            "kurtosis_z": float(np.mean(z**4) / np.mean(z**2) ** 2)}


def small_sample_ratios(errors: np.ndarray, sigmas: np.ndarray, independent: int, shared: int, draws: int = 20000,
                        seed: int = 0) -> np.ndarray:
    """The ratio (median half-width over median |error|) of ``independent + shared`` runs drawn from the pooled
    re-quantised runs, ``shared`` of them repeating a drawn run (a case's runs that record the same stroke)."""
    rng = np.random.default_rng(seed)
    e, s = np.abs(np.asarray(errors, dtype=float)), np.asarray(sigmas, dtype=float)
    out = np.empty(draws)
    for k in range(draws):
        i = rng.integers(0, len(e), independent)
        j = np.r_[i, i[:shared]]
        out[k] = np.median(Z95 * s[j]) / np.median(e[j])
    return out


def main(argv: list[str] | None = None) -> int:
    """Print each run's scatter over the offsets against its budget, and the pooled calibration; returns 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("archive", help="a lab's .tar.xz (with answers.json, read to score only)")
    p.add_argument("--runs", required=True, help="comma-separated CASE/RUN, e.g. case-02/run-03")
    p.add_argument("--offsets", type=int, default=40, help="encoder offsets per run")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--sample", default="", help="INDEPENDENT+REPEATED: the ratio of a small set, e.g. 8+4")
    p.add_argument("--observed", type=float, default=5.2, help="a set's measured ratio, for its tail probability")
    a = p.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    errs, sigs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        with tarfile.open(a.archive) as tar:
            tar.extractall(tmp, filter="data")
        answers_path = next(Path(tmp).rglob("answers.json"))
        answers = json.loads(answers_path.read_text())
        answers = answers.get("cases", answers)
        for spec in a.runs.split(","):
            case, run = spec.strip().split("/")
            rows = requantised_runs(answers_path.parent / case, run, rng.uniform(0.0, 1.0, a.offsets))
            lam = np.array([r["lambda66"] for r in rows])
            truth = float(answers[case]["lambda66"])
            rate = np.median([r["parts"]["rate"] for r in rows])
            sigma = np.array([r["sigma"] for r in rows])
            flat = np.array([r["parts"]["trend"] == 0.0 for r in rows])
            print(f"{case}/{run}: lambda66 sd over offsets {lam.std(ddof=1):.5f} kg m^2 (rate part {rate:.5f}, "
                  f"sd / rate {lam.std(ddof=1) / rate:.2f}); trend part zero in {flat.sum()}/{len(rows)}; "
                  f"error vs truth: median |e| {100 * np.median(np.abs(lam - truth)) / truth:.4f} %, "
                  f"covered {np.mean(np.abs(lam - truth) < Z95 * sigma):.2f}")
            errs += list((lam - truth) / truth)
            sigs += list(sigma / lam)
    s = summary(np.array(errs), np.array(sigs))
    print(f"pooled {s['n']} re-quantised runs: ratio {s['ratio']:.2f} (2.9 calibrated), covered {s['covered']:.3f}, "
          f"median |z| {s['median_abs_z']:.2f} (0.674 Gaussian), rms z {s['rms_z']:.2f}, "
          f"kurtosis of z {s['kurtosis_z']:.1f} (3 Gaussian)")
    if a.sample:
        ind, sh = (int(x) for x in a.sample.split("+"))
        r = small_sample_ratios(np.array(errs), np.array(sigs), ind, sh)
        print(f"ratio of {ind + sh} runs ({ind} independent strokes, {sh} repeated), drawn from these: median "
              f"{np.median(r):.2f}, 5-95 % {np.percentile(r, 5):.2f}-{np.percentile(r, 95):.2f}; "
              f"P(ratio >= {a.observed:g}) = {np.mean(r >= a.observed):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
