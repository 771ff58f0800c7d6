"""A cheap stand-in task with the reverse-stroke observation layout, for tests and smoke runs.

Description
    A mass-spring hull ``J phi'' + c phi = k_t i`` must follow a sinusoidal reference
    with a motor current ``i = action * i_max``. Only the tracking fields of
    :data:`addedinertia_env.experiment.task.OBSERVATION_FIELDS` are filled; the rest are zero.
    One step costs microseconds, so training and export code can be tested in seconds.
    It is NOT the rig: numbers learned here say nothing about the reverse stroke.
Action Space
    ``Box(-1, 1, (1,))``: normalised current command.
Observation Space
    ``Box(-10, 10, (16,))`` in the task's layout and scales.
Rewards
    ``-(tracking error / 5 mrad)^2``, clipped at -10 per step.
Episode End
    Truncated after ``n_steps`` steps (default 200, at ``dt`` = 10 ms).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from addedinertia_env.experiment.task import OBS_LIMIT, OBSERVATION_FIELDS, ObservationLayout

TOY_ENV_ID = "AddedInertia/ToyTracking-v0"


class ToyTrackingEnv(gym.Env):
    """The toy tracking task of the module docstring (``AddedInertia/ToyTracking-v0``).

    ``n_steps`` steps per episode of ``action_repeat`` integration steps of ``dt`` s each;
    hull ``J`` = 1 kg m^2, ``c`` = 2 N m/rad, ``k_t`` = 0.25 N m/A, ``i_max`` = 10 A.
    """

    metadata = {"render_modes": []}

    def __init__(self, n_steps: int = 200, dt: float = 0.01, action_repeat: int = 1):
        self.n_steps, self.dt, self.action_repeat = int(n_steps), float(dt), int(action_repeat)
        self.layout = ObservationLayout()
        self.observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (self.layout.size,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self._scales = np.array([OBSERVATION_FIELDS[n][1] for n in self.layout.names])
        self.J, self.c, self.k_t, self.i_max = 1.0, 2.0, 0.25, 10.0  # kg m^2, N m/rad, N m/A, A

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Draw a new reference (amplitude 0.02-0.08 rad, 1-3 rad/s) from ``seed``; returns ``(obs, {})``."""
        super().reset(seed=seed)
        self.amplitude = float(self.np_random.uniform(0.02, 0.08))  # rad
        self.omega = float(self.np_random.uniform(1.0, 3.0))  # rad/s
        self.phi, self.rate, self.k = 0.0, self.amplitude * self.omega, 0
        return self._obs(), {}

    def _ref(self, t: float) -> tuple[float, float, float]:
        a, w = self.amplitude, self.omega
        return a * np.sin(w * t), a * w * np.cos(w * t), -a * w * w * np.sin(w * t)

    def _obs(self) -> np.ndarray:
        t = self.k * self.dt
        phi_ref, rate_ref, acc_ref = self._ref(t)
        values = dict.fromkeys(self.layout.names, 0.0)
        values.update(tracking_error=phi_ref - self.phi, rate_error=rate_ref - self.rate, phi_ref=phi_ref,
                      rate_ref=rate_ref, accel_ref=acc_ref, phi=self.phi, hull_rate=self.rate,
                      ahead_10ms=self._ref(t + 0.01)[0] - phi_ref, ahead_50ms=self._ref(t + 0.05)[0] - phi_ref,
                      ahead_100ms=self._ref(t + 0.1)[0] - phi_ref, is_reverse=1.0,
                      phase_progress=self.k / self.n_steps)
        obs = np.array([values[n] for n in self.layout.names]) / self._scales
        return np.clip(obs, -OBS_LIMIT, OBS_LIMIT).astype(np.float32)

    def step(self, action):
        """Apply the normalised current ``action`` for ``action_repeat`` steps; returns ``(obs, reward, False, truncated, info)``."""
        torque = self.k_t * self.i_max * float(np.clip(np.asarray(action).reshape(-1)[0], -1, 1))
        for _ in range(self.action_repeat):
            acc = (torque - self.c * self.phi) / self.J
            self.rate += acc * self.dt
            self.phi += self.rate * self.dt
            self.k += 1
        err = (self._ref(self.k * self.dt)[0] - self.phi) / OBSERVATION_FIELDS["tracking_error"][1]
        reward = -min(err * err, 10.0)
        truncated = self.k >= self.n_steps
        return self._obs(), float(reward), False, truncated, {"tracking": reward}


def register_toy() -> None:
    """Register ``AddedInertia/ToyTracking-v0`` with Gymnasium (once; later calls do nothing)."""
    if TOY_ENV_ID not in gym.registry:
        gym.register(id=TOY_ENV_ID, entry_point=ToyTrackingEnv)


def toy_config(algo: str = "ppo", timesteps: int = 512, **overrides):
    """The ``configs/algos/<algo>.yaml`` block for the stand-in task, shortened: for tests and smoke runs."""
    from addedinertia_env.learning.config import load_config  # noqa: PLC0415

    cfg = load_config(algo, env_id=TOY_ENV_ID)
    cfg.n_timesteps = timesteps
    for key, value in overrides.items():
        setattr(cfg, key, value)
    return cfg
