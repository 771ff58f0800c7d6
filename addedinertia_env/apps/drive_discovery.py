"""Discovery datasets with a drive flaw hidden (issue 28, docs/DISCOVERY.md "The drive's flaws").

The standard discovery dataset (:mod:`.discovery_dataset`: two twists x two holds on
``wigley-2m``, realistic sensors, the default controller) run through a drive drawn from a
seed: one flaw at a realistic size (the ranges of real parts, docs/DRIVE.md "Parameters from
real parts"), or a right drive (``none``: a gearhead without losses, or a direct drive, and a
current driver with its own bandwidth, which leave nothing for discovery to name). The
flywheel keeps wigley-2m's 0.25 N m/A through a gearhead (the motor's own ``k_t`` is that over
the ratio), as ``configs/rigs/wigley-2m-geared.yaml``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.sim.drive import DriveParams

# the word discovery should name for each hidden flaw ("none": nothing); backlash where the
# simulator has it (DriveParams.backlash, drivephys' model)
HAS_BACKLASH = "backlash" in {f.name for f in dataclasses.fields(DriveParams)}
FLAWS = ("none", "mesh_loss", "gear_drag", "cogging") + (("backlash",) if HAS_BACKLASH else ())


def draw_drive(flaw: str, seed: int) -> DriveParams:
    """A drive with ``flaw`` at a realistic size drawn from ``seed`` (docs/DRIVE.md cites the parts)."""
    if flaw not in FLAWS:
        raise ValueError(f"drive flaw {flaw!r}: expected one of {', '.join(FLAWS)}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 28, FLAWS.index(flaw)]))
    ratio = float(rng.uniform(3.0, 8.0))  # planetary gearheads, 1-2 stages
    tau = float(rng.uniform(1e-4, 1e-3))  # a servo amplifier's current loop
    if flaw == "none":
        return DriveParams(gear_ratio=ratio if rng.random() < 0.5 else 1.0, driver_time_constant=tau)
    if flaw == "mesh_loss":
        return DriveParams(gear_ratio=ratio, gear_efficiency=float(rng.uniform(0.81, 0.90)), driver_time_constant=tau)
    if flaw == "gear_drag":
        return DriveParams(gear_ratio=ratio, gear_drag=float(rng.uniform(0.005, 0.020)), driver_time_constant=tau)
    if flaw == "backlash":  # drive-v1's ranges: 0.5-1.5 deg, a 100-200 g cm^2 rotor (docs/DRIVE.md)
        return DriveParams(gear_ratio=ratio, backlash=float(np.radians(rng.uniform(0.5, 1.5))),
                           rotor_inertia=float(rng.uniform(1e-5, 2e-5)), driver_time_constant=tau)
    # cogging: 5-25 mN m peak at the motor shaft (1-4 % of a small servo motor's rated torque), the
    # lcm of slots and poles of common motors (6 slots 4 poles: 12; 9/6: 18; 12/8: 24; 12/10: 60), on
    # a direct drive or through a gearhead
    geared = rng.random() < 0.5
    return DriveParams(gear_ratio=ratio if geared else 1.0, cogging_torque=float(rng.uniform(0.005, 0.025)),
                       cogging_periods=float(rng.choice([12, 18, 24, 60])),
                       cogging_phase=float(rng.uniform(0, 2 * np.pi)), driver_time_constant=tau)


def simulate_drive_dataset(flaw: str, seed: int, controller: str | None = None,
                           drive: DriveParams | None = None) -> list[RunRecord]:
    """The standard discovery dataset's runs on a drive with ``flaw`` drawn from ``seed`` (no hidden
    effect); ``drive``: this drive instead (``flaw`` is then only a label)."""
    from addedinertia_env.apps.discovery_dataset import DatasetSpec  # noqa: PLC0415
    from addedinertia_env.apps.simulate import simulate_run  # noqa: PLC0415 - heavy import (MuJoCo, agents)
    from addedinertia_env.experiment.protocol import plan_from_preset  # noqa: PLC0415
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping  # noqa: PLC0415

    spec = DatasetSpec() if controller is None else DatasetSpec(controller=controller)
    data = load_preset(spec.rig)
    rig = rig_from_mapping(data)
    drive = drive if drive is not None else draw_drive(flaw, seed)
    rig = rig.replace(drive=drive, motor=dataclasses.replace(rig.motor, k_t=rig.motor.k_t / drive.gear_ratio))
    records = []
    noise_seeds = np.random.SeedSequence([seed, 28, 1]).spawn(len(spec.runs))
    for (alpha, hold), ss in zip(spec.runs, noise_seeds):
        plan = plan_from_preset(data, alpha=alpha, hold_s=hold)
        rec = simulate_run(rig, spec.controller, plan, seed=ss, run_id=f"run-a{alpha:.3f}-h{hold:.1f}")
        rec.meta["experiment"]["seed"] = seed
        records.append(rec)
    return records
