"""How the energy method's rotor Coulomb smoothing rate changes its numbers (docs/RELIABILITY.md s2b).

``python -m addedinertia_env.reports.coulomb_scale --scales 1e-2 1e-3 1e-4 1e-5 1e-6 1e-9``

For each smoothing rate ``w_s`` of ``f_coul tanh(Omega / w_s)``
(:data:`addedinertia_env.identify.rotor_friction.ROTOR_COULOMB_RATE_SCALE`, set per run here):

* the largest relative difference of ``identify()``'s lambda66 and interval (energy method,
  as written and corrected) between two OpenBLAS kernels (``OPENBLAS_CORETYPE``, one process
  each, as ``tests/test_same_numbers_any_cpu.py``), over batched-env episodes with random
  actions, hard-v0 training episodes (the trainers' batch: base pid and the oracle) and, with
  ``--data``, a foreign lab's reverse-symmetric runs;
* the hard-v0 episodes' as-written errors ``e`` (%, against the simulator's truth: scoring only),
  and how far each moves from a sign-like rate (the smallest of ``--scales``).

The simulator is not touched: its own friction law makes the episodes once, then every rate
identifies the same records.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

WORKER = r"""
import json, pickle, sys
import threadpoolctl
import addedinertia_env.identify.energy_balance as eb
import addedinertia_env.identify.energy_calibration as ec
from addedinertia_env.evaluation.scoring import AS_WRITTEN, CORRECTED, estimate
target, corpus, scales = sys.argv[1], sys.argv[2], [float(s) for s in sys.argv[3:]]
records = pickle.load(open(corpus, "rb"))
out = {"arch": None, "results": {}}
for w in scales:
    eb.ROTOR_COULOMB_RATE_SCALE = ec.ROTOR_COULOMB_RATE_SCALE = w
    rows = out["results"][repr(w)] = {}
    for name, rec in records.items():
        rows[name] = {}
        for score in (AS_WRITTEN, CORRECTED):
            e = estimate([rec], score)
            rows[name][score] = e.failure_type if e.failure else [e.lambda66, *e.ci95]
out["arch"] = sorted({str(i.get("architecture")) for i in threadpoolctl.threadpool_info()
                      if i.get("internal_api") == "openblas"})
json.dump(out, open(target, "w"))
"""


def _kernels() -> tuple[str, str]:
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    return "Haswell", ("SkylakeX" if " avx512f" in flags else "Sandybridge")


def corpus(env_episodes: int, hard_seeds: int, data: list[Path], tmp: Path) -> tuple[dict, dict]:
    """Records by name, and the true lambda66 (kg m^2) of the hard-v0 ones (scoring only): ``env_episodes``
    batched-env episodes, the trainers' batch on ``hard_seeds`` hard-v0 training seeds (base pid and the
    oracle), and the reverse-symmetric runs of each archive in ``data`` (unpacked under ``tmp``)."""
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415
    from addedinertia_env.learning import paired_batch  # noqa: PLC0415
    from addedinertia_env.learning.ars_residual import base_factory, base_params  # noqa: PLC0415
    from addedinertia_env.records.record import read_record  # noqa: PLC0415
    from addedinertia_env.vector.env import ReverseStrokeVectorEnv  # noqa: PLC0415

    records: dict = {}
    env = ReverseStrokeVectorEnv(4)
    env.reset(seed=5)
    rng = np.random.default_rng(1)
    while len(records) < env_episodes:
        _, _, term, trunc, _ = env.step(rng.uniform(-0.3, 0.3, size=(4, 1)).astype(np.float32))
        for e in np.nonzero(term | trunc)[0]:
            records[f"env-{len(records)}"] = env.record(int(e), run_id=f"env-{len(records)}")
    # the trainers' batch (reports/digests.trainer_digests): its records as it scores them
    kept = []
    original = paired_batch.score_episode

    def keep(recs, *a, **k):
        kept.append(list(recs)[0])
        return original(recs, *a, **k)

    paired_batch.score_episode = keep
    try:
        suite = load_suite("hard-v0")
        seeds = list(range(hard_seeds))
        paired_batch.run_batch(suite, seeds + seeds, base_factory("pid", base_params(suite, "pid")),
                               oracle=[False] * len(seeds) + [True] * len(seeds))
    finally:
        paired_batch.score_episode = original
    truth = {}
    for k, rec in enumerate(kept):
        name = f"hard-{'oracle' if k >= hard_seeds else 'pid'}-{k % hard_seeds}"
        records[name] = rec
        truth[name] = rec.truth_lambda66()
    for archive in data:
        folder = tmp / archive.name.split(".")[0]
        with tarfile.open(archive) as tar:
            tar.extractall(folder, filter="data")
        for p in sorted(folder.rglob("case-*/*.csv")):
            if json.loads(p.with_suffix(".json").read_text())["experiment"]["kind"] == "reverse-symmetric":
                records[f"{folder.name}/{p.parent.name}/{p.stem}"] = read_record(p)
    return records, truth


def _run(kernel: str, path: Path, scales: list[float], tmp: Path) -> dict:
    target = tmp / f"{kernel}.json"
    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "OPENBLAS_CORETYPE": kernel, "OPENBLAS_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join([str(repo), os.environ.get("PYTHONPATH", "")])}
    subprocess.run([sys.executable, "-c", WORKER, str(target), str(path), *map(repr, scales)], env=env,
                   check=True, cwd=repo)
    return json.loads(target.read_text())


def _rel(x, y) -> float:
    if isinstance(x, str) or isinstance(y, str):
        return 0.0 if x == y else float("inf")
    x, y = np.asarray(x), np.asarray(y)
    return float(np.max(np.abs(x - y) / np.abs(x)))


def main(argv: list[str] | None = None) -> int:
    """Command line (module doc): print the table of docs/RELIABILITY.md section 2b; exit status 0."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scales", type=float, nargs="+", default=[1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-9],
                    help="smoothing rates to compare, rad/s (the smallest is the sign-like reference)")
    ap.add_argument("--env-episodes", type=int, default=8)
    ap.add_argument("--hard-seeds", type=int, default=8, help="hard-v0 training seeds (pid and oracle each)")
    ap.add_argument("--data", type=Path, nargs="*", default=[], help="foreign-lab archives (.tar.xz)")
    ap.add_argument("--json", type=Path, help="write the raw results here")
    args = ap.parse_args(argv)
    scales = sorted(args.scales, reverse=True)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        records, truth = corpus(args.env_episodes, args.hard_seeds, args.data, tmp)
        path = tmp / "corpus.pkl"
        path.write_bytes(pickle.dumps(records))
        a_name, b_name = _kernels()
        a, b = _run(a_name, path, scales, tmp), _run(b_name, path, scales, tmp)
    print(f"kernels: {a_name} {a['arch']} vs {b_name} {b['arch']}; {len(records)} records "
          f"({sum(n.startswith('env') for n in records)} env, {len(truth)} hard-v0, "
          f"{sum('/' in n for n in records)} foreign-lab)")
    ref = repr(scales[-1])
    summary = {}
    for w in scales:
        ra, rb = a["results"][repr(w)], b["results"][repr(w)]
        groups = {"env": "env-", "hard-v0": "hard-", "foreign": None}
        cross = {}
        for g, prefix in groups.items():
            names = [n for n in records if (n.startswith(prefix) if prefix else "/" in n)]
            cross[g] = max((_rel(ra[n][s], rb[n][s]) for n in names for s in ra[n]), default=float("nan"))
        err = {n: 100 * (ra[n]["as-written"][0] / truth[n] - 1) if not isinstance(ra[n]["as-written"], str)
               else float("nan") for n in truth}
        err_ref = {n: 100 * (a["results"][ref][n]["as-written"][0] / truth[n] - 1)
                   if not isinstance(a["results"][ref][n]["as-written"], str) else float("nan") for n in truth}
        moves = np.array([abs(abs(err[n]) - abs(err_ref[n])) for n in truth])
        summary[repr(w)] = {"cross_kernel": cross, "as_written_pct": err, "move_vs_sign_like_pts": moves.tolist()}
        print(f"w_s = {w:g} rad/s: cross-kernel max rel diff env {cross['env']:.1e}, hard-v0 {cross['hard-v0']:.1e}, "
              f"foreign {cross['foreign']:.1e}; hard-v0 |e| vs sign-like: max move {np.nanmax(moves):.2e} points, "
              f"median {np.nanmedian(moves):.2e}; mean |e| {np.nanmean(np.abs(list(err.values()))):.3f} %")
    print("hard-v0 as-written e (%) per episode, by w_s:")
    for n in truth:
        print(f"  {n:14s} " + "  ".join(f"{summary[repr(w)]['as_written_pct'][n]:8.3f}" for w in scales))
    if args.json:
        args.json.write_text(json.dumps({"scales": scales, "kernels": [a_name, b_name], "summary": summary,
                                         "raw": {a_name: a, b_name: b}}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
