"""The rest angle after the brake's release against the simulator's true angle (docs/ENERGY_METHOD.md item 4).

Simulates drawn hulls (``experiment.scenarios.make_scenario``), keeps the true hull angle that the sensor model
is given at every sample, and reads the rest at the release both ways: the quadratic in time through the
encoder's steps (``energy_rest.crossings_fit``) and the hull's law of motion (``energy_rest.released_fit``).
Prints each run's errors in encoder counts and their mean and spread. Scoring code: it reads the truth.

    python -m addedinertia_env.reports.release_rest --preset wigley-2m --seeds 1-8 --controllers pd,lqr [--cummins]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def release_errors(preset: str, seed: int, controller: str, hydrodynamics: str | None = None) -> tuple | None:
    """(quadratic's error, law's error) in counts for one simulated reverse run, or None (no hold, no encoder)."""
    from addedinertia_env.apps.simulate import simulate_run  # noqa: PLC0415
    from addedinertia_env.experiment.scenarios import make_scenario  # noqa: PLC0415
    from addedinertia_env.identify import energy_rest  # noqa: PLC0415
    from addedinertia_env.sim import sensors  # noqa: PLC0415

    truth: list[tuple[float, float]] = []
    original = sensors.SensorModel.read

    def read(self, t, phi, psi, u, i, brake, envs=None, active=None):
        truth.append((float(np.asarray(t).reshape(-1)[0]), float(np.asarray(phi).reshape(-1)[0])))
        return original(self, t, phi, psi, u, i, brake, envs, active)

    sc = make_scenario(seed, preset, hydrodynamics=hydrodynamics)
    sensors.SensorModel.read = read
    try:
        rec = simulate_run(sc.rig, controller, sc.plan, seed=1000 * seed + 1)
    finally:
        sensors.SensorModel.read = original
    rig = rec.meta["rig"]
    counts = rig["encoder_counts"]["phi"]
    phase = np.asarray(rec["phase"])
    hold, free = np.nonzero(phase == "hold")[0], np.nonzero(phase == "free")[0]
    if not counts or not len(hold):
        return None
    t, phi = rec.t, np.asarray(rec["phi"], dtype=float)
    true_phi = np.interp(t, *np.array(truth).T)
    q = 2.0 * np.pi / counts
    k3 = int(hold[-1])
    current = np.asarray(rec["i"], dtype=float) - float(np.mean(np.asarray(rec["i"], dtype=float)[free]))
    torque = -rig["c_torsion"] * (phi - rig.get("phi_neutral", 0.0)) - rig["k_t"] * current
    quad = energy_rest.crossings_fit(t, phi, k3, energy_rest.REST_FIT_S, q)
    law = energy_rest.released_fit(t, phi, k3, energy_rest.REST_FIT_S, q, torque)
    return (None if quad is None else (quad[0] - true_phi[k3]) / q,
            None if law is None else (law.rest - true_phi[k3]) / q)


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main(argv: list[str] | None = None) -> int:
    """Print the rest-after-release table (both fits against the simulator's true angle, in encoder counts);
    ``argv`` as on the command line; returns 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="wigley-2m")
    p.add_argument("--seeds", default="1-8", help="drawn hulls, e.g. 1-8")
    p.add_argument("--controllers", default="pd,lqr")
    p.add_argument("--cummins", action="store_true", help="water with memory")
    a = p.parse_args(argv)
    rows = []
    for seed in _seeds(a.seeds):
        for ctrl in a.controllers.split(","):
            r = release_errors(a.preset, seed, ctrl, "cummins" if a.cummins else None)
            if r is None:
                continue
            rows.append(r)
            print(f"{a.preset} h{seed} {ctrl}: quadratic {r[0]:+.3f} counts, law {r[1]:+.3f} counts")
    for name, j in (("quadratic", 0), ("law of motion", 1)):
        x = np.array([r[j] for r in rows if r[j] is not None])
        if len(x):
            print(f"{name}: mean {x.mean():+.3f}, sd {x.std():.3f} counts over {len(x)} runs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
