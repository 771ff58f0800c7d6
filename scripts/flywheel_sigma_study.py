"""The flywheel calibration's own per-run sigma of the torque scale, checked against the simulator's truth (issue 26).

A study, not the estimator: it reads the truth (the torque per logged ampere the simulator applies,
``1 / (1 + current_gain_error)`` of the drawn hull's sensors) to score only.

    python scripts/flywheel_sigma_study.py drawn --sets SETS [--out rows.jsonl]
        every reverse run of the drawn memory-free hulls under SETS/constant (interval_calibration's sets): the
        scale, its per-run sigma and source, the error against the truth; summaries by sensor noise and seeds
    python scripts/flywheel_sigma_study.py monte-carlo PRESET SEED [--draws 24]
        one drawn hull simulated again with its sensors' noise redrawn (same hull, plan and controller): the
        scatter of the calibrated scale and lag against the median of their per-run sigmas
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from addedinertia_env.experiment.scenarios import make_scenario
from addedinertia_env.identify.energy_balance import RunBalance
from addedinertia_env.identify.energy_calibration import CALIBRATION_MODEL_ERROR
from addedinertia_env.records.record import read_record
from addedinertia_env.reports.interval_calibration import CONTROLLERS, PRESETS


def drawn(sets: Path, seeds: int, out: str | None) -> None:
    rows = []
    for preset in PRESETS:
        for s in range(1, seeds + 1):
            sc = make_scenario(s, preset, hydrodynamics="constant")
            true = 1.0 / (1.0 + sc.rig.sensors.current_gain_error)
            for run in ("rev-a", "rev-b"):
                f = sets / "constant" / preset / f"h{s}" / run / "run-0000.csv"
                if not f.exists():
                    continue
                b = RunBalance(read_record(f).without_truth())
                rows.append(dict(label=f"{preset}-h{s}-{run}", seed=s, true=true, noise_i=b.noise_i,
                                 **b.torque_scale_summary()))
    if out:
        Path(out).write_text("".join(json.dumps(r) + "\n" for r in rows))
    fly = [r for r in rows if r["source"] == "flywheel calibration"]
    print(f"{len(rows)} reverse runs; the flywheel calibration set the scale on {len(fly)}")
    for r in fly:
        e = r["scale"] - r["true"]
        print(f"  {r['label']:22s} current noise {r['noise_i']:.4f} A  scale - truth {e:+.2e}  sigma {r.get('own_sigma', r['sigma']):.2e} "
              f"(current {r['sigma_current']:.1e}, residual {r['sigma_residual']:.1e}, model {CALIBRATION_MODEL_ERROR:.0e})"
              f"  z {e / r.get('own_sigma', r['sigma']):+.2f}  lag {1e3 * r['lag_s']:.3f} +- {1e3 * r['lag_sigma_s']:.3f} ms")
    groups = {"noise-free, seeds 1-13": lambda r: r["noise_i"] <= 1e-6 and r["seed"] <= 13,
              "noise-free, seeds 14-18": lambda r: r["noise_i"] <= 1e-6 and r["seed"] > 13,
              "sensor noise, seeds 1-13": lambda r: r["noise_i"] > 1e-6 and r["seed"] <= 13,
              "sensor noise, seeds 14-18": lambda r: r["noise_i"] > 1e-6 and r["seed"] > 13}
    for name, sel in groups.items():
        sub = [r for r in fly if sel(r)]
        if not sub:
            continue
        e = np.array([r["scale"] - r["true"] for r in sub])
        own = np.array([math.hypot(r["sigma_current"], r["sigma_residual"]) for r in sub])
        sig = np.array([r.get("own_sigma", r["sigma"]) for r in sub])
        z = e / sig
        print(f"{name}: {len(sub)} runs; rms(scale - truth) {np.sqrt(np.mean(e * e)):.2e}; fit's own sigma median "
              f"{np.median(own):.1e} ({own.min():.1e}-{own.max():.1e}); with the model's error: median {np.median(sig):.2e}, "
              f"median |z| {np.median(np.abs(z)):.2f}, rms z {np.sqrt(np.mean(z * z)):.2f}, |z| < 1.96 {int((np.abs(z) < 1.96).sum())}/{len(z)}")


def monte_carlo(preset: str, seed: int, draws: int) -> None:
    from addedinertia_env.apps.simulate import simulate_run  # noqa: PLC0415

    sc = make_scenario(seed, preset, hydrodynamics="constant")
    ctrl = CONTROLLERS[seed % len(CONTROLLERS)]
    S, L, sig, own, lsig = [], [], [], [], []
    for k in range(draws):
        b = RunBalance(simulate_run(sc.rig, ctrl, sc.plan, seed=5000 + k).without_truth())
        c = b.calibration
        if c is not None and b.current_lag_calibrated:
            S.append(c.scale), L.append(c.lag), sig.append(c.sigma), lsig.append(c.sigma_lag)
            own.append(math.hypot(c.sigma_current, c.sigma_residual))
    if len(S) < 3:
        print(f"{preset} h{seed}: the lag was pinned on {len(S)} of {draws} draws")
        return
    S, L = np.array(S), np.array(L)
    true = 1.0 / (1.0 + sc.rig.sensors.current_gain_error)
    print(f"{preset} h{seed} {ctrl}, current noise {sc.rig.sensors.current_noise} A: calibrated {len(S)}/{draws}; scale sd "
          f"{S.std(ddof=1):.2e}, fit's own sigma median {np.median(own):.2e} (ratio {np.median(own) / S.std(ddof=1):.2f}), "
          f"with the model's error {np.median(sig):.2e}; lag sd {1e3 * L.std(ddof=1):.4f} ms, sigma_lag median "
          f"{1e3 * np.median(lsig):.4f} ms (ratio {np.median(lsig) / L.std(ddof=1):.2f}); mean scale - truth {S.mean() - true:+.2e}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("drawn")
    d.add_argument("--sets", required=True)
    d.add_argument("--seeds", type=int, default=18)
    d.add_argument("--out")
    m = sub.add_parser("monte-carlo")
    m.add_argument("preset", choices=PRESETS)
    m.add_argument("seed", type=int)
    m.add_argument("--draws", type=int, default=24)
    a = ap.parse_args(argv)
    if a.cmd == "drawn":
        drawn(Path(a.sets), a.seeds, a.out)
    else:
        monte_carlo(a.preset, a.seed, a.draws)
    return 0


if __name__ == "__main__":
    sys.exit(main())
