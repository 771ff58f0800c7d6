"""A learned controller for a benchmark suite (hard-v0) distilled from the oracle by DAgger.

The benchmark scores an entry by its distance from the oracle's lambda66 on the same
scenario and sensor noise (the control error ``|e - e_oracle|``). The oracle is
computed-torque tracking on the simulator's true state and parameters
(:class:`~addedinertia_env.experiment.oracle.OracleController`), so a controller that acts
as the oracle does, in closed loop, scores near zero. That is a supervised problem with a
privileged teacher ("learning by cheating", Chen et al. 2019): the student sees only what
a real controller sees (the task's observation, through the suite's delayed, quantised
100 Hz loop); the teacher's label at every state the student visits is the oracle's action
computed there on the truth, in simulation only.

Dataset Aggregation (DAgger; Ross, Gordon and Bagnell 2011): iteration ``i`` rolls out
the current student mixed with the teacher (at every controller call the rig gets the
teacher's action with probability ``beta_i = beta_decay ** i``; iteration 0 is the
teacher alone), labels every visited state with the teacher's action, adds the rows to
the data set and refits the student on all rows so far.

What is learned: a correction on top of a classical base controller (``pd``: stateless,
so the untrained student *is* pd), both acting at the suite's drive rate
(``action_repeat`` = 10 samples, 100 Hz)::

    x = clip((obs - mean) / std, -5, 5)                       # frozen statistics of the first data
    r = is_reverse * clip(W3 tanh(W2 tanh(W1 x + b1) + b2) + b3, -1, 1)
    action = clip(base(obs) + scale * r, -1, 1)               # agents/residual.py

fitted by least squares (Adam, mini-batches, warm-started) to the target
``clip((teacher - base) / scale, -1, 1)``. The gate ``is_reverse`` (an observation field)
keeps the correction off in the hold, where the oracle commands nothing.

Learning curves: the imitation loss on the freshly visited states (before the refit: the
on-policy error DAgger bounds) and the paired control error on held-aside training
scenarios (the oracle and the bare base run once on them), against agent steps and CPU
time. The trainer reads truth for the labels and the score only; the policy never does.
Cost is CPU time of this process (``time.process_time``; BLAS and torch on one thread).
``python -m addedinertia_env.learning.dagger --help``; docs/LEARNING.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.atomic import atomic_target, atomic_write_text
from addedinertia_env.experiment.task import OBSERVATION_FIELDS
from addedinertia_env.learning.ars_residual import base_factory, base_params, capped_cost
from addedinertia_env.learning.paired_batch import run_batch

CLIP_X = 5.0  # normalised observations are clipped to +-5
GATES = {"reverse": "is_reverse", "hold": "is_hold", "none": None}  # where the correction acts
TRAIN_SEED_STRIDE = 1_000_003  # training scenario numbers of run ``seed``: disjoint streams per seed
VALIDATION_FIRST = 800_000_000  # held-aside training scenarios for the curves and the choice of iteration


class MLPStudent:
    """The student on batches of observations (numpy; the ONNX graph computes the same), see module doc."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, weights: list[np.ndarray] | None = None,
                 hidden: int = 32, seed: int = 0, gate: str = "reverse"):
        self.mean = np.asarray(mean, dtype=np.float64)
        self.std = np.asarray(std, dtype=np.float64)
        if gate not in GATES:
            raise ValueError(f"MLPStudent(gate={gate!r}); expected one of {list(GATES)}")
        self.gate_name = gate
        self.gate = None if GATES[gate] is None else list(OBSERVATION_FIELDS).index(GATES[gate])
        if weights is None:
            rng = np.random.default_rng(seed)
            n = len(self.mean)
            weights = [rng.normal(0, 1 / np.sqrt(n), (hidden, n)), np.zeros(hidden),
                       rng.normal(0, 1 / np.sqrt(hidden), (hidden, hidden)), np.zeros(hidden),
                       np.zeros((1, hidden)), np.zeros(1)]  # zero output layer: the untrained student is the base
        self.weights = [np.asarray(w, dtype=np.float64) for w in weights]

    def features(self, obs: np.ndarray) -> np.ndarray:
        """Observations (n, n_obs) normalised with the frozen statistics and clipped to +-5."""
        return np.clip((np.asarray(obs, dtype=np.float64) - self.mean) / self.std, -CLIP_X, CLIP_X)

    def raw(self, obs: np.ndarray) -> np.ndarray:
        """The network's unclipped, ungated output (n,) for observations (n, n_obs)."""
        w1, b1, w2, b2, w3, b3 = self.weights
        h = np.tanh(self.features(np.atleast_2d(obs)) @ w1.T + b1)
        h = np.tanh(h @ w2.T + b2)
        return (h @ w3.T + b3)[:, 0]

    def __call__(self, obs: np.ndarray, slots: np.ndarray | None = None) -> np.ndarray:
        """Corrections (n,) float32 in [-1, 1] for observations (n, n_obs); with the ``reverse`` gate,
        zero outside the reverse stroke."""
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float32))
        return (self.gated(obs) * np.clip(self.raw(obs), -1.0, 1.0)).astype(np.float32)

    def gated(self, obs: np.ndarray) -> np.ndarray:
        """The gate (n,) for observations (n, n_obs): the gate field's value (0 or 1), or ones."""
        obs = np.atleast_2d(obs)
        return np.ones(len(obs)) if self.gate is None else obs[:, self.gate].astype(np.float64)

    def n_parameters(self) -> int:
        """Number of trained parameters."""
        return int(sum(w.size for w in self.weights))


def fit(student: MLPStudent, obs: np.ndarray, target: np.ndarray, *, steps: int = 1500, batch: int = 512,
        lr: float = 3e-3, seed: int = 0) -> float:
    """Refit ``student`` (in place, warm-started) by Adam on the mean squared error between its
    clipped output and ``target`` (n,) on the reverse-stroke rows of ``obs`` (n, n_obs); returns
    the final mean squared error on all those rows."""
    import torch  # noqa: PLC0415 - heavy, only to train

    torch.manual_seed(seed)
    on = student.gated(obs) > 0.5
    x = torch.as_tensor(student.features(obs[on]), dtype=torch.float32)
    y = torch.as_tensor(target[on], dtype=torch.float32)
    params = [torch.tensor(w, dtype=torch.float32, requires_grad=True) for w in student.weights]
    opt = torch.optim.Adam(params, lr=lr)
    gen = torch.Generator().manual_seed(seed)

    def forward(xb):
        w1, b1, w2, b2, w3, b3 = params
        h = torch.tanh(xb @ w1.T + b1)
        h = torch.tanh(h @ w2.T + b2)
        return torch.clamp((h @ w3.T + b3)[:, 0], -1.0, 1.0)

    n = len(x)
    for _ in range(steps):
        idx = torch.randint(0, n, (min(batch, n),), generator=gen)
        loss = torch.mean((forward(x[idx]) - y[idx]) ** 2)
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        final = float(torch.mean((forward(x) - y) ** 2))
    student.weights = [p.detach().numpy().astype(np.float64) for p in params]
    return final


def imitation_targets(labels, scale: float) -> np.ndarray:
    """The student's target on labelled rows: ``clip((teacher - base) / scale, -1, 1)``."""
    return np.clip((labels.teacher_action - labels.base_action) / scale, -1.0, 1.0)


def imitation_loss(student: MLPStudent, labels, scale: float) -> float:
    """Mean squared error (in units of the correction) of the student against the teacher on
    the reverse-stroke rows of ``labels``."""
    on = student.gated(labels.observations) > 0.5
    if not on.any():
        return float("nan")
    pred = student(labels.observations[on])
    return float(np.mean((pred - imitation_targets(labels, scale)[on]) ** 2))


def train(out: Path, *, suite_name: str = "hard-v0", base: str = "pd", seed: int = 0, scale: float = 1.0,
          iterations: int = 10, scenarios: int = 48, beta_decay: float = 0.5, hidden: int = 32,
          fit_steps: int = 1500, validate: int = 48, cap: float = 0.005, cpu_minutes: float = 10.0,
          teacher_omega_c: float = 40.0, gate: str = "reverse", action_repeat: int = 10, log=print) -> dict[str, Any]:
    """Train (module doc); writes ``out/curve.jsonl`` (one line per iteration; the first line,
    iteration -1, is the bare base), ``out/policy.npz`` (the student of the iteration with the
    lowest median control error on the held-aside scenarios, the leaderboard's ranked score) and
    ``out/training_card.json``;
    returns the training card. Stops after ``iterations`` or ``cpu_minutes`` of CPU time."""
    import torch  # noqa: PLC0415

    from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    suite = load_suite(suite_name)
    pinned = base_params(suite, base)
    make_base = base_factory(base, pinned)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    next_scenario = seed * TRAIN_SEED_STRIDE
    env_steps = episodes = 0
    command = " ".join(["python -m addedinertia_env.learning.dagger", *sys.argv[1:]])

    # held-aside training scenarios: the oracle and the bare base, once
    val_seeds = list(range(VALIDATION_FIRST, VALIDATION_FIRST + validate))
    ref = run_batch(suite, val_seeds + val_seeds, make_base, oracle=[True] * validate + [False] * validate,
                    action_repeat=action_repeat)
    rel_oracle, rel_base = ref.rel_error[:validate], ref.rel_error[validate:]
    base_cost = capped_cost(rel_base, rel_oracle, cap)
    env_steps += ref.agent_steps
    episodes += 2 * validate

    def validation(student) -> dict[str, float]:
        r = run_batch(suite, val_seeds, make_base, policy=student, residual_scale=scale, action_repeat=action_repeat)
        cost = capped_cost(r.rel_error, rel_oracle, cap)
        ce = np.abs(r.rel_error - rel_oracle)
        return {"val_mean_cost": float(cost.mean()), "val_median_ce": float(np.nanmedian(ce)),
                "val_paired_mean_diff": float(np.mean(cost - base_cost)),
                "val_paired_median_diff": float(np.nanmedian(ce - np.abs(rel_base - rel_oracle))),
                "val_failures": int(np.sum(~np.isfinite(r.rel_error))), "_steps": r.agent_steps}

    data: dict[str, list[np.ndarray]] = {"obs": [], "target": []}
    student: MLPStudent | None = None
    history: list[dict[str, Any]] = []
    best = (float("inf"), -1)  # (median control error on the held-aside scenarios, iteration)
    curve_path = out / "curve.jsonl"
    curve_path.write_text("")

    def write_card() -> dict[str, Any]:
        cpu_s = time.process_time() - cpu0
        card = {"algo": "dagger", "suite": suite_name, "split": "train", "base": base, "base_params": pinned,
                "seed": seed, "scale": scale, "gate": gate, "action_repeat": action_repeat, "iterations_done": len(history),
                "chosen_iteration": best[1], "chosen_val_median_ce": best[0],
                "base_val_mean_cost": float(np.mean(base_cost)),
                "base_val_median_ce": float(np.nanmedian(np.abs(rel_base - rel_oracle))),
                "validation_scenarios": [val_seeds[0], val_seeds[-1]],
                "hyperparams": {"iterations": iterations, "scenarios": scenarios, "beta_decay": beta_decay,
                                "hidden": hidden, "fit_steps": fit_steps, "teacher_omega_c": teacher_omega_c, "validate": validate, "cap": cap,
                                "cpu_minutes": cpu_minutes},
                "cost": {"env_steps": env_steps, "episodes": episodes, "cpu_s": round(cpu_s, 1),
                         "cpu_minutes": round(cpu_s / 60.0, 2), "wall_s": round(time.perf_counter() - wall0, 1)},
                "command": command}
        atomic_write_text(out / "training_card.json", json.dumps(card, indent=2) + "\n")
        return card

    row0 = {"iteration": -1, "beta": None, "episodes": episodes, "agent_steps": env_steps,
            "cpu_s": round(time.process_time() - cpu0, 2), "rows": 0, "onpolicy_loss": None, "fit_loss": None,
            "val_mean_cost": float(np.mean(base_cost)),
            "val_median_ce": float(np.nanmedian(np.abs(rel_base - rel_oracle))),
            "val_paired_mean_diff": 0.0, "val_paired_median_diff": 0.0,
            "val_failures": int(np.sum(~np.isfinite(rel_base)))}
    with curve_path.open("a") as f:
        f.write(json.dumps(row0) + "\n")
    for it in range(iterations):
        beta = beta_decay ** it
        seeds = list(range(next_scenario, next_scenario + scenarios))
        next_scenario += scenarios
        roll = run_batch(suite, seeds, make_base, policy=student, residual_scale=scale, action_repeat=action_repeat,
                         teacher_labels=True, teacher_mix=beta, mix_seed=seed * 1000 + it,
                         teacher_omega_c=teacher_omega_c)
        env_steps += roll.agent_steps
        episodes += len(seeds)
        labels = roll.labels
        if student is None:  # frozen normalisation from the first data
            mean = labels.observations.mean(axis=0)
            std = np.maximum(labels.observations.std(axis=0), 1e-3)
            student = MLPStudent(mean, std, hidden=hidden, seed=seed, gate=gate)
        onpolicy = imitation_loss(student, labels, scale)
        data["obs"].append(labels.observations)
        data["target"].append(imitation_targets(labels, scale))
        fit_loss = fit(student, np.concatenate(data["obs"]), np.concatenate(data["target"]), steps=fit_steps,
                       seed=seed * 1000 + it)
        val = validation(student)
        env_steps += val.pop("_steps")
        episodes += validate
        row = {"iteration": it, "beta": beta, "episodes": episodes, "agent_steps": env_steps,
               "cpu_s": round(time.process_time() - cpu0, 2), "wall_s": round(time.perf_counter() - wall0, 2),
               "rows": int(sum(len(o) for o in data["obs"])), "onpolicy_loss": onpolicy, "fit_loss": fit_loss, **val}
        history.append(row)
        with curve_path.open("a") as f:
            f.write(json.dumps(row) + "\n")
        log(f"iter {it}: beta {beta:.3f} on-policy loss {onpolicy:.4f} fit {fit_loss:.4f} | val cost "
            f"{val['val_mean_cost'] * 100:.4f} % (base {np.mean(base_cost) * 100:.4f} %), median ce "
            f"{val['val_median_ce'] * 100:.4f} %, paired median diff {val['val_paired_median_diff'] * 100:+.4f} %, "
            f"fails {val['val_failures']} | cpu {row['cpu_s']:.0f} s, steps {env_steps}")
        save_student(student, out / f"policy_it{it}.npz")
        if val["val_median_ce"] < best[0]:  # the leaderboard ranks by the median control error
            best = (val["val_median_ce"], it)
            save_student(student, out / "policy.npz")
        write_card()
        if time.process_time() - cpu0 > 60.0 * cpu_minutes:
            break
    return write_card()


def save_student(student: MLPStudent, path: Path) -> None:
    """Write ``student`` to ``path`` (``.npz``) atomically; :func:`load_student` reads it back."""
    with atomic_target(path, suffix=".npz") as tmp:
        np.savez(tmp, *student.weights, mean=student.mean, std=student.std, gate=student.gate_name)


def load_student(path: Path) -> MLPStudent:
    """The student saved by :func:`train` (``policy.npz`` or ``policy_itN.npz``)."""
    data = np.load(path)
    weights = [data[f"arr_{j}"] for j in range(6)]
    return MLPStudent(data["mean"], data["std"], weights, gate=str(data["gate"]))


# --- export ------------------------------------------------------------------------------------
def export_onnx(run: Path, onnx_path: Path, *, extra_card: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write the student of ``run`` (``policy.npz``, ``training_card.json``) as ONNX with its metadata
    (``agents/onnx_policy.py``: a residual on ``base`` acting at ``policy_rate_hz``, board mode
    ``zoh``, the base deciding with the correction once per action) and the card ``<stem>.json``
    (:func:`.residual_export.export_residual`); returns the card."""
    import torch  # noqa: PLC0415 - torch is heavy
    from torch import nn  # noqa: PLC0415

    from addedinertia_env.learning.export import random_observations  # noqa: PLC0415
    from addedinertia_env.learning.residual_export import export_residual  # noqa: PLC0415

    train_card = json.loads((run / "training_card.json").read_text())
    student = load_student(run / "policy.npz")

    class Student(nn.Module):
        def __init__(self):
            super().__init__()
            for name, value in (("mean", student.mean), ("std", student.std)):
                self.register_buffer(name, torch.as_tensor(value, dtype=torch.float32))
            for j, w in enumerate(student.weights):
                self.register_buffer(f"w{j}", torch.as_tensor(w, dtype=torch.float32))

        def forward(self, obs):
            x = torch.clamp((obs - self.mean) / self.std, -CLIP_X, CLIP_X)
            h = torch.tanh(x @ self.w0.T + self.w1)
            h = torch.tanh(h @ self.w2.T + self.w3)
            r = torch.clamp(h @ self.w4.T + self.w5, -1.0, 1.0)
            if student.gate is not None:
                r = r * obs[:, student.gate:student.gate + 1]
            return r

    obs = random_observations(1000)
    if student.gate is not None:  # the gate field is 0 or 1 on the rig: check both
        gate_col = list(OBSERVATION_FIELDS).index(GATES[student.gate_name])
        obs[:, gate_col] = (np.arange(len(obs)) % 2).astype(np.float32)
    return export_residual(Student(), student, train_card, onnx_path, algo="dagger", parity_obs=obs,
                           residual_extra={"gate": student.gate_name},
                           card_extra={"n_parameters": student.n_parameters()}, extra_card=extra_card)


def main(argv: list[str] | None = None) -> int:
    """Command line: train one seed by DAgger; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m addedinertia_env.learning.dagger",
                                     description="Distil the oracle into a residual controller on a suite's training "
                                                 "split by DAgger.")
    parser.add_argument("--suite", default="hard-v0")
    parser.add_argument("--base", default="pd", help="classical base controller (default pd)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scale", type=float, default=1.0, help="largest correction, fraction of i_max")
    parser.add_argument("--iterations", type=int, default=10)
    parser.add_argument("--scenarios", type=int, default=48, help="training scenarios rolled out per iteration")
    parser.add_argument("--beta-decay", type=float, default=0.5, help="teacher mixing beta_i = decay^i")
    parser.add_argument("--teacher-omega-c", type=float, default=40.0,
                        help="the teacher's tracking bandwidth, rad/s (the benchmark's oracle: 40)")
    parser.add_argument("--gate", choices=sorted(GATES), default="reverse",
                        help="where the correction acts: the reverse stroke only (default) or always (hold too)")
    parser.add_argument("--hidden", type=int, default=32, help="units per hidden layer")
    parser.add_argument("--fit-steps", type=int, default=1500, help="Adam steps per refit")
    parser.add_argument("--validate", type=int, default=48, help="held-aside training scenarios")
    parser.add_argument("--cap", type=float, default=0.005, help="per-episode cost cap (relative)")
    parser.add_argument("--cpu-minutes", type=float, default=10.0, help="stop after this much CPU time")
    parser.add_argument("--out", type=Path, required=True, help="run folder (curve.jsonl, policy.npz, card)")
    args = parser.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    train(args.out, suite_name=args.suite, base=args.base, seed=args.seed, scale=args.scale,
          iterations=args.iterations, scenarios=args.scenarios, beta_decay=args.beta_decay, hidden=args.hidden,
          fit_steps=args.fit_steps, teacher_omega_c=args.teacher_omega_c, gate=args.gate, validate=args.validate, cap=args.cap, cpu_minutes=args.cpu_minutes,
          log=lambda m: print(m, flush=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
