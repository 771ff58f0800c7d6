"""The momentum check's margins, measured: docs/RELIABILITY.md's table (issue 30).

    python -m addedinertia_env.reports.momentum_check --data PATH/foreign-lab.tar.xz \\
        --data PATH/foreign-lab-2.tar.xz

For each group of records, the largest share of the allowance an honest record uses
(:func:`~addedinertia_env.records.consistency.momentum_account`'s ``used``; over 1 is refused), the
smallest share the same records use with ``phi`` and ``psi`` in degrees, and how many of those
are refused. Groups: the dev sets' reverse-symmetric runs (``--data``, unpacked into a
temporary folder), simulated records (wigley-2m and spheroid-7, the default controller, one
hidden effect each), batched-env episodes under random actions. Prints a Markdown table
(about two CPU-minutes).
"""

from __future__ import annotations

import argparse
import dataclasses
import tarfile
import tempfile
from pathlib import Path

import numpy as np

from addedinertia_env.records.consistency import momentum_account
from addedinertia_env.foundation.machine import machine_line
from addedinertia_env.records.record import read_record
from addedinertia_env.records.run_record import RunRecord

EFFECTS = ("none", "bearing_coulomb", "fluid_memory", "spring_stiffening", "neutral_offset", "sensor_delay",
           "torque_constant")


def in_degrees(rec: RunRecord) -> RunRecord:
    """``rec`` with its angles in degrees (the rest unchanged)."""
    return RunRecord(samples={k: (np.degrees(v) if k in ("phi", "psi") else v) for k, v in rec.samples.items()},
                     meta=rec.meta, path=rec.path)


def simulated() -> list[RunRecord]:
    """Fourteen simulated reverse-symmetric records: wigley-2m and spheroid-7 with the default controller,
    each with one hidden effect of :data:`EFFECTS` at a seeded realistic size."""
    from addedinertia_env.experiment.protocol import plan_from_preset  # noqa: PLC0415
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping  # noqa: PLC0415
    from addedinertia_env.apps.simulate import effects_from_name, simulate_run  # noqa: PLC0415

    out = []
    for preset in ("wigley-2m", "spheroid-7"):
        data = load_preset(preset)
        params, plan = rig_from_mapping(data), plan_from_preset(data)
        for k, effect in enumerate(EFFECTS):
            p = dataclasses.replace(params, effects=effects_from_name(effect, seed=k))
            out.append(simulate_run(p, "feedforward-pd", plan, seed=k + 10, run_id=f"{preset}-{effect}"))
    return out


def env_episodes(n: int = 40) -> list[RunRecord]:
    """``n`` episodes of eight batched environments driven by random actions (uniform in +-0.3), as records."""
    from addedinertia_env.vector.env import ReverseStrokeVectorEnv  # noqa: PLC0415

    env = ReverseStrokeVectorEnv(8)
    env.reset(seed=5)
    rng = np.random.default_rng(1)
    out: list[RunRecord] = []
    while len(out) < n:
        _, _, term, trunc, _ = env.step(rng.uniform(-0.3, 0.3, size=(8, 1)).astype(np.float32))
        out += [env.record(int(e), run_id=f"episode-{len(out)}") for e in np.nonzero(term | trunc)[0]]
    return out[:n]


def row(label: str, records: list[RunRecord]) -> str:
    """One Markdown row: ``label``, the number of records with a reverse stroke, the largest ``used`` of the
    honest records, the smallest in degrees, and how many in degrees are refused."""
    honest = [momentum_account(r) for r in records]
    pairs = [(h["used"], momentum_account(in_degrees(r))["used"]) for h, r in zip(honest, records) if h is not None]
    caught = sum(d > 1.0 for _, d in pairs)
    return (f"| {label} | {len(pairs)} | {max(h for h, _ in pairs):.3f} | {min(d for _, d in pairs):.3g} | "
            f"{caught} / {len(pairs)} |")


def main(argv: list[str] | None = None) -> int:
    """Print the table (module doc); returns 0."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", action="append", default=[], help="a dev-set archive (.tar.xz); repeatable")
    args = ap.parse_args(argv)
    lines = ["| records | n | honest records, largest `used` | in degrees (phi, psi), smallest `used` | "
             "refused in degrees |", "|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        dev = []
        for k, archive in enumerate(args.data):
            with tarfile.open(archive) as tar:
                tar.extractall(Path(tmp) / str(k), filter="data")
        dev = [read_record(p) for p in sorted(Path(tmp).rglob("case-*/*.csv"))]
        dev = [r for r in dev if r.experiment.get("kind") == "reverse-symmetric"]
        if dev:
            lines.append(row("shared dev sets, reverse-symmetric runs", dev))
    lines.append(row("simulated, wigley-2m and spheroid-7, one hidden effect each (" + ", ".join(EFFECTS) + ")",
                     simulated()))
    lines.append(row("batched-env episodes under random actions", env_episodes()))
    print("\n".join(lines))
    print(f"\nMachine: {machine_line()}.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
