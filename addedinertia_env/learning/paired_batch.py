"""Whole benchmark episodes of a suite, many at once on the batched engine, scored as the benchmark scores them.

:func:`run_batch` runs one episode per scenario seed of a suite's split (``train`` for
learning; never ``test``) in one :class:`~addedinertia_env.vector.pool.ExperimentPool`
(the suite's control loop included: reading delay, 100 Hz hold, quantised set-points),
each slot driven by

* ``"oracle"``: :class:`~addedinertia_env.experiment.oracle.OracleController`, the
  benchmark's truth-based reference row, on the slot's simulator truth, or
* a classical base controller (``base``, e.g. ``pd``) plus, where a ``policy`` is given,
  its residual correction (:func:`agents.residual.residual_action`, as
  :class:`agents.onnx_policy.OnnxPolicy` applies it on the benchmark).

Both act once per drive set-point period (``action_repeat`` samples: 100 Hz on hard-v0),
with the :class:`~addedinertia_env.experiment.task.ControllerContext` that
``experiment.runner.controller_context`` gives on the benchmark. Each episode is scored
by the benchmark's ranked score (:func:`addedinertia_env.evaluation.scoring.score_episode`,
``"as-written"``: ``e = (lambda66_est - lambda66_true) / lambda66_true``, the truth from the
record's truth block). The scenario's truth (lambda66, the oracle's state) is used here for scoring and the oracle only: this is a trainer, not an estimator.

One difference from the benchmark, by design of the batched pool: the record has no
passive tail after the reverse stroke (tests/test_vector_env.py bounds its effect on
lambda66 at ~1e-5 relative).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
from threadpoolctl import ThreadpoolController

from agents.residual import residual_action

from addedinertia_env.bench.runner import cycle_seed
from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.oracle import OracleController
from addedinertia_env.sim import forces
from addedinertia_env.evaluation.scoring import AS_WRITTEN, score_episode
from addedinertia_env.experiment.task import ControllerContext, ReverseStrokeTask
from addedinertia_env.vector.observe import observe
from addedinertia_env.vector.pool import READY, ExperimentPool

_BLAS = ThreadpoolController()
# (observations (m, n_obs) float32, their slots (m,)) -> corrections (m,) in [-1, 1]
Policy = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class BatchResult:
    """Per-episode outcome of :func:`run_batch` (arrays in the order of the seeds)."""

    seeds: list[int]
    rel_error: np.ndarray  # e of the ranked method (nan: identification failed)
    energy_J: np.ndarray  # J, integral of |u i| over hold and reverse
    agent_steps: int  # controller calls summed over the episodes
    samples: int  # rig samples stepped, all slots (free strokes included)
    tracking_sq: np.ndarray = field(default_factory=lambda: np.zeros(0))  # rad^2, sum over the reverse stroke's samples
    limit_samples: np.ndarray = field(default_factory=lambda: np.zeros(0))  # samples at the drive's limit
    observations: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))  # (steps, n_obs), if kept
    labels: "TeacherLabels | None" = None  # with ``teacher_labels=True``


@dataclass
class TeacherLabels:
    """Every controller call of the non-oracle slots of a :func:`run_batch` with ``teacher_labels``:
    what the student saw and what the oracle (the teacher, on the slot's truth) would have done there."""

    observations: np.ndarray  # (m, n_obs) float32, the observation the controller got
    base_action: np.ndarray  # (m,) the base controller's action there (fraction of i_max)
    teacher_action: np.ndarray  # (m,) the oracle's action on the true state at that moment (fraction of i_max)
    slot: np.ndarray  # (m,) slot (index into the seeds) of each row
    followed_teacher: np.ndarray  # (m,) bool, the rig got the teacher's action (DAgger's mixing)


class _SlotTruth:
    """What :class:`OracleController` reads of its rig, for one slot of the pool (simulator truth)."""

    def __init__(self, pool: ExperimentPool, k: int):
        self.pool, self.k = pool, k
        self.params = pool.scenarios[k].rig
        self.k_t = float(pool.rig._k_t_env[k]) if np.ndim(pool.rig._k_t_env) else float(pool.rig._k_t_env)

    def true_state(self):
        """The slot's true hull state now (the fields the oracle reads)."""
        s = self.pool.rig.true_state(self.k)
        if forces.has_radiation_memory(self.params) and "radiation_torque" not in s:
            raise ValueError(f"scenario {self.pool.scenarios[self.k].name}: radiation memory, whose torque the "
                             "batched rig's true_state does not report; the oracle cannot run here")
        return _State(**{key: s[key] for key in ("t", "phi", "w", "water_rate", "psi", "omega", "i")},
                      radiation_torque=float(s.get("radiation_torque", 0.0)))


@dataclass
class _State:
    t: float
    phi: float
    w: float
    water_rate: float
    radiation_torque: float = 0.0  # N m, 0 without radiation memory
    psi: float = 0.0  # rad, flywheel angle relative to the hull (the drive's torques: cogging)
    omega: float = 0.0  # rad/s, flywheel rate relative to the hull (gear friction and drag)
    i: float = 0.0  # A, the motor current now (the driver's lag)


def slot_context(pool: ExperimentPool, k: int, action_repeat: int) -> ControllerContext:
    """Slot ``k``'s controller context, as ``experiment.runner.controller_context`` builds it
    for a drive taking a set-point every ``action_repeat`` samples."""
    sc = pool.scenarios[k]
    dt = pool.dt * action_repeat
    slow = {"policy_rate_hz": 1.0 / dt, "sample_dt": pool.dt} if action_repeat > 1 else {}
    reference = pool.reference(k)
    link = sc.loop.stated_round_trip_s if sc.loop is not None else None  # the round trip a suite states (drive-v3)
    return ControllerContext(rig=sc.rig.known(), layout=ReverseStrokeTask.layout, reference=reference,
                             inertia_prior=float(pool.inertia_prior[k]), dt=dt, hold_s=sc.plan.hold_s,
                             link_round_trip_s=link, **slow)


def run_batch(suite, seeds: Sequence[int], make_base: Callable[[], Controller] | None, *, split: str = "train",
              oracle: Sequence[bool] | None = None, policy: Policy | None = None, residual_scale: float = 0.0,
              action_repeat: int = 10, keep_observations: bool = False, teacher_labels: bool = False,
              teacher_mix: float = 0.0, mix_seed: int = 0,
              teacher_omega_c: float = 40.0, action_limit: float = 1.0) -> BatchResult:
    """One episode per seed (``suite.split_seed(split, seed)``), all in one batch; see module doc.

    ``oracle[j]``: slot ``j`` runs the oracle instead of the base. ``policy`` maps the
    observations of the non-oracle slots still running (and their slot numbers) to
    corrections in [-1, 1], applied as ``clip(base + residual_scale * correction, -action_limit, action_limit)``
    (:func:`agents.residual.residual_action`; ``action_limit`` 0-1, the policy's own current limit).

    ``teacher_labels``: also evaluate, at every call of a non-oracle slot, the oracle on that
    slot's truth (the teacher of :mod:`.dagger`) and return the rows in ``result.labels``.
    ``teacher_mix`` (probability, 0-1): at each such call, draw (``mix_seed``) whether the rig
    gets the teacher's action instead of the slot's own (DAgger's beta; needs ``teacher_labels``).
    ``teacher_omega_c`` (rad/s): the teacher's tracking bandwidth (the oracle slots keep the benchmark's).
    """
    if split == "test":
        raise ValueError("run_batch(split='test'): the test split is held out; train on 'train' (or 'tuning')")
    if not 0.0 < float(action_limit) <= 1.0:
        raise ValueError(f"run_batch(action_limit={action_limit}): expected the policy's current limit as a "
                         "fraction of i_max in (0, 1]")
    if teacher_mix and not teacher_labels:
        raise ValueError(f"run_batch(teacher_mix={teacher_mix}): mixing in the teacher needs teacher_labels=True")
    with _BLAS.limit(limits=1, user_api="blas"):
        return _run(suite, list(seeds), make_base, split, oracle, policy, residual_scale, action_repeat,
                    keep_observations, teacher_labels, float(teacher_mix), mix_seed, teacher_omega_c,
                    float(action_limit))


def _run(suite, seeds, make_base, split, oracle, policy, scale, repeat, keep, label=False, mix=0.0,
         mix_seed=0, teacher_omega_c=40.0, limit=1.0) -> BatchResult:
    n = len(seeds)
    # the sensor noise of the benchmark's scored cycle 0 (bench/runner.py), so that a scenario here
    # is the benchmark's episode on the same scenario
    scenarios = [dataclasses.replace(sc, sensor_seed=cycle_seed(sc, 0))
                 for sc in (suite.scenario(suite.split_seed(split, s)) for s in seeds)]
    pool = ExperimentPool(n, scenarios[0], "current")
    slots = np.arange(n)
    pool.begin(slots, scenarios)
    zeros, idle = np.zeros(n), np.zeros(n, dtype=bool)
    samples = 0
    while np.any(pool.stage != READY):  # settle and free strokes
        pool.sample(zeros, idle)
        samples += n
    pool.take(slots)
    is_oracle = np.zeros(n, dtype=bool) if oracle is None else np.asarray(oracle, dtype=bool)
    controllers, teachers = [], {}
    for k in range(n):
        ctx = slot_context(pool, k, repeat)
        c = OracleController(_SlotTruth(pool, k)) if is_oracle[k] else make_base()
        c.reset(ctx)
        controllers.append(c)
        if label and not is_oracle[k]:
            teachers[k] = OracleController(_SlotTruth(pool, k), omega_c=teacher_omega_c)
            teachers[k].reset(ctx)
    rows: dict[str, list] = {"obs": [], "base": [], "teacher": [], "slot": [], "followed": []}
    mix_rng = np.random.default_rng(mix_seed)
    controlled = np.ones(n, dtype=bool)
    obs = observe(pool, slots)
    kept: list[np.ndarray] = []
    steps = 0
    tracking_sq, limit_samples = np.zeros(n), np.zeros(n)  # the environment's shaping terms' totals
    while controlled.any():
        live = np.nonzero(controlled)[0]
        action = np.zeros(n)
        for k in live:
            action[k] = float(controllers[k].predict(obs[k], deterministic=True)[0][0])
        learned = live[~is_oracle[live]]
        base_action = action[learned].copy()
        if policy is not None and len(learned):
            corr = np.asarray(policy(obs[learned], learned), dtype=np.float32).reshape(-1)
            for j, k in enumerate(learned):
                action[k] = float(residual_action(np.float32(action[k]), corr[j], scale, limit)[0])
        if label and len(learned):
            taught = np.array([float(teachers[k].predict(obs[k], deterministic=True)[0][0]) for k in learned])
            follow = mix_rng.random(len(learned)) < mix if mix > 0 else np.zeros(len(learned), dtype=bool)
            action[learned[follow]] = taught[follow]
            for key, value in (("obs", obs[learned]), ("base", base_action), ("teacher", taught),
                               ("slot", learned), ("followed", follow)):
                rows[key].append(value)
        if keep:
            kept.append(obs[live])
        steps += len(live)
        value = np.clip(action, -1.0, 1.0) * pool.i_max
        for _ in range(repeat):
            out = pool.sample(value, controlled)
            samples += int(controlled.sum())
            if out:  # the increments of the slots driven in this sample (the others' are not set)
                tracking_sq += np.where(controlled, out["tracking_sq"], 0.0)
                limit_samples += np.where(controlled, out["limit"], 0)
            if out and len(out["ended"]):
                controlled[out["ended"]] = False
            if not controlled.any():
                break
        obs = observe(pool, slots)
    rel = np.full(n, math.nan)
    for k in range(n):
        try:  # the benchmark's ranked score, by the one scoring (its energy: pool.energy, below)
            rel[k] = score_episode([pool.record(k)], AS_WRITTEN, metrics=False).rel_error
        except Exception:  # noqa: BLE001 - any failure of one episode is that episode's result (bench/runner.py)
            rel[k] = math.nan
    observations = np.concatenate(kept) if kept else np.zeros((0, 0), np.float32)
    labels = None
    if label:
        cat = {key: (np.concatenate(v) if v else np.zeros(0)) for key, v in rows.items()}
        labels = TeacherLabels(observations=cat["obs"].astype(np.float32).reshape(len(cat["base"]), -1),
                               base_action=cat["base"].astype(float), teacher_action=cat["teacher"].astype(float),
                               slot=cat["slot"].astype(int), followed_teacher=cat["followed"].astype(bool))
    return BatchResult(seeds=list(seeds), rel_error=rel, energy_J=pool.energy.copy(), agent_steps=steps,
                       samples=samples, tracking_sq=tracking_sq, limit_samples=limit_samples, observations=observations, labels=labels)
