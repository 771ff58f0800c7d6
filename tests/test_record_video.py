"""Gymnasium's RecordVideo works on the environment out of the box (the `video` extra: MoviePy)."""

from __future__ import annotations

import numpy as np

import gymnasium as gym
from gymnasium.wrappers import RecordVideo

import addedinertia_env  # noqa: F401 - registers the ids


def test_record_video_writes_an_mp4_of_an_episode(tmp_path):
    env = gym.make("AddedInertia/ReverseStroke-v0", render_mode="plot", action_repeat=50, hold_s=0.2,
                   fixed={"period_s": 3.0})
    env = RecordVideo(env, str(tmp_path / "video"), episode_trigger=lambda _e: True, video_length=3, disable_logger=True)
    env.reset(seed=0)
    for _ in range(4):
        env.step(np.zeros(1, np.float32))
    env.close()
    videos = list((tmp_path / "video").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
