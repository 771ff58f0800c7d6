"""Digests of the project's numbers, to prove a refactoring left them unchanged.

``python -m addedinertia_env.reports.digests --out BEFORE.json`` on one commit, then
``python -m addedinertia_env.reports.digests --compare BEFORE.json`` on another: the second
run computes the same quantities and says, section by section, whether they are equal bit
for bit, equal within ``--rtol``, or different (exit status 1; 0 when all are equal).

What is computed (about 2-3 CPU-minutes on the 2-core Xeon):

* ``env``: whole episodes of ``AddedInertia/ReverseStroke-v0`` under the default controller
  (the nominal and the randomised rig, and the hard-v0 suite's scenarios), a few seeds each;
  SHA-256 of the per-step rewards and of the per-step infos, the return and the episode's
  score (lambda66 estimate and truth, relative error, energy, tracking, saturation);
* ``vector``: the batched vector env (``gym.make_vec``, 2 envs) under a seeded random action
  sequence until each env has ended one episode: rewards and the ended episodes' scores;
* ``identify``: ``identify()`` on in-situ simulated records of every rig preset (energy
  method corrected and as written, free decay), and, with ``--data PATH...`` (foreign-lab
  archives ``.tar.xz`` or their unpacked folders), on every record of those labs;
* ``bench``: benchmark rows of two classical controllers and the oracle on the smoke suite;
* ``trainer``: the ranked relative errors of the trainers' batched episodes
  (``learning.paired_batch.run_batch``) on a few hard-v0 training scenarios.

Floats are stored exactly (``repr``), hashes over their float64 bytes; answers files are
never read.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.atomic import atomic_write_text

ENV_ID = "AddedInertia/ReverseStroke-v0"
ENV_CASES = {  # name -> (env kwargs, seeds)
    "default-nominal": ({"action_repeat": 10, "hold_s": 0.5, "randomize": False}, [0]),
    "default-random": ({"action_repeat": 10, "hold_s": 0.5}, [0, 1]),
    "hard-v0": ({"action_repeat": 10, "suite": "hard-v0"}, [0, 1]),
}
CORPUS_SEEDS = (0, 1)
BENCH_CONTROLLERS = ("feedforward-pd", "pid", "oracle")
TRAINER_SEEDS = (0, 1, 2, 3)


def _plain(x: Any) -> Any:
    """JSON-able copy of ``x`` (arrays to lists, numpy scalars to Python numbers)."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, (str, int, float, bool)) or x is None:
        return x
    return repr(x)


def _sha(obj: Any) -> str:
    if isinstance(obj, np.ndarray):
        data = np.ascontiguousarray(obj, dtype=np.float64).tobytes()
    else:
        data = json.dumps(_plain(obj), sort_keys=True).encode()
    return hashlib.sha256(data).hexdigest()[:16]


SCORE_KEYS = ("lambda66_est", "lambda66_true", "rel_error", "ci95", "energy_J", "tracking_rms_rad",
              "saturated_frac", "failed")


def env_digests() -> dict[str, Any]:
    """Whole episodes of the single env under the default controller."""
    import gymnasium as gym  # noqa: PLC0415

    import addedinertia_env  # noqa: F401, PLC0415 - registers the id
    from agents import make_controller  # noqa: PLC0415
    from agents.registry import DEFAULT_CONTROLLER  # noqa: PLC0415

    out: dict[str, Any] = {}
    for name, (kwargs, seeds) in ENV_CASES.items():
        for seed in seeds:
            env = gym.make(ENV_ID, **kwargs)
            obs, info = env.reset(seed=seed)
            controller = make_controller(DEFAULT_CONTROLLER)
            controller.reset(env.unwrapped.controller_context())
            rewards, infos, observations = [], [info], [obs]
            while True:
                action = controller.predict(obs, deterministic=True)[0]
                obs, reward, terminated, truncated, info = env.step(action)
                rewards.append(float(reward))
                infos.append(info)
                observations.append(obs)
                if terminated or truncated:
                    break
            final = infos[-1]
            r = np.asarray(rewards)
            out[f"{name}/seed-{seed}"] = {
                "steps": len(rewards), "rewards_sha": _sha(r), "infos_sha": _sha(infos),
                "observations_sha": _sha(np.asarray(observations)), "return": float(r.sum()),
                "score": {k: _plain(final.get(k)) for k in SCORE_KEYS},
                "reward_terms_final": _plain(final.get("reward_terms")),
            }
            env.close()
    return out


def vector_digests() -> dict[str, Any]:
    """The batched vector env, 2 envs, a seeded random action sequence, one episode each."""
    import gymnasium as gym  # noqa: PLC0415

    import addedinertia_env  # noqa: F401, PLC0415

    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", action_repeat=10, hold_s=0.5)
    rng = np.random.default_rng(7)
    envs.reset(seed=3)
    rewards, ended, scores = [], np.zeros(2, bool), {}
    for _ in range(5000):
        action = rng.uniform(-0.3, 0.3, size=(2, 1)).astype(np.float32)
        _, reward, terminated, truncated, info = envs.step(action)
        rewards.append(np.asarray(reward, np.float64))
        done = np.asarray(terminated) | np.asarray(truncated)
        for e in np.flatnonzero(done & ~ended):
            scores[f"env-{e}"] = {k: _plain(info[k][e]) for k in SCORE_KEYS if k in info}
        ended |= done
        if ended.all():
            break
    envs.close()
    r = np.asarray(rewards)
    return {"steps": len(rewards), "rewards_sha": _sha(r), "return": _plain(r.sum(axis=0)), "scores": scores}


def _result(res) -> dict[str, Any]:
    return {"lambda66": float(res.lambda66), "ci95": [float(res.ci95[0]), float(res.ci95[1])],
            "n_intervals": _plain(getattr(res, "n_intervals", None))}


def _identify_all(records: list, kinds: dict[str, list[tuple[str, dict]]]) -> dict[str, Any]:
    from addedinertia_env.identify import identify  # noqa: PLC0415

    out: dict[str, Any] = {}
    by_kind: dict[str, list] = {}
    for rec in records:
        by_kind.setdefault(rec.experiment["kind"], []).append(rec)
    for kind, recs in sorted(by_kind.items()):
        for method, options in kinds.get(kind, []):
            label = method + "".join(f",{k}={v}" for k, v in sorted(options.items()))
            for i, rec in enumerate(recs):
                try:
                    out[f"{kind}/{i}/{label}"] = _result(identify([rec], method, **options))
                except Exception as e:  # noqa: BLE001 - a refusal is a result too
                    out[f"{kind}/{i}/{label}"] = {"error": f"{type(e).__name__}: {e}"}
    return out


METHODS = {"reverse-symmetric": [("energy", {}), ("energy", {"asymmetry_correction": False})],
           "free-decay": [("free-decay", {})]}


def identify_digests(data: list[Path]) -> dict[str, Any]:
    """identify() on simulated records of every preset (and on a foreign lab's records)."""
    from agents.registry import DEFAULT_CONTROLLER  # noqa: PLC0415

    from addedinertia_env.experiment.protocol import plan_from_preset  # noqa: PLC0415
    from addedinertia_env.sim.presets import available_rigs, load_preset, rig_from_mapping  # noqa: PLC0415
    from addedinertia_env.apps.simulate import simulate_run  # noqa: PLC0415

    out: dict[str, Any] = {}
    for preset in available_rigs():
        mapping = load_preset(preset)
        rig, plan = rig_from_mapping(mapping), plan_from_preset(mapping)
        records = []
        for seed in CORPUS_SEEDS:
            records.append(simulate_run(rig, DEFAULT_CONTROLLER, plan, seed=seed, run_id=f"{preset}/{seed}"))
            records.append(simulate_run(rig, DEFAULT_CONTROLLER, plan, seed=seed, kind="free-decay",
                                        run_id=f"{preset}/decay/{seed}"))
        for key, value in _identify_all(records, METHODS).items():
            out[f"{preset}/{key}"] = value
    for path in data:
        out.update(_foreign(path))
    return out


def _foreign(data: Path) -> dict[str, Any]:
    from addedinertia_env.records.record import read_record  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as tmp:
        root = data
        if data.is_file():
            with tarfile.open(data) as tar:
                tar.extractall(tmp, filter="data")
            root = Path(tmp)
        out: dict[str, Any] = {}
        for case in sorted({p.parent for p in root.rglob("*.csv")}):
            records = [read_record(p) for p in sorted(case.glob("*.csv"))]
            for key, value in _identify_all(records, METHODS).items():
                out[f"{data.name}/{case.name}/{key}"] = value
    return out


ROW_KEYS = ("lambda66_true", "lambda66_est", "ci95", "rel_error", "abs_rel_error", "lambda66_est_corrected",
            "rel_error_corrected", "energy_J", "tracking_rms_rad", "saturated_frac", "failure", "failure_corrected",
            "entry_kind", "score_method")


def bench_digests() -> dict[str, Any]:
    """Benchmark rows on the smoke suite's test split."""
    from addedinertia_env.bench.runner import run_tasks  # noqa: PLC0415
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    suite = load_suite("smoke")
    tasks = [suite.task(sc, c) for c in BENCH_CONTROLLERS for sc in suite.scenarios("test")]
    rows = run_tasks(tasks, jobs=1, progress=False)
    return {f"{row['controller']}/{row['scenario']}": {k: _plain(row.get(k)) for k in ROW_KEYS} for row in rows}


def trainer_digests() -> dict[str, Any]:
    """The trainers' batched episodes (base pid, and the oracle) on hard-v0 training scenarios."""
    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415
    from addedinertia_env.learning.ars_residual import base_factory, base_params  # noqa: PLC0415
    from addedinertia_env.learning.paired_batch import run_batch  # noqa: PLC0415

    suite = load_suite("hard-v0")
    make_base = base_factory("pid", base_params(suite, "pid"))
    seeds = list(TRAINER_SEEDS)
    res = run_batch(suite, seeds + seeds, make_base, oracle=[False] * len(seeds) + [True] * len(seeds))
    return {"seeds": seeds, "rel_error": _plain(res.rel_error), "energy_J": _plain(res.energy_J),
            "agent_steps": res.agent_steps, "samples": res.samples}


SECTIONS = {"env": env_digests, "vector": vector_digests, "bench": bench_digests, "trainer": trainer_digests}


def compute(data: list[Path], sections: list[str] | None = None, log=print) -> dict[str, Any]:
    """Every section's digests (``sections``: a subset of ``env vector identify bench trainer``)."""
    out: dict[str, Any] = {}
    for name in sections or [*SECTIONS, "identify"]:
        t0 = time.process_time()
        out[name] = identify_digests(data) if name == "identify" else SECTIONS[name]()
        log(f"{name}: {time.process_time() - t0:.1f} CPU-s", file=sys.stderr)
    return out


def _walk(a: Any, b: Any, path: str, diffs: list[tuple[str, str, float]]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                diffs.append((f"{path}/{k}", "only in " + ("baseline" if k in a else "this run"), math.inf))
            else:
                _walk(a[k], b[k], f"{path}/{k}", diffs)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            _walk(x, y, f"{path}[{i}]", diffs)
    elif _is_num(a) and _is_num(b):
        if a == b or (math.isnan(a) and math.isnan(b)):
            return
        rel = abs(a - b) / max(abs(a), abs(b), 1e-300)
        diffs.append((path, f"{a!r} -> {b!r}", rel))
    elif a != b:
        diffs.append((path, f"{a!r} -> {b!r}", math.inf))


def _is_num(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def compare(baseline: dict[str, Any], now: dict[str, Any], rtol: float = 0.0) -> tuple[bool, list[str]]:
    """Whether ``now`` equals ``baseline`` (numbers within ``rtol`` relative; hashes exactly), and
    one line per section and per difference."""
    lines, ok = [], True
    for section in sorted(set(baseline) | set(now)):
        if section not in baseline or section not in now:
            lines.append(f"{section}: only in {'baseline' if section in baseline else 'this run'}")
            continue
        diffs: list[tuple[str, str, float]] = []
        _walk(baseline[section], now[section], section, diffs)
        if not diffs:
            lines.append(f"{section}: identical bit for bit")
            continue
        worst = max(d[2] for d in diffs)
        within = worst <= rtol
        ok &= within
        lines.append(f"{section}: {len(diffs)} differences, largest relative {worst:.3g}"
                     + (" (within rtol)" if within else ""))
        lines += [f"  {p}: {what}" + (f" (rel {rel:.3g})" if math.isfinite(rel) else "") for p, what, rel in diffs]
    return ok, lines


def main(argv: list[str] | None = None) -> int:
    """Command line (module doc); returns the exit status."""
    p = argparse.ArgumentParser(prog="python -m addedinertia_env.reports.digests", description=__doc__.splitlines()[0])
    p.add_argument("--out", help="write the digests to this JSON file")
    p.add_argument("--compare", help="compare with a JSON file written by --out; exit 1 if anything differs")
    p.add_argument("--data", nargs="+", default=[],
                   help="foreign-lab archives (.tar.xz) or folders: identify() on their records too")
    p.add_argument("--sections", nargs="+", choices=[*SECTIONS, "identify"], help="compute only these sections")
    p.add_argument("--rtol", type=float, default=0.0, help="relative tolerance for numbers in --compare (default 0)")
    args = p.parse_args(argv)
    data = [Path(d) for d in args.data]
    for path in data:
        if not path.exists():
            print(f"--data {path}: no such file or folder (expected a foreign-lab .tar.xz or its folder)",
                  file=sys.stderr)
            return 2
    baseline = None
    if args.compare:
        try:
            baseline = json.loads(Path(args.compare).read_text())
        except (OSError, ValueError) as e:
            print(f"--compare {args.compare}: cannot read digests ({e})", file=sys.stderr)
            return 2
    sections = args.sections or (sorted(baseline) if baseline else None)
    now = compute(data, sections)
    if args.out:
        atomic_write_text(Path(args.out), json.dumps(now, indent=1, sort_keys=True) + "\n")
    if baseline is None:
        return 0
    ok, lines = compare({k: baseline[k] for k in now if k in baseline} if args.sections else baseline, now, args.rtol)
    print("\n".join(lines))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
