"""``AddedInertia/ReverseStroke-v0``: one reverse-symmetric experiment per episode."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from addedinertia_env.experiment.protocol import Experiment
from addedinertia_env.experiment.runner import controller_context as _runner_context
from addedinertia_env.records.record import RunRecord
from addedinertia_env.rig.interface import Rig
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.experiment.scenarios import Scenario, build_rig, load_ranges
from addedinertia_env.evaluation.scoring import reward_score, score_episode, truth_lambda66
from addedinertia_env.experiment.task import OBS_LIMIT, SCORE_ONLY, ReverseStrokeTask, RewardWeights
from addedinertia_env.envs.config import EnvConfig
from addedinertia_env.envs.render import PlotRenderer, RigRenderer

RENDER_MODES = ("rgb_array", "plot")
NOMINAL_SAMPLE_RATE = 1000.0  # Hz, for render_fps only (the presets' sample rate)


def simulated_rig(scenario: Scenario) -> MujocoRig:
    """The default rig factory: the MuJoCo rig of ``scenario`` with its own sensor-noise stream
    (seen through the scenario's control loop, if it has one: ``scenarios.build_rig``)."""
    return build_rig(scenario)


class ReverseStrokeEnv(gym.Env[np.ndarray, np.ndarray]):
    """The reverse stroke of patent RU 2627023 on a simulated yaw rig, as a Gymnasium environment.

    Description
        A ship hull floats on a torsion rod; a motor on the hull spins a flywheel, and
        its reaction turns the hull. Each episode is one experiment: the rod is twisted
        by ``alpha`` and released with the motor passive; the hull swings through
        neutral and slows to a stop, where a brake holds it for ``hold_s`` seconds. Then
        the brake opens and the hull must retrace the free stroke backwards in time (the
        *mirrored reference*, fitted to the encoder record of the free stroke). The
        energy method (``identify(..., "energy")``) then estimates the hull's added
        moment of inertia ``lambda66`` from the record. It is exact only if the reverse
        stroke mirrors the free one, and its error grows with the energy that flows
        through the motor: the agent should track symmetrically with little energy.

        ``reset`` runs everything up to the hold (the agent has nothing to do there);
        the agent acts from the start of the hold (it may pre-spin the flywheel while
        the brake takes the reaction) to the end of the reverse stroke. The physics
        (:class:`~addedinertia_env.sim.mujoco_rig.MujocoRig`), the experiment
        (:class:`~addedinertia_env.experiment.protocol.Experiment`) and the task
        (:class:`~addedinertia_env.experiment.task.ReverseStrokeTask`) are separate objects; this
        class only adds action repeat, seeding, scoring and rendering. ``rig_factory``
        swaps the rig (a batched view, the bench through ``hw_adapter``).

    Action Space
        ``Box(-1, 1, (1,), float32)``: the motor command as a fraction of the current
        limit ``i_max`` (``control_mode="current"``, default; the drive's current loop
        realises it within one sample) or of the supply voltage ``u_max``
        (``control_mode="voltage"``). Out-of-range actions are clipped; non-finite ones
        raise ``ValueError``. One action is held for ``action_repeat`` rig samples.

    Observation Space
        ``Box(-10, 10, (22,), float32)``: the fields of
        :data:`addedinertia_env.experiment.task.OBSERVATION_FIELDS`, each divided by its fixed
        scale and clipped to +-10. Decode by name with
        :class:`~addedinertia_env.experiment.task.ObservationLayout` (``env.unwrapped.layout``).
        They come from sensors (hull and motor encoders, current sensor), the
        sensor-derived reference and the rig's known (calibrated) constants; never from
        the simulator's true state.

        ====  ===================  =======  =====  ======================================
        idx   name                 unit     scale  meaning
        ====  ===================  =======  =====  ======================================
        0     tracking_error       rad      0.005  phi_ref - phi
        1     rate_error           rad/s    0.05   rate_ref - estimated hull rate
        2     phi_ref              rad      0.2    reference, from the neutral
        3     rate_ref             rad/s    0.3    reference rate (0 in the hold)
        4     accel_ref            rad/s^2  0.5    reference acceleration (0 in the hold)
        5-7   ahead_10/50/100ms    rad      .005,  phi_ref(t + h) - phi_ref(t)
                                            .02,.04
        8     phi                  rad      0.2    hull encoder, from the neutral
        9     hull_rate            rad/s    0.3    windowed estimate from the encoder
        10    flywheel_rate        rad/s    50     from the motor encoder
        11    current              A        15     current sensor
        12    is_hold              -        1      1 during the hold
        13    is_reverse           -        1      1 during the reverse stroke
        14    phase_progress       -        1      0 at the phase start, 1 at its end
        15    electric_energy      J        20     integral of abs(u i) so far
        16    time_to_phase_end    s        5      to the end of the hold / the stroke
        17    inertia_prior        kg m^2   20     J_hull + lambda66 seen at the stop
        18    stroke_duration      s        2      of the reverse stroke
        19    c_torsion            N m/rad  50     known rod stiffness
        20    k_t                  N m/A    0.25   known torque constant
        21    J_flywheel           kg m^2   0.1    known flywheel inertia
        ====  ===================  =======  =====  ======================================

    Rewards
        The sum of named terms, each in ``info["reward_terms"]`` (summed over the
        action repeat), weights in ``reward_weights``:
        ``tracking = -w (e / 1 mrad)^2 dt`` per sample of the reverse stroke;
        ``energy = -w * joules of abs(u i)`` drawn; ``limits = -w dt`` per sample at the
        current (or voltage) limit; ``accuracy = -w min(abs(rel_error) / 1 %, 10)``
        once, at the last step (a failed estimate costs the cap, 10). Defaults
        ``tracking=1, energy=0.1, limits=1, accuracy=1``. The episode's return does not
        depend on ``action_repeat``. On a benchmark suite (``suite=``) the accuracy term
        scores the ranked identification (the energy method as written), so it is minus
        the episode's leaderboard score in percent (bench/score.py: ``min(|e|, 10 %)``, a
        failure at the cap), and the default weights are that term alone
        (``tracking=0, energy=0, limits=0, accuracy=1``; docs/ENVIRONMENT.md).

    Starting State
        Scenario (rig, sensors, ``alpha``, ``hold_s``) drawn from the preset and
        ``configs/randomization.yaml`` (if ``randomize``) with a scenario seed drawn from
        ``np_random``; the free stroke has run; the hull is braked at its stop; the
        first observation is the first sample of the hold.

    Episode End
        Terminated when the reverse stroke and the passive tail after it are over
        (about ``hold_s`` + half a period of samples: 2,000 to 8,000 at 1 kHz).
        Truncation only by the registered step limit (20,000 agent steps), which a
        valid configuration never reaches. The last ``info`` carries ``lambda66_est``,
        ``lambda66_true`` (the record's truth block, A66(0); nan on a bench), scored by
        :func:`addedinertia_env.evaluation.scoring.score_episode` (the corrected score),
        ``rel_error`` (``(lambda66_est - lambda66_true) / lambda66_true``, a fraction: 0.01 is 1 %;
        nan when the estimate failed), ``ci95``, ``failed`` (the estimate could not be formed),
        ``energy_J``, ``tracking_rms_rad``, ``saturated_frac``.

    Arguments
        ``gym.make("AddedInertia/ReverseStroke-v0", render_mode=None, **kwargs)`` with
        the fields of :class:`~addedinertia_env.envs.config.EnvConfig`: ``preset``
        (``"wigley-2m"``), ``randomize`` (True), ``ranges`` (overrides of the
        randomisation ranges, ``{key: [low, high]}``), ``fixed`` (pinned scenario
        values), ``sensor_quality``, ``hold_s``, ``alpha``, ``scenario_seed``,
        ``action_repeat`` (1), ``control_mode`` (``"current"``), ``reward_weights``;
        plus ``rig_factory`` (scenario -> rig) and ``width``/``height`` of frames.
        ``suite`` (e.g. ``"hard-v0"``) draws the scenarios of a benchmark suite instead,
        control loop and hidden effects included, from ``suite_split`` ``"train"``
        (seeds outside the tuning and test splits; default) or ``"tuning"``; the
        scenario options then only pick the seed. With a 100 Hz drive (hard-v0) use
        ``action_repeat=10``: the drive takes one set-point per 10 samples anyway.
        ``reset(options=...)`` accepts the scenario options (``preset`` to
        ``scenario_seed``). ``render_mode``: ``"rgb_array"`` (MuJoCo view of hull and
        flywheel; needs ``MUJOCO_GL``, see :mod:`.render`) or ``"plot"`` (the episode so
        far: hull angle, current, flywheel rate over time, phases shaded).

    Version History
        v0: first version.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": int(NOMINAL_SAMPLE_RATE)}
    layout = ReverseStrokeTask.layout

    def __init__(self, render_mode: str | None = None, *, preset: str = "wigley-2m", randomize: bool = True,
                 ranges: Mapping[str, Any] | None = None, fixed: Mapping[str, Any] | None = None,
                 sensor_quality: str | None = None, hold_s: float | None = None, alpha: float | None = None,
                 scenario_seed: int | None = None, action_repeat: int = 1, control_mode: str = "current",
                 reward_weights: RewardWeights | Mapping[str, float] | None = None,
                 rig_factory: Callable[[Scenario], Rig] | None = None, width: int = 480, height: int = 360,
                 suite: str | None = None, suite_split: str = "train"):
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"ReverseStrokeEnv option render_mode={render_mode!r}: expected None or one of {RENDER_MODES}")
        for name, value in (("width", width), ("height", height)):
            if not (isinstance(value, int) and not isinstance(value, bool) and 16 <= value <= 4096):
                raise ValueError(f"ReverseStrokeEnv option {name}={value!r}: expected an integer number of pixels in [16, 4096]")
        if rig_factory is not None and not callable(rig_factory):
            raise ValueError(f"ReverseStrokeEnv option rig_factory={rig_factory!r}: expected a callable scenario -> rig")
        # on a suite the default reward is the ranked score alone (SCORE_ONLY; docs/ENVIRONMENT.md)
        default_weights = SCORE_ONLY if suite is not None else RewardWeights()
        self.config = EnvConfig(preset=preset, randomize=randomize, ranges=ranges or {}, fixed=fixed or {},
                                sensor_quality=sensor_quality, hold_s=hold_s, alpha=alpha,
                                scenario_seed=scenario_seed, action_repeat=action_repeat,
                                control_mode=control_mode, reward_weights=reward_weights or default_weights)
        self.render_mode = render_mode
        self.rig_factory = rig_factory or simulated_rig
        self.suite, self.suite_split = None, suite_split
        self.score_method = reward_score(suite)  # the ranked score on a suite (issue 28), else the corrected one
        if suite is not None:  # scenarios of a benchmark suite (configs/suites/), e.g. hard-v0
            from addedinertia_env.bench.suites import load_suite  # noqa: PLC0415

            self.suite = load_suite(suite)
            self.score_method = self.suite.ranked  # the suite's own ranked estimate (bench/suites.py ``ranked``)
            if suite_split == "test":
                raise ValueError(f"ReverseStrokeEnv option suite_split={suite_split!r}: the test split is held "
                                 "out; expected 'train' (seeds outside both splits) or 'tuning'")
            if suite_split not in ("train", "tuning"):
                raise ValueError(f"ReverseStrokeEnv option suite_split={suite_split!r}: expected 'train' or 'tuning'")
        self.width, self.height = width, height
        # One dict per instance (never a shared mutable class attribute).
        self.metadata = {**type(self).metadata,
                         "render_fps": max(1, round(NOMINAL_SAMPLE_RATE / self.config.action_repeat))}
        n = self.layout.size
        self.observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (n,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self._default_ranges = load_ranges()  # configs/randomization.yaml, read once
        self.scenario: Scenario | None = None
        self.rig: Rig | None = None
        self.experiment: Experiment | None = None
        self.task: ReverseStrokeTask | None = None
        self._renderer: RigRenderer | None = None
        self._plotter: PlotRenderer | None = None
        self.episode_config = self.config  # the config with this episode's reset options

    # --- the policy's rate (a property of the task) ----------------------------------
    board_mode = "zoh"  # between actions the drive holds the action: the two-rate board's "zoh" mode

    @property
    def policy_rate_hz(self) -> float | None:
        """Hz, how often the agent acts: the rig's sample rate / ``action_repeat`` (None
        before the first reset). A two-rate bench runs the policy at this host rate with
        the board in mode :attr:`board_mode` (``deploy --host-rate-hz``); the board loop
        (``loop/board_loop.py``) holds the action exactly as this environment does."""
        if self.rig is None:
            return None
        return 1.0 / (self.rig.dt * self.config.action_repeat)

    # --- Gymnasium API ----------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Draw a scenario, run the free stroke, and return the first observation and info (Gymnasium API)."""
        super().reset(seed=seed)
        cfg = self.config.with_options(options)
        drawn = int(self.np_random.integers(0, 2**63 - 1))  # always drawn: the stream stays aligned
        scenario_seed = cfg.scenario_seed if cfg.scenario_seed is not None else drawn
        self.episode_config = cfg
        if self.suite is not None:
            seed_k = cfg.scenario_seed if cfg.scenario_seed is not None else drawn
            self.scenario = self.suite.scenario(self.suite.split_seed(self.suite_split, seed_k))
        else:
            self.scenario = cfg.scenario(scenario_seed, self._default_ranges)
        self.rig = self.rig_factory(self.scenario)
        self.experiment = Experiment(self.rig, self.scenario.plan)
        self.experiment.start()
        self.task = ReverseStrokeTask.for_rig(self.experiment.known, self.config.reward_weights,
                                              self.config.control_mode)
        self._summary: dict[str, Any] | None = None
        if self._renderer is not None:  # a new model: a new renderer at the next render()
            self._renderer.close()
            self._renderer = None
        info = {"scenario": self.scenario.name, "scenario_seed": scenario_seed,
                "sensor_quality": self.scenario.sensor_quality, "phase": self.experiment.phase,
                "t": self.experiment.last.t}
        return self.task.observe(self.experiment), info

    def step(self, action: np.ndarray):
        """Apply a normalised action for ``action_repeat`` samples; (observation, reward, terminated, truncated, info)."""
        exp, task = self.experiment, self.task
        if exp is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        if not exp.needs_control:
            raise gym.error.ResetNeeded("the experiment is over (terminated); call reset() for the next one")
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (1,) or not np.isfinite(a[0]):
            raise ValueError(f"action {action!r}: expected one finite number in [-1, 1] (shape (1,))")
        cmd = task.command(a)
        tracking = energy = limits = 0.0
        for _ in range(self.config.action_repeat):
            before = exp.electric_energy
            reading = exp.step(cmd)
            e = task.tracking_error(exp, reading)
            at_limit = task.at_limit(cmd, reading)
            energy += exp.electric_energy - before
            tracking += 0.0 if e is None else e * e
            limits += at_limit
            if exp.done:
                break
        terms = task.terms(tracking_sq=tracking, energy=energy, limit_samples=limits, dt=exp.rig.dt)
        info: dict[str, Any] = {"phase": exp.phase, "t": exp.last.t}
        terminated = exp.done
        if terminated:
            self._summary = self._score()
            terms["accuracy"] = task.accuracy_term(self._summary["rel_error"], failed=self._summary["failed"])
            info.update(self._summary)
        info["reward_terms"] = terms
        reward = float(sum(terms.values()))
        return task.observe(exp), reward, terminated, False, info

    def render(self):
        """An RGB frame (``rgb_array``) or a figure of the run so far (``plot``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; make the env with render_mode='rgb_array' or 'plot'")
            return None
        if self.experiment is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        if self.render_mode == "plot":
            if self._plotter is None:
                self._plotter = PlotRenderer()
            return self._plotter.render(self.experiment.record(), title=self._title())
        if self._renderer is None:
            if not hasattr(self.rig, "model"):
                raise RuntimeError(f"render_mode='rgb_array' draws a MuJoCo rig; {type(self.rig).__name__} has no model")
            self._renderer = RigRenderer(self.rig.model, self.width, self.height)
        exp = self.experiment
        reference = float(exp.reference.phi(exp.last.t)) if exp.reference is not None else None
        return self._renderer.render(self.rig.data, reference_angle=reference)

    def close(self):
        """Release the renderers."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None

    # --- for controllers, runners and scoring -----------------------------------------
    def controller_context(self):
        """The :class:`agents.base.ControllerContext` of this episode (sensor data and known
        constants only), with ``dt`` the control period (sample period x action repeat)."""
        if self.experiment is None:
            raise gym.error.ResetNeeded("call reset() before controller_context()")
        ctx = _runner_context(self.experiment)
        # the agent's period is the rig's sample period x action_repeat, whatever the drive's
        # own set-point period (a suite's 100 Hz drive already sets ctx.dt to 10 samples)
        dt = self.rig.dt * self.config.action_repeat
        if self.config.action_repeat == 1 and ctx.policy_rate_hz is None:
            return ctx
        return dataclasses.replace(ctx, dt=dt, policy_rate_hz=1.0 / dt, sample_dt=self.rig.dt)

    def record(self, run_id: str = "run") -> RunRecord:
        """The episode's run record so far (complete once terminated)."""
        if self.experiment is None:
            raise gym.error.ResetNeeded("call reset() before record()")
        return self.experiment.record(run_id, extra_experiment={"scenario": self.scenario.name})

    def lambda66_true(self) -> float:
        """The episode's true lambda66 (kg m^2): its record's ``truth`` block, as the score reads it
        (:func:`addedinertia_env.evaluation.scoring.truth_lambda66`); nan on a bench or before ``reset()``."""
        if self.experiment is None:
            return math.nan
        return truth_lambda66([self.record()])

    # --- internals --------------------------------------------------------------------
    def _score(self) -> dict[str, Any]:
        """The benchmark numbers of the finished episode: the one scoring
        (:func:`addedinertia_env.evaluation.scoring.score_episode`; the corrected score, or the
        ranked one on a suite: :func:`~addedinertia_env.evaluation.scoring.reward_score`)."""
        return score_episode([self.record()], self.score_method).info()

    def _title(self) -> str:
        s = self.scenario
        true = self._summary["lambda66_true"] if self._summary is not None else self.lambda66_true()
        text = f"{s.name}: lambda66 true {true:.3f} kg m^2"
        if self._summary is not None:
            text += f", estimate {self._summary['lambda66_est']:.3f} ({100 * self._summary['rel_error']:+.2f} %)"
        return text

