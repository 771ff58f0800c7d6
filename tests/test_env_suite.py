"""Every environment of the project through one generic check, in the manner of dm_control's
suite tests (issue 29 item 6).

The cases are found, not listed: every Gymnasium id registered under the project's namespace
(``AddedInertia/``) and, for the reverse-stroke id, every rig preset in ``configs/rigs/`` and
every benchmark suite in ``configs/suites/``. Each case must

* pass Gymnasium's ``env_checker`` with no warning (spaces, reset/step API, seeding);
* give finite observations inside the observation space over a whole (short) episode;
* be deterministic under a seed: the same seed and actions give the same trajectory
  (observations, rewards, infos), another seed another one;
* report reward terms (``info["reward_terms"]``) that sum to the reward at every step.

Episodes are kept short (hold 0.2 s, 50 samples per action); the suites' cases, whose
scenarios are longer, and the env checker on the presets other than the default (about 20 s
each: it resets many times) are marked slow.
"""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import addedinertia_env  # noqa: F401 - registers the ids
from addedinertia_env.bench.suites import available_suites
from addedinertia_env.learning.toy import register_toy
from addedinertia_env.sim.presets import available_rigs

NAMESPACE = "AddedInertia"
REVERSE_STROKE = "AddedInertia/ReverseStroke-v0"
SHORT = {"hold_s": 0.2, "action_repeat": 50}
# ids whose reward is one term by design (no ``reward_terms`` in info); each with its reason
ONE_TERM = {"AddedInertia/ToyTracking-v0": "the toy stand-in's reward is its tracking cost alone (learning/toy.py)"}
SLOW_IDS: set[str] = set()

register_toy()


def project_ids() -> list[str]:
    """Every id registered under the project's namespace."""
    return sorted(k for k, spec in gym.registry.items() if spec.namespace == NAMESPACE)


def cases():
    out = []
    for env_id in project_ids():
        if env_id == REVERSE_STROKE:
            out += [pytest.param(env_id, {**SHORT, "preset": p}, id=f"{env_id}[{p}]") for p in available_rigs()]
            out += [pytest.param(env_id, {"suite": s, "action_repeat": 50}, id=f"{env_id}[suite={s}]",
                                 marks=pytest.mark.slow) for s in available_suites()]
        else:
            marks = [pytest.mark.slow] if env_id in SLOW_IDS else []
            out.append(pytest.param(env_id, {}, id=env_id, marks=marks))
    return out


CASES = cases()
DEFAULT_PRESET = "wigley-2m"  # the env's default: its checker case runs by default, the others' are slow
CHECKER_CASES = [c if c.values[1].get("preset", DEFAULT_PRESET) == DEFAULT_PRESET or c.marks
                 else pytest.param(*c.values, id=c.id, marks=pytest.mark.slow) for c in CASES]


def _rollout(env_id: str, kwargs: dict, seed: int, n_max: int = 2000):
    env = gym.make(env_id, **kwargs)
    actions = np.random.default_rng(seed).uniform(-0.3, 0.3, size=(n_max,) + env.action_space.shape)
    obs, info = env.reset(seed=seed)
    out = {"obs": [obs], "rewards": [], "infos": [info]}
    for k in range(n_max):
        obs, reward, terminated, truncated, info = env.step(actions[k].astype(env.action_space.dtype))
        out["obs"].append(obs)
        out["rewards"].append(reward)
        out["infos"].append(info)
        if terminated or truncated:
            break
    out["space"] = env.observation_space
    env.close()
    return out


def _same(a, b) -> bool:
    """Equal, NaN equal to NaN, through dicts, lists and arrays."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple, np.ndarray)):
        a, b = np.asarray(a), np.asarray(b)
        if a.dtype.kind in "fc":
            return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
        if a.dtype == object:
            return a.shape == b.shape and all(_same(x, y) for x, y in zip(a.ravel(), b.ravel()))
        return np.array_equal(a, b)
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b


def test_the_cases_cover_every_project_id_preset_and_suite():
    ids = {p.values[0] for p in CASES}
    assert ids == set(project_ids()) and REVERSE_STROKE in ids
    presets = {p.values[1].get("preset") for p in CASES} - {None}
    assert presets == set(available_rigs()) and len(presets) >= 2


@pytest.fixture(scope="module")
def rollouts():
    """Two rollouts per case under seed 0 and one under seed 1, computed once per case."""
    cache: dict[str, dict] = {}

    def get(env_id: str, kwargs: dict, seed: int, again: bool = False):
        key = f"{env_id}/{sorted(kwargs.items())}/{seed}/{again}"
        if key not in cache:
            cache[key] = _rollout(env_id, kwargs, seed)
        return cache[key]

    return get


@pytest.mark.parametrize(("env_id", "kwargs"), CHECKER_CASES)
def test_env_checker_passes_with_no_warning(env_id, kwargs):
    env = gym.make(env_id, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)  # rendering: tests/test_env.py
    env.close()


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_observations_are_finite_and_inside_the_space(env_id, kwargs, rollouts):
    ep = rollouts(env_id, kwargs, 0)
    assert len(ep["rewards"]) > 0
    for obs in ep["obs"]:
        assert np.all(np.isfinite(obs)), obs
        assert ep["space"].contains(obs), obs
    assert all(np.isfinite(r) for r in ep["rewards"])


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_the_same_seed_gives_the_same_trajectory_and_another_seed_another(env_id, kwargs, rollouts):
    a, b, c = rollouts(env_id, kwargs, 0), rollouts(env_id, kwargs, 0, again=True), rollouts(env_id, kwargs, 1)
    assert len(a["rewards"]) == len(b["rewards"])
    for key in ("obs", "rewards", "infos"):
        assert _same(a[key], b[key]), key
    n = min(len(a["obs"]), len(c["obs"]))
    assert not _same(a["obs"][:n], c["obs"][:n])


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_reward_terms_sum_to_the_reward(env_id, kwargs, rollouts):
    ep = rollouts(env_id, kwargs, 0)
    if env_id in ONE_TERM:
        assert all("reward_terms" not in info for info in ep["infos"][1:])
        return
    for reward, info in zip(ep["rewards"], ep["infos"][1:]):
        terms = info["reward_terms"]
        assert reward == pytest.approx(sum(terms.values()), rel=1e-12, abs=1e-15), (reward, terms)
