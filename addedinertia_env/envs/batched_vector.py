"""``AddedInertia/ReverseStroke-v0`` as a vector environment over one batched rig.

:class:`BatchedReverseStrokeVectorEnv` runs ``num_envs`` copies of
:class:`~addedinertia_env.envs.reverse_stroke.ReverseStrokeEnv` (same options, same
observation and action spaces, same rewards, infos and scoring: the single environment's
code does all of that), but the rig samples of the controlled part of every episode (hold
and reverse stroke) are taken in one :meth:`BatchedRig.step` for all environments.

How: each copy's rig is a :class:`SlotRig`, the :class:`~addedinertia_env.rig.interface.Rig`
protocol over slot ``k`` of the shared batch. The parts of an episode that the single
environment runs inside ``reset`` (twist, release, free stroke, brake) and inside its last
``step`` (the passive tail) run on the slot's own one-environment rig
(:class:`BatchedSingleRig`); the slot's state moves into the batch when the controlled
part begins and out of it for the tail, with its parameters, noise stream and sensor
delay line. The Python bookkeeping of each copy (experiment log, rate filters, reference,
observation) stays per environment; docs/PERFORMANCE.md measures what that leaves of the
physics speed-up.

Autoreset: Gymnasium's next-step mode (the step after an episode ends resets that
environment and returns its first observation, reward 0). ``action_repeat`` must be 1.

Select it with :func:`vector_env` (``batched=True``), which training and benchmark code
can call in place of ``gym.make_vec``. As measured (docs/PERFORMANCE.md), it is *not*
faster than ``gym.make_vec`` yet: per-environment Python bookkeeping dominates the step,
and the free strokes run on one-environment numpy rigs, slower than MuJoCo at n = 1. So
:func:`vector_env` defaults to ``gym.make_vec``; a vectorised experiment protocol (free
strokes simulated in batch, reference evaluated in batch) is what would make it pay.
"""

from __future__ import annotations

import time
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..rig.batched import BatchedRig
from ..rig.batched_single import BatchedSingleRig
from ..rig.interface import SimulatedRigBase
from ..rig.motor import MODES, MotorCommand
from ..scenarios import Scenario
from .reverse_stroke import ReverseStrokeEnv

ENV_ID = "AddedInertia/ReverseStroke-v0"


class SlotRig(SimulatedRigBase):
    """Slot ``k`` of the owner's batch, behind the Rig protocol (see the module docstring)."""

    source = "sim"

    def __init__(self, owner: "BatchedReverseStrokeVectorEnv", k: int, scenario: Scenario):
        self.owner, self.k = owner, k
        self.params = scenario.rig
        self.solo = BatchedSingleRig(scenario.rig, seed=scenario.sensor_seed)
        self.in_batch = False
        self.pending: tuple[MotorCommand, Any] | None = None  # (command, reading) taken by the batch

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True):
        self._leave_batch()
        return self.solo.reset(phi0=phi0, psi0=psi0, omega0=omega0, brake=brake)

    def set_brake(self, on: bool) -> None:
        if self.in_batch:
            self.owner.batch.set_brake(bool(on), envs=[self.k])
        else:
            self.solo.set_brake(on)

    def step(self, cmd: MotorCommand):
        if self.in_batch and self.pending is not None:
            taken, reading = self.pending
            self.pending = None
            if taken != cmd:
                raise RuntimeError(f"slot {self.k}: the batch took {taken}, the experiment asked for {cmd}")
            return reading
        self._leave_batch()  # the passive tail (or anything unforeseen) runs on the slot's own rig
        return self.solo.step(cmd)

    def truth(self) -> dict:
        return self.solo.truth()

    def enter_batch(self) -> None:
        batch = self.owner.batch
        batch.set_env_params(self.k, self.params, rng=self.solo.batch.sensors.rngs_or_rng(0))
        batch.copy_env(self.k, self.solo.batch, 0)
        self.in_batch = True

    def _leave_batch(self) -> None:
        if self.in_batch:
            self.solo.batch.copy_env(0, self.owner.batch, self.k)
            self.in_batch = False
            self.pending = None


class BatchedReverseStrokeVectorEnv(VectorEnv):
    """``num_envs`` reverse-stroke environments over one batched rig (module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int, **env_kwargs: Any):
        if not (isinstance(num_envs, int) and num_envs >= 1):
            raise ValueError(f"num_envs = {num_envs!r}: expected an integer >= 1")
        if env_kwargs.get("action_repeat", 1) != 1:
            raise ValueError(f"action_repeat = {env_kwargs['action_repeat']!r}: the batched vector env steps the rig "
                             "once per action; use action_repeat=1 or gym.make_vec")
        if "rig_factory" in env_kwargs or env_kwargs.get("render_mode") is not None:
            raise ValueError("the batched vector env supplies the rig itself and does not render; "
                             "leave out rig_factory and render_mode")
        self.num_envs = num_envs
        self.slots: list[SlotRig | None] = [None] * num_envs
        self.envs = [ReverseStrokeEnv(rig_factory=self._factory(k), **env_kwargs) for k in range(num_envs)]
        self.single_observation_space = self.envs[0].observation_space
        self.single_action_space = self.envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.batch: BatchedRig | None = None
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self._obs = np.zeros((num_envs, *self.single_observation_space.shape), dtype=np.float32)

    def _factory(self, k: int):
        def make(scenario: Scenario) -> SlotRig:
            slot = SlotRig(self, k, scenario)
            self.slots[k] = slot
            return slot

        return make

    # --- Gymnasium vector API ---------------------------------------------------------
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        seeds = seed if isinstance(seed, (list, tuple)) else [None if seed is None else seed + k
                                                             for k in range(self.num_envs)]
        if len(seeds) != self.num_envs:
            raise ValueError(f"reset(seed=...): {len(seeds)} seeds for {self.num_envs} environments")
        infos: dict[str, Any] = {}
        for k, env in enumerate(self.envs):
            self._obs[k], info = env.reset(seed=seeds[k], options=options)
            infos = self._add_info(infos, info, k)
        # One batch for all slots, with each slot's parameters and noise stream.
        solos = [slot.solo for slot in self.slots]
        self.batch = BatchedRig([s.params for s in solos], seed=[s.batch.sensors.rngs_or_rng(0) for s in solos],
                                initial_reading=False)
        for slot in self.slots:
            slot.enter_batch()
        self._needs_reset[:] = False
        return self._obs.copy(), infos

    def step(self, actions):
        if self.batch is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        actions = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, -1)
        stepping = ~self._needs_reset
        cmds: list[MotorCommand | None] = [None] * self.num_envs
        modes = np.zeros(self.num_envs, dtype=np.int64)
        values = np.zeros(self.num_envs)
        for k in np.nonzero(stepping)[0]:
            if not np.all(np.isfinite(actions[k])):
                raise ValueError(f"actions[{k}] = {actions[k]!r}: expected finite numbers in [-1, 1]")
            cmd = self.envs[k].task.command(actions[k])
            cmds[k] = cmd
            modes[k], values[k] = MODES.index(cmd.mode), cmd.value
        reading = self.batch.step(modes, values)
        rewards = np.zeros(self.num_envs)
        terminated = np.zeros(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        infos: dict[str, Any] = {}
        for k in range(self.num_envs):
            env = self.envs[k]
            if self._needs_reset[k]:
                self._obs[k], info = env.reset()
                self.slots[k].enter_batch()
                self._needs_reset[k] = False
            else:
                self.slots[k].pending = (cmds[k], reading.single(k))
                self._obs[k], rewards[k], terminated[k], truncated[k], info = env.step(actions[k])
                self._needs_reset[k] = terminated[k] or truncated[k]
            infos = self._add_info(infos, info, k)
        return self._obs.copy(), rewards, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        for env in getattr(self, "envs", []):  # also after a refused __init__
            env.close()


def vector_env(num_envs: int, batched: bool = False, **env_kwargs: Any) -> VectorEnv:
    """The reverse-stroke vector environment: ``gym.make_vec`` (sync, default: faster today,
    see docs/PERFORMANCE.md) or, with ``batched=True``, the batched-rig vector env.

    Falls back to ``gym.make_vec`` where the batched one cannot serve (``action_repeat``
    above 1, a custom ``rig_factory``, rendering).
    """
    usable = (env_kwargs.get("action_repeat", 1) == 1 and "rig_factory" not in env_kwargs
              and env_kwargs.get("render_mode") is None)
    if batched and usable:
        return BatchedReverseStrokeVectorEnv(num_envs, **env_kwargs)
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="sync", **env_kwargs)


def measure_vector_envs(num_envs: int = 8, steps: int = 3000, seed: int = 0, progress=None) -> dict[str, Any]:
    """Env steps per second of ``gym.make_vec`` (sync) and of the batched vector env.

    Same options, seeds and random actions for both; the initial reset (``num_envs`` free
    strokes) and any autoresets are included in the time.
    """
    say = progress or (lambda _m: None)
    rows = []
    for kind in ("gym.make_vec sync (MujocoRig)", "batched (BatchedReverseStrokeVectorEnv)"):
        env = vector_env(num_envs, batched=kind.startswith("batched"))
        rng = np.random.default_rng(seed)
        t0 = time.perf_counter()
        env.reset(seed=seed)
        episodes = 0
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(rng.uniform(-0.3, 0.3, size=(num_envs, 1)).astype(np.float32))
            episodes += int(np.sum(term | trunc))
        wall = time.perf_counter() - t0
        env.close()
        rows.append({"kind": kind, "n_envs": num_envs, "steps": steps, "episodes_ended": episodes,
                     "wall_s": wall, "env_steps_per_s": num_envs * steps / wall})
        say(f"{kind}: {rows[-1]['env_steps_per_s']:.0f} env steps/s")
    ratio = rows[1]["env_steps_per_s"] / rows[0]["env_steps_per_s"]
    note = (f"Batched / sync = {ratio:.2f}. {num_envs} environments, {steps} vector steps, random actions in "
            "[-0.3, 0.3], initial reset included.")
    return {"rows": rows, "ratio_batched_to_sync": ratio, "note": note}
