"""Episodes as a Minari dataset (offline RL): simulated from the environment, or run records.

Two sources, never mixed in one dataset (their spaces differ):

* **simulated** (:func:`simulate_episodes`): ``N`` episodes of ``AddedInertia/ReverseStroke-v0``
  (optionally a benchmark suite's scenarios) under a controller of the registry. Each step
  is the environment's own ``(observation, action, reward, terminated, truncated)``;
  the observation and action spaces are the environment's; the rewards are its rewards
  (their sum is the episode's return; the last step's accuracy term is the corrected score,
  :data:`addedinertia_env.evaluation.scoring.REWARD`).
* **run records** (:func:`record_episodes`): bench, emulator or simulated run records
  (``addedinertia-run/1``), one episode per record, one step per sample. The observation
  is the sample's sensor readings ``[t, phi, psi, u, i]`` (s, rad, rad, V, A); the action
  is the commanded value (``i_cmd`` in A, else ``u_cmd`` in V, else the measured current:
  ``action_source`` in the episode's metadata says which); the reward is 0 at every step
  but the last, which is ``-abs(rel_error)`` of the leaderboard's ranked score
  (:data:`addedinertia_env.evaluation.scoring.RANKED`, the energy method as written), or nan where
  the record has no truth (a real bench: its estimate is still in the episode's metadata).

The dataset's metadata (``minari.load_dataset(ID).storage.metadata["addedinertia"]``)
names the source, the score, the suite and its version, the reward weights and the
reference scores; ``ref_min_score``/``ref_max_score`` (Minari's own keys, used by
``minari.get_normalized_score``) are the mean returns of the reference controllers on the
same episodes (``zero`` and ``feedforward-pd``, the environment's baselines,
``envs/baselines.py``). Each episode's metadata holds its seed, scenario, estimate, truth,
relative error and return, so a score can be replayed from the data.

The dataset is built under a temporary folder beside the Minari root and renamed into
place: a crash leaves no half-written dataset under its name.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import tempfile
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env import __version__

RECORD_OBSERVATION = ("t", "phi", "psi", "u", "i")
PHASES = ("idle", "free", "hold", "reverse")  # info "phase" codes: index in this tuple
REFERENCE_MIN, REFERENCE_MAX = "zero", "feedforward-pd"
ENV_ID = "AddedInertia/ReverseStroke-v0"


class DatasetError(ValueError):
    """The export cannot be made from this input (bad name, existing dataset, unusable runs)."""


@dataclass
class Episode:
    """One episode's arrays (observations one longer than actions) and its flat metadata."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    infos: dict[str, np.ndarray]
    meta: dict[str, Any] = field(default_factory=dict)


def _minari():
    try:
        import minari  # noqa: PLC0415
    except ImportError:
        raise DatasetError("Minari is not installed; expected pip install 'addedinertia[data]'") from None
    return minari


def check_dataset_id(name: str) -> str:
    """``name`` as a Minari dataset id (``[namespace/]name-vN``), or :class:`DatasetError`."""
    from minari.dataset.minari_dataset import parse_dataset_id  # noqa: PLC0415

    import re  # noqa: PLC0415

    expected = "expected [namespace/]name-vN, e.g. addedinertia/ffpd-sim-v0"
    if not re.fullmatch(r"([A-Za-z0-9_.-]+/)?[A-Za-z0-9_.]+(-[A-Za-z0-9_.]+)*-v[0-9]+", name):
        raise DatasetError(f"--minari {name!r}: not a Minari dataset id; {expected}")
    try:
        parse_dataset_id(name)
    except Exception as e:  # minari raises its own error types for malformed ids
        raise DatasetError(f"--minari {name!r}: not a Minari dataset id ({e}); {expected}") from None
    return name


def _phase_codes(phases) -> np.ndarray:
    return np.array([PHASES.index(p) if p in PHASES else -1 for p in phases], dtype=np.int64)


# --- simulated episodes -------------------------------------------------------------------
def _run_env_episode(env, controller: str, seed: int) -> Episode:
    from agents import make_controller  # noqa: PLC0415

    obs, info = env.reset(seed=seed)
    ctrl = None if controller == REFERENCE_MIN else make_controller(controller)  # zero: 0 A, no controller
    if ctrl is not None:
        ctrl.reset(env.unwrapped.controller_context())
    observations, actions, rewards, phases, times = [obs], [], [], [info["phase"]], [info["t"]]
    terminated = truncated = False
    while not (terminated or truncated):
        action = (np.zeros(1, np.float32) if ctrl is None
                  else np.asarray(ctrl.predict(obs, deterministic=True)[0], dtype=np.float32).reshape(1))
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        actions.append(action)
        rewards.append(reward)
        phases.append(info["phase"])
        times.append(info["t"])
    n = len(actions)
    meta = {"seed": int(seed), "controller": controller, "scenario": str(env.unwrapped.scenario.name),
            "return": float(np.sum(rewards)), "steps": n,
            **{k: float(info[k]) for k in ("lambda66_est", "lambda66_true", "rel_error", "energy_J",
                                           "tracking_rms_rad", "saturated_frac")},
            "failed": bool(info["failed"])}
    return Episode(np.asarray(observations, np.float32), np.asarray(actions, np.float32),
                   np.asarray(rewards, np.float64), np.array([False] * (n - 1) + [bool(terminated)]),
                   np.array([False] * (n - 1) + [bool(truncated)]),
                   {"phase": _phase_codes(phases), "t": np.asarray(times, np.float64)}, meta)


def make_env(suite: str | None, action_repeat: int):
    """The environment the simulated episodes run in (``gym.make``, so its spec is stored)."""
    import gymnasium as gym  # noqa: PLC0415

    import addedinertia_env  # noqa: F401, PLC0415  (registers the environment)

    kwargs: dict[str, Any] = {"action_repeat": action_repeat}
    if suite is not None:
        kwargs["suite"] = suite
    return gym.make(ENV_ID, **kwargs)


def simulate_episodes(episodes: int, controller: str, *, seed: int = 0, suite: str | None = None,
                      action_repeat: int = 10, references: bool = True, progress=None):
    """``episodes`` episodes under ``controller`` (env seeds ``seed ..``); returns (env, episodes, scoring).

    With ``references``, the reference controllers run the same seeds and their mean
    returns become the scoring's reference scores."""
    from addedinertia_env.evaluation.scoring import REWARD  # noqa: PLC0415

    env = make_env(suite, action_repeat)
    seeds = list(range(seed, seed + episodes))
    out = []
    for k, s in enumerate(seeds):
        out.append(_run_env_episode(env, controller, s))
        if progress:
            progress(f"episode {k + 1}/{episodes} (seed {s}): return {out[-1].meta['return']:.4g}")
    refs: dict[str, float] = {}
    if references:
        for name in (REFERENCE_MIN, REFERENCE_MAX):
            runs = out if name == controller else [_run_env_episode(env, name, s) for s in seeds]  # no rerun
            refs[name] = float(np.mean([e.meta["return"] for e in runs]))
            if progress:
                progress(f"reference {name}: mean return {refs[name]:.4g} over {episodes} episode(s)")
    weights = env.unwrapped.config.reward_weights
    scoring = {"source": "simulated", "env_id": ENV_ID, "controller": controller, "seeds": seeds,
               "action_repeat": action_repeat, "suite": suite, "suite_version": _suite_version(suite),
               "score": REWARD, "return": "sum of the environment's rewards (envs/reverse_stroke.py)",
               "reward_weights": _plain(weights), "reference_scores": refs,
               "reference_controllers": {"ref_min_score": REFERENCE_MIN, "ref_max_score": REFERENCE_MAX}}
    return env, out, scoring


def _plain(obj) -> Any:
    import dataclasses  # noqa: PLC0415

    if dataclasses.is_dataclass(obj):
        return dataclasses.asdict(obj)
    return obj


def _suite_version(suite: str | None) -> dict[str, str] | None:
    """The suite's name (its ``-vN`` is the version) and the sha256 of its file, or None."""
    if suite is None:
        return None
    from addedinertia_env.bench.suites import suite_path  # noqa: PLC0415

    path = suite_path(suite)
    return {"name": suite, "file": path.name, "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}


# --- run records --------------------------------------------------------------------------
def record_episode(record) -> Episode:
    """One run record as one episode (module docstring: observation, action, reward)."""
    from addedinertia_env.evaluation.scoring import RANKED, score_episode  # noqa: PLC0415

    s = record.samples
    n = len(record.t)
    if n < 2:
        raise DatasetError(f"{record.path}: {n} sample(s); expected at least 2 to make one step")
    obs = np.column_stack([np.asarray(s[c], np.float64) for c in RECORD_OBSERVATION])
    source = next((c for c in ("i_cmd", "u_cmd") if c in s), "i")
    actions = np.asarray(s[source], np.float64)[:-1].reshape(-1, 1)
    est = score_episode([record], RANKED).info()
    rewards = np.zeros(n - 1)
    rewards[-1] = -abs(est["rel_error"]) if math.isfinite(est["rel_error"]) else math.nan
    meta = {"run_id": str(record.meta.get("run_id", "")), "file": str(record.path or ""),
            "record_source": str(record.meta.get("source", "")), "action_source": source,
            "return": float(rewards.sum()), "steps": n - 1,
            **{k: float(est[k]) for k in ("lambda66_est", "lambda66_true", "rel_error", "energy_J",
                                          "tracking_rms_rad", "saturated_frac")},
            "failed": bool(est["failed"])}
    term = np.zeros(n - 1, bool)
    term[-1] = True
    return Episode(obs, actions, rewards, term, np.zeros(n - 1, bool),
                   {"phase": _phase_codes(record.phase), "t": obs[:, 0].copy()}, meta)


def record_episodes(paths: list[str]):
    """Episodes of the run records at ``paths`` (read and validated; a bad one raises RecordError)."""
    from addedinertia_env.records.record import read_record  # noqa: PLC0415
    from addedinertia_env.evaluation.scoring import RANKED  # noqa: PLC0415

    seen: dict[Path, str] = {}
    for p in paths:  # run-0001.csv and run-0001.json are one record: never two episodes
        stem = Path(p).resolve().with_suffix("")
        if stem in seen:
            raise DatasetError(f"{p}: the same run record as {seen[stem]}; expected each record once "
                               "(its .csv or its .json)")
        seen[stem] = str(p)
    episodes = [record_episode(read_record(p)) for p in paths]
    scoring = {"source": "run records", "files": [str(p) for p in paths], "score": RANKED,
               "return": "-abs(rel_error) of the score at the last step (nan without a truth block)",
               "observation": list(RECORD_OBSERVATION), "suite": None, "suite_version": None,
               "reference_scores": {}}
    return episodes, scoring


# --- writing ------------------------------------------------------------------------------
def _spaces_for_records(episodes: list[Episode]):
    from gymnasium import spaces  # noqa: PLC0415

    return (spaces.Box(-np.inf, np.inf, (len(RECORD_OBSERVATION),), np.float64),
            spaces.Box(-np.inf, np.inf, (1,), np.float64))


@contextmanager
def _datasets_root(root: Path):
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def dataset_path(dataset_id: str) -> Path:
    """Where Minari keeps ``dataset_id`` (``MINARI_DATASETS_PATH`` or ``~/.minari/datasets``)."""
    from minari.storage import get_dataset_path  # noqa: PLC0415

    return Path(get_dataset_path(dataset_id))


def write_dataset(dataset_id: str, episodes: list[Episode], scoring: dict[str, Any], *, env=None,
                  description: str = "") -> Path:
    """Write ``episodes`` as the Minari dataset ``dataset_id`` (atomically); returns its folder."""
    minari = _minari()
    from minari.data_collector import EpisodeBuffer  # noqa: PLC0415

    check_dataset_id(dataset_id)
    final = dataset_path(dataset_id)
    if final.exists():
        raise DatasetError(f"--minari {dataset_id}: a dataset already exists at {final}; "
                           "expected a new name or version (Minari datasets are never overwritten)")
    if not episodes:
        raise DatasetError("no episodes to export; expected run records or --simulate N")
    root = dataset_path("")
    buffers = [EpisodeBuffer(id=k, seed=e.meta.get("seed"), observations=e.observations, actions=e.actions,
                             rewards=list(e.rewards), terminations=list(e.terminations),
                             truncations=list(e.truncations), infos=e.infos)
               for k, e in enumerate(episodes)]
    kwargs: dict[str, Any] = {}
    if env is not None:
        kwargs["env"] = env
    else:
        kwargs["observation_space"], kwargs["action_space"] = _spaces_for_records(episodes)
    refs = scoring.get("reference_scores") or {}
    if REFERENCE_MIN in refs and REFERENCE_MAX in refs:
        kwargs["ref_min_score"], kwargs["ref_max_score"] = refs[REFERENCE_MIN], refs[REFERENCE_MAX]
    tmp = Path(tempfile.mkdtemp(prefix=".export-", dir=root))
    try:
        with _datasets_root(tmp), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r"(`(author_email|eval_env)` is set to None|env_spec is None)", category=UserWarning)
            ds = minari.create_dataset_from_buffers(
                dataset_id, buffers, algorithm_name=scoring.get("controller") or scoring["source"],
                author="addedinertia", code_permalink="https://github.com/addedinertia/addedinertia",
                description=description or f"addedinertia {__version__}: {scoring['source']} episodes",
                data_format="hdf5", **kwargs)
            ds.storage.update_metadata({"addedinertia": {**scoring, "version": __version__}})
            ds.storage.update_episode_metadata([e.meta for e in episodes])
        final.parent.mkdir(parents=True, exist_ok=True)
        os.rename(tmp / dataset_id, final)  # same file system: atomic; fails if it appeared meanwhile
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final
