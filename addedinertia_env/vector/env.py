"""``AddedInertia/ReverseStroke-v0`` for ``num_envs`` environments on the batched engine.

``gym.make_vec("AddedInertia/ReverseStroke-v0", num_envs=N)`` (or
``vectorization_mode="vector_entry_point"``) gives :class:`ReverseStrokeVectorEnv`: the
same task as ``num_envs`` copies of :class:`~addedinertia_env.envs.ReverseStrokeEnv` (same
options, spaces, observations, rewards and end-of-episode scoring), with every rig sample
of every environment taken in one call of the batched rig, and the experiment protocol,
observation and reward computed on arrays (:mod:`.pool`, :mod:`.observe`).

``workers=W`` (W > 1) runs it in W processes, one shard of environments each
(:mod:`.shards`, reached through :func:`~.entry.make_vector_env`): for machines with idle cores.

Resets cost nothing at step time: a pool of spare slots runs the next episodes' settle
and free strokes in the background (in the same batch), and an environment that resets
takes a slot already braked at its stop. Spare episodes draw their scenario seeds from
the vector environment's own generator (seeded by ``reset(seed=...)``); the first
episode of environment ``e`` after ``reset(seed=s)`` is the single environment's
``reset(seed=s + e)``. Every episode reports its ``scenario_seed``: the single
environment with ``scenario_seed=`` that number runs the same episode
(tests/test_vector_env.py holds the two equal).

``suite="hard-v0"`` (``suite_split`` ``"train"`` or ``"tuning"``) draws a benchmark suite's
scenarios as the single environment does, hidden effects and control loop (reading delay,
held and quantised set-points: :class:`~addedinertia_env.loop.control_loop.LoopState`, the
single environment's own loop code) included.

Differences from ``num_envs`` single environments, by design: the passive tail after the
reverse stroke is not simulated, so the terminal observation is the one at the end of the
reverse stroke (``is_reverse`` 0) instead of 0.1 s later, and the episode's record ends
there; rendering is not offered (render one ``gym.make`` environment instead).

Autoreset (Gymnasium 1.x): ``autoreset_mode="next_step"`` (default; the step after an
episode ends resets that environment, ignores its action and returns reward 0) or
``"same_step"`` (or the ``AutoresetMode`` members; the new episode's first observation is returned at once; the terminal
observation and info are in ``info["final_obs"]`` and ``info["final_info"]``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from threadpoolctl import ThreadpoolController
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from addedinertia_env.envs.config import EnvConfig
from addedinertia_env.identify.common import prepare as prepare_identification
from addedinertia_env.experiment.scenarios import load_ranges
from addedinertia_env.evaluation.scoring import REWARD, Estimate, estimate, reward_score, score_episode
from addedinertia_env.experiment.task import OBS_LIMIT, SCORE_ONLY, ReverseStrokeTask, RewardWeights
from addedinertia_env.vector.observe import observe
from addedinertia_env.vector.pool import ENDED, READY, SETTLE, FREE, EMPTY, ExperimentPool

_BLAS = ThreadpoolController()  # the small least-squares fits run on one BLAS thread (16x faster on a busy 2-core machine)
# Spare slots per environment (free strokes running ahead). An episode spends about 0.6 of its
# controlled time (hold + reverse) in settle and free stroke with the default ranges, so about 0.6
# spares per environment are running at any time: at 0.6 resets often waited for a spare (582
# extra rig samples per 1000 agent steps at 512 envs), at 0.8 none did, and 2 processes at
# N = 1024 ran 6 % faster (3 alternating runs each, 0.7 and 1.0 alike within the spread).
SPARE_FRACTION = 0.8
SPARE_BATCH_DIVISOR = 32  # spares start in batches of n_spare / this (fewer, larger begin() calls)
METRIC_KEYS = ("lambda66_est", "lambda66_true", "rel_error", "energy_J", "tracking_rms_rad", "saturated_frac")


def estimate_lambda66(record, score: str = REWARD) -> Estimate:
    """The estimate of one ended episode, as the single environment scores it
    (:func:`addedinertia_env.evaluation.scoring.estimate` with ``score``: the corrected score, or the
    environment's :attr:`ReverseStrokeVectorEnv.score_method`, the ranked one on a suite): lambda66 kg m^2
    and its 95 % interval, or nan and the failure when the identification fails. Runs on one BLAS
    thread; any process may compute it (the sharded env sends records to whichever worker
    has the least to do)."""
    with _BLAS.limit(limits=1, user_api="blas"):
        return estimate([record], score)


@dataclass
class PendingStep:
    """A step between :meth:`ReverseStrokeVectorEnv.advance` and :meth:`~ReverseStrokeVectorEnv.finish`:
    environments that reset at its start, those whose episode ended in it, those of them to score
    and their ``records`` (same order), and the reward terms so far (``accuracy`` still missing)."""

    resetting: np.ndarray
    ended_envs: np.ndarray
    scored_envs: np.ndarray
    terms: dict[str, np.ndarray]
    records: list = field(default_factory=list)


class ReverseStrokeVectorEnv(VectorEnv):
    """``num_envs`` reverse-stroke environments on one batched rig (module docstring).

    Keyword arguments: those of :class:`~addedinertia_env.envs.ReverseStrokeEnv` (``preset``,
    ``randomize``, ``ranges``, ``fixed``, ``sensor_quality``, ``hold_s``, ``alpha``,
    ``scenario_seed``, ``action_repeat``, ``control_mode``, ``reward_weights``, ``suite``,
    ``suite_split``), plus
    ``autoreset_mode``, ``spare_fraction`` (spare slots per environment, >= 0.1) and
    ``score_episodes`` (default True: every ended episode's record is identified, as the
    single env does; False skips the identification, so ``info`` has no benchmark numbers,
    and needs ``reward_weights`` with ``accuracy`` 0).
    """

    def __init__(self, num_envs: int = 1, *, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 spare_fraction: float = SPARE_FRACTION, render_mode: str | None = None,
                 score_episodes: bool = True, **env_kwargs: Any):
        if not (isinstance(num_envs, int) and not isinstance(num_envs, bool) and num_envs >= 1):
            raise ValueError(f"ReverseStrokeVectorEnv option num_envs={num_envs!r}: expected an integer >= 1")
        if render_mode is not None:
            raise ValueError(f"ReverseStrokeVectorEnv option render_mode={render_mode!r}: the vector environment "
                             "does not render; render one gym.make('AddedInertia/ReverseStroke-v0') instead")
        suite, suite_split = env_kwargs.pop("suite", None), env_kwargs.pop("suite_split", "train")
        self.suite, self.suite_split = None, suite_split
        if suite is not None:  # a benchmark suite's scenarios, control loop included (as ReverseStrokeEnv)
            from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

            if suite_split not in ("train", "tuning"):
                raise ValueError(f"ReverseStrokeVectorEnv option suite_split={suite_split!r}: expected 'train' "
                                 "(seeds outside both splits) or 'tuning'; the test split is held out")
            self.suite = load_suite(suite)
        for key in ("rig_factory", "width", "height"):
            if key in env_kwargs:
                raise ValueError(f"ReverseStrokeVectorEnv option {key}: not available on the batched engine "
                                 "(it simulates its own rigs); use gym.make_vec(..., vectorization_mode='sync')")
        (self.single_observation_space, self.single_action_space, self.observation_space, self.action_space,
         self.metadata) = self.spaces(num_envs, autoreset_mode)
        if not (isinstance(spare_fraction, (int, float)) and 0.1 <= spare_fraction <= 4):
            raise ValueError(f"ReverseStrokeVectorEnv option spare_fraction={spare_fraction!r}: expected a number "
                             "in [0.1, 4] (spare slots per environment)")
        env_kwargs.pop("max_episode_steps", None)  # from the registration; an episode ends well before it
        self.score_method = reward_score(suite)  # the ranked score on a suite (issue 28), else the corrected one
        if self.suite is not None:  # the suite's own ranked estimate (bench/suites.py ``ranked``; memory-v1's)
            self.score_method = self.suite.ranked
        weights = env_kwargs.pop("reward_weights", None) or (SCORE_ONLY if suite is not None else RewardWeights())
        self.config = EnvConfig(reward_weights=weights, **env_kwargs)
        if not isinstance(score_episodes, bool):
            raise ValueError(f"ReverseStrokeVectorEnv option score_episodes={score_episodes!r}: expected True or False")
        if not score_episodes and self.config.reward_weights.accuracy != 0:
            raise ValueError("ReverseStrokeVectorEnv option score_episodes=False: the accuracy reward needs each "
                             "episode identified; set reward_weights={'accuracy': 0} too, or keep score_episodes=True")
        self.score_episodes = score_episodes
        if score_episodes:
            prepare_identification()  # its one-time imports now, not at the first episode's end
        self.num_envs = num_envs
        self.n_spare = max(2, int(math.ceil(spare_fraction * num_envs)))
        self.n_slots = num_envs + self.n_spare
        self.spare_batch = max(1, self.n_spare // SPARE_BATCH_DIVISOR)  # empty slots that start free strokes together
        self._default_ranges = load_ranges()
        self.pool: ExperimentPool | None = None
        self._env_rngs: list[np.random.Generator | None] = [None] * num_envs
        self._spare_rng: np.random.Generator | None = None
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self.env_slot = np.zeros(num_envs, dtype=np.int64)
        self._owned = np.zeros(self.n_slots, dtype=bool)
        self.slot_seed = np.zeros(self.n_slots, dtype=np.int64)  # the scenario_seed each slot runs
        self.episode_config = self.config
        self._task: ReverseStrokeTask | None = None
        self.episodes_ended = 0
        self._spares_due = False  # the last advance(defer_spares=True) left its spare starts to start_spares()

    @staticmethod
    def spaces(num_envs: int, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP, **_ignored: Any):
        """(single observation space, single action space, batched observation and action spaces,
        metadata) of ``num_envs`` environments."""
        names = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP}
        mode = names.get(autoreset_mode, autoreset_mode) if isinstance(autoreset_mode, str) else autoreset_mode
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"ReverseStrokeVectorEnv option autoreset_mode={autoreset_mode!r}: expected "
                             "'next_step' or 'same_step'")
        n_obs = ReverseStrokeTask.layout.size
        single_obs = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (n_obs,), np.float32)
        single_action = spaces.Box(-1.0, 1.0, (1,), np.float32)
        return (single_obs, single_action, batch_space(single_obs, num_envs), batch_space(single_action, num_envs),
                {"autoreset_mode": mode, "render_modes": []})

    # --- scenarios and slots ---------------------------------------------------------------
    def _scenario(self, seed: int):
        """Scenario number ``seed`` (as ReverseStrokeEnv.reset: of the suite's split, if a suite is set)."""
        if self.suite is not None:
            return self.suite.scenario(self.suite.split_seed(self.suite_split, seed))
        return self.episode_config.scenario(seed, self._default_ranges)

    def _begin(self, slots: np.ndarray, seeds: list[int]) -> None:
        self.slot_seed[slots] = seeds
        self.pool.begin(slots, [self._scenario(s) for s in seeds])

    def _draw(self, rng: np.random.Generator) -> int:
        drawn = int(rng.integers(0, 2**63 - 1))  # as ReverseStrokeEnv.reset: always drawn
        pinned = self.episode_config.scenario_seed
        return pinned if pinned is not None else drawn

    def _start_spares(self, minimum: int = 1) -> None:
        pool = self.pool
        free = np.nonzero((pool.stage == EMPTY) & ~self._owned)[0]
        if len(free) >= minimum:
            self._begin(free, [self._draw(self._spare_rng) for _ in free])

    def start_spares(self) -> None:
        """Start the spare episodes that the last :meth:`advance` left due (``defer_spares=True``): a
        batch of empty slots begins its settle and free strokes. The same slots and scenarios
        whenever it runs before the next step's sampling, which calls it first if nobody did (a
        process of the sharded env calls it while it would otherwise wait for another)."""
        if self._spares_due:
            self._spares_due = False
            self._start_spares(minimum=self.spare_batch)

    def fit_spare_stops(self, stop=None) -> int:
        """The stroke fits of spare episodes that reached their stop, one after another until
        ``stop()`` is true (:meth:`~.pool.ExperimentPool.fit_stops`): a process of the sharded env
        does them while it waits for another, not in its sampling. The same numbers whenever they
        run (an environment taking a slot has its fit done first). Returns how many were done."""
        if self.pool is None:
            return 0
        with _BLAS.limit(limits=1, user_api="blas"):  # the fits' small least squares
            return self.pool.fit_stops(stop=stop)

    def _claim(self, envs: np.ndarray) -> None:
        """Environments ``envs`` take ready slots (running the spares on until enough are ready)."""
        self.start_spares()
        pool = self.pool
        old = self.env_slot[envs]
        self._owned[old] = False
        pool.stage[old[pool.stage[old] == ENDED]] = EMPTY
        ready = np.nonzero((pool.stage == READY) & ~self._owned)[0]
        if len(ready) < len(envs):
            self._start_spares()
            no_control = np.zeros(pool.n, dtype=bool)
            zeros = np.zeros(pool.n)
            while len(ready) < len(envs):
                if not np.any((pool.stage == SETTLE) | (pool.stage == FREE)):
                    self._start_spares()
                pool.sample(zeros, no_control)
                ready = np.nonzero((pool.stage == READY) & ~self._owned)[0]
        take = np.sort(ready)[:len(envs)]
        self.env_slot[envs] = take
        self._owned[take] = True
        pool.take(take)

    # --- Gymnasium vector API ------------------------------------------------------------------
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        """Reset every environment (Gymnasium ``VectorEnv.reset``): ``seed`` an int (slot ``e`` gets ``seed + e``) or a list of one per slot; returns ``(obs, info)``."""
        with _BLAS.limit(limits=1, user_api="blas"):
            return self._reset(seed, options)

    def _reset(self, seed, options):
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + e for e in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset(seed=...): {len(seeds)} seeds for {self.num_envs} environments")
        for e, s in enumerate(seeds):
            if s is not None or self._env_rngs[e] is None:
                self._env_rngs[e], _ = seeding.np_random(s)
        if seed is not None or self._spare_rng is None:
            base = seeds[0] if seeds[0] is not None else None
            self._spare_rng = np.random.default_rng(None if base is None else [int(base), 0x5EA5])
        self.episode_config = self.config.with_options(options)
        seeds = [self._draw(rng) for rng in self._env_rngs] + [self._draw(self._spare_rng) for _ in range(self.n_spare)]
        self.pool = pool = ExperimentPool(self.n_slots, self._scenario(seeds[0]), self.config.control_mode)
        self._begin(np.arange(self.n_slots), seeds)
        mine = np.arange(self.num_envs)
        zeros, no_control = np.zeros(pool.n), np.zeros(pool.n, dtype=bool)
        while np.any(pool.stage[mine] != READY):
            pool.sample(zeros, no_control)
        self._owned[:] = False
        self.env_slot[:] = mine
        self._owned[mine] = True
        pool.take(mine)
        self._task = ReverseStrokeTask(i_max=1.0, weights=self.config.reward_weights)
        self._needs_reset[:] = False
        self._spares_due = False
        return observe(pool, self.env_slot), self._reset_info(mine)

    def _reset_info(self, envs: np.ndarray) -> dict[str, Any]:
        pool, n = self.pool, self.num_envs
        mask = np.zeros(n, dtype=bool)
        mask[envs] = True
        seeds = np.zeros(n, dtype=np.int64)
        names = np.full(n, None, dtype=object)
        quality = np.full(n, None, dtype=object)
        for e in envs:
            s = pool.scenarios[self.env_slot[e]]
            seeds[e], names[e], quality[e] = self.slot_seed[self.env_slot[e]], s.name, s.sensor_quality
        return {"scenario": names, "_scenario": mask, "scenario_seed": seeds, "_scenario_seed": mask,
                "sensor_quality": quality, "_sensor_quality": mask.copy()}

    def step(self, actions):
        """Step every environment with ``actions`` (one normalised current per slot); returns ``(obs, rewards, terminated, truncated, info)``, ended slots reset automatically."""
        with _BLAS.limit(limits=1, user_api="blas"):
            return self._step(actions)

    def _step(self, actions):
        pending = self._advance(actions)  # step() holds the one-BLAS-thread limit for all three parts
        return self._finish(pending, [estimate([r], self.score_method) for r in pending.records])

    def advance(self, actions, defer_spares: bool = False) -> "PendingStep":
        """The first half of :meth:`step`: every environment's samples, up to the identification of
        the episodes that ended. Returns the :class:`PendingStep`; its ``records`` (one per ended
        episode, when episodes are scored) go through :func:`estimate_lambda66` (here or in another
        process) and :meth:`finish` completes the step with those estimates. ``defer_spares``: leave
        the step's spare starts to :meth:`start_spares` (the same episodes, started later)."""
        with _BLAS.limit(limits=1, user_api="blas"):
            return self._advance(actions, defer_spares)

    def _advance(self, actions, defer_spares: bool = False) -> "PendingStep":
        pool = self.pool
        if pool is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        self.start_spares()  # those the last step left due, before anything samples
        n = self.num_envs
        a = np.asarray(actions, dtype=np.float64).reshape(n, -1)
        if a.shape != (n, 1):
            raise ValueError(f"actions of shape {np.shape(actions)}: expected ({n}, 1), one number per environment")
        resetting = np.nonzero(self._needs_reset)[0]
        stepping = np.nonzero(~self._needs_reset)[0]
        if not np.all(np.isfinite(a[stepping])):
            bad = int(stepping[~np.isfinite(a[stepping, 0])][0])
            raise ValueError(f"actions[{bad}] = {a[bad]!r}: expected finite numbers in [-1, 1]")
        if len(resetting):
            self._claim(resetting)
        slots = self.env_slot[stepping]
        scale = pool.i_max if self.config.control_mode == "current" else pool.u_max
        value = np.zeros(pool.n)
        value[slots] = np.clip(a[stepping, 0], -1.0, 1.0) * scale[slots]
        controlled = np.zeros(pool.n, dtype=bool)
        controlled[slots] = True
        tracking, energy, limits = np.zeros(pool.n), np.zeros(pool.n), np.zeros(pool.n, dtype=np.int64)
        ended: list[np.ndarray] = []
        for _ in range(self.config.action_repeat):
            out = pool.sample(value, controlled)
            if out:
                tracking += out["tracking_sq"]
                energy += out["energy"]
                limits += out["limit"]
                if len(out["ended"]):
                    controlled[out["ended"]] = False
                    ended.append(out["ended"])
            if not controlled.any():
                break
        self._spares_due = True
        if not defer_spares:
            self.start_spares()
        env_of_slot = np.full(pool.n, -1)
        env_of_slot[self.env_slot] = np.arange(n)
        terms = self._task.terms(tracking_sq=tracking[self.env_slot], energy=energy[self.env_slot],
                                 limit_samples=limits[self.env_slot], dt=pool.dt)
        ended_envs = env_of_slot[np.concatenate(ended)] if ended else np.zeros(0, dtype=np.int64)
        scored = ended_envs if self.score_episodes else np.zeros(0, dtype=np.int64)
        records = [pool.record(int(self.env_slot[e])) for e in scored]
        return PendingStep(resetting=resetting, ended_envs=ended_envs, scored_envs=scored, terms=terms,
                           records=records)

    def finish(self, pending: "PendingStep", estimates: list[Estimate]):
        """The second half of :meth:`step`: the ended episodes' benchmark numbers from ``estimates``
        (:func:`estimate_lambda66` of ``pending.records``, in order), rewards, observations, infos and
        autoresets; returns ``(obs, rewards, terminated, truncated, info)``."""
        with _BLAS.limit(limits=1, user_api="blas"):
            return self._finish(pending, estimates)

    def _finish(self, pending: "PendingStep", estimates):
        pool, n = self.pool, self.num_envs
        if len(estimates) != len(pending.records):
            raise ValueError(f"finish(): {len(estimates)} estimates for {len(pending.records)} ended episodes")
        resetting, ended_envs, terms = pending.resetting, pending.ended_envs, pending.terms
        terms["accuracy"] = np.zeros(n)
        terminated = np.zeros(n, dtype=bool)
        infos: dict[str, Any] = {}
        if len(ended_envs):
            terminated[ended_envs] = True
        if len(pending.scored_envs):
            metrics = self._score(pending.scored_envs, pending.records, estimates)
            terms["accuracy"][pending.scored_envs] = metrics.pop("_accuracy")
            infos.update(metrics)
        not_stepping = np.zeros(n, dtype=bool)
        not_stepping[resetting] = True
        for key in terms:
            terms[key][not_stepping] = 0.0
        rewards = sum(terms.values())
        obs = observe(pool, self.env_slot)
        infos["reward_terms"] = terms
        infos["_reward_terms"] = ~not_stepping
        infos["t"] = pool.t[self.env_slot].copy()
        infos["_t"] = np.ones(n, dtype=bool)
        if len(resetting):
            infos.update(self._reset_info(resetting))
        truncated = np.zeros(n, dtype=bool)
        self.episodes_ended += len(ended_envs)
        if self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP and len(ended_envs):
            final_info = {k: v for k, v in infos.items()}
            infos["final_obs"] = np.where(terminated[:, None], obs, 0.0).astype(np.float32)
            infos["_final_obs"] = terminated.copy()
            infos["final_info"] = final_info
            infos["_final_info"] = terminated.copy()
            self._claim(ended_envs)
            obs[ended_envs] = observe(pool, self.env_slot[ended_envs])
            infos.update(self._reset_info(ended_envs))
        else:
            self._needs_reset = terminated | truncated
        return obs, rewards.astype(np.float64), terminated, truncated, infos

    def _score(self, envs: np.ndarray, records: list, estimates: list) -> dict[str, Any]:
        """The benchmark numbers of the episodes that ended (ReverseStrokeEnv._score), as info arrays,
        from their records and :func:`estimate_lambda66` estimates
        (:func:`addedinertia_env.evaluation.scoring.score_episode`, the corrected score)."""
        pool, n = self.pool, self.num_envs
        mask = np.zeros(n, dtype=bool)
        mask[envs] = True
        out: dict[str, Any] = {k: np.full(n, np.nan) for k in METRIC_KEYS}
        out["ci95"] = np.full((n, 2), np.nan)
        out["failed"] = np.zeros(n, dtype=bool)
        out["failure"] = np.full(n, "", dtype=object)
        out["scenario_seed"] = np.zeros(n, dtype=np.int64)
        accuracy = np.zeros(len(envs))
        for j, e in enumerate(envs):
            k = int(self.env_slot[e])
            record = records[j]
            score = score_episode([record], self.score_method, references=[pool.reference(k)],
                                  estimated=estimates[j])
            if score.failed:
                out["failure"][e] = score.failure
            for key in METRIC_KEYS:
                out[key][e] = getattr(score, key)
            out["ci95"][e] = list(score.ci95)
            out["failed"][e] = score.failed
            out["scenario_seed"][e] = self.slot_seed[k]
            accuracy[j] = self._task.accuracy_term(score.rel_error, failed=score.failed)
        for key in list(out):
            out["_" + key] = mask.copy()
        out["_accuracy"] = accuracy
        return out

    def record(self, env: int = 0, run_id: str = "run"):
        """Environment ``env``'s current (or just finished) episode as a run record (no tail)."""
        if self.pool is None:
            raise gym.error.ResetNeeded("call reset() before record()")
        return self.pool.record(int(self.env_slot[env]), run_id)

    def close_extras(self, **kwargs: Any) -> None:
        """Drop the experiment pool (its arrays are freed with it)."""
        self.pool = None

