"""One training run: vectorised envs, VecNormalize, evaluation, checkpoints, TensorBoard, a card.

Outputs in ``out``::

    model.zip              the stable-baselines3 model
    vecnormalize.pkl       observation statistics (export bakes them into the ONNX graph)
    training_card.json     algo, config, seeds, environment steps, wall and CPU time, final evaluation
    best/best_model.zip    best model of the periodic evaluations
    eval/evaluations.npz   periodic evaluation results (EvalCallback)
    eval/curve.jsonl       one line per evaluation (periodic, and the final one: every run has one)
    checkpoints/           model_<N>_steps.zip + vecnormalize + cost JSON (+ replay buffer, off-policy)
    tb/                    TensorBoard logs (``tensorboard --logdir out/tb``)

Resuming (``resume=checkpoint.zip``) reloads the model, its VecNormalize statistics, the
replay buffer if any, and the cost so far, then trains up to ``n_timesteps`` in all.
The resumed run is not bit-identical to an uninterrupted one (environment RNGs restart).
"""

from __future__ import annotations

from addedinertia_env.foundation.machine import machine_info

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.sim.presets import ConfigError
from addedinertia_env.experiment.task import OBSERVATION_FIELDS
from addedinertia_env.learning.callbacks import (
    CostCheckpointCallback,
    EpisodeMetricsCallback,
    SeededEvalCallback,
    TrainingClock,
    write_json_atomic,
)
from addedinertia_env.learning.config import TrainConfig
from addedinertia_env.learning.envs import effective_action_repeat, make_vec, pinned_base_params, uses_batched

OFF_POLICY = {"sac", "td3"}


def _normalizer(venv, cfg: TrainConfig, training: bool):
    from stable_baselines3.common.vec_env import VecNormalize  # noqa: PLC0415

    norm = dict(cfg.normalize)
    norm.setdefault("gamma", cfg.hyperparams.get("gamma", 0.99))
    vn = VecNormalize(venv, training=training, **norm)
    if not training:
        vn.norm_reward = False
    return vn


def resume_files(checkpoint: str | Path) -> dict[str, Path | None]:
    """Files that belong with a checkpoint zip: VecNormalize stats, replay buffer, cost so far."""
    ckpt = Path(checkpoint)
    if not ckpt.exists():
        raise FileNotFoundError(f"checkpoint {ckpt} does not exist; pass a model_<N>_steps.zip or a model.zip")
    m = re.fullmatch(r"(.*)_(\d+)_steps\.zip", ckpt.name)
    if m:
        prefix, steps = m.groups()
        found = {"vecnormalize": ckpt.with_name(f"{prefix}_vecnormalize_{steps}_steps.pkl"),
                 "replay_buffer": ckpt.with_name(f"{prefix}_replay_buffer_{steps}_steps.pkl"),
                 "cost": ckpt.with_name(f"{prefix}_cost_{steps}_steps.json")}
    else:
        found = {"vecnormalize": ckpt.with_name("vecnormalize.pkl"), "replay_buffer": ckpt.with_name("replay_buffer.pkl"),
                 "cost": ckpt.with_name("training_card.json")}
    if not found["vecnormalize"].exists():
        raise ConfigError(f"resume {ckpt}: missing {found['vecnormalize'].name} beside it (VecNormalize statistics)")
    return {k: (v if v.exists() else None) for k, v in found.items()}


def train(cfg: TrainConfig, seed: int, out: str | Path, resume: str | Path | None = None,
          command: str = "", verbose: int = 0, device: str = "cpu") -> dict[str, Any]:
    """Train per ``cfg``; returns the training card (also written to ``out/training_card.json``)."""
    import torch  # noqa: PLC0415
    from stable_baselines3.common.utils import set_random_seed  # noqa: PLC0415

    torch.set_num_threads(1)  # small networks: threads cost more than they give on shared cores
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    set_random_seed(seed)
    clock = TrainingClock()
    if cfg.residual.get("enabled") and not cfg.residual.get("base_params"):
        cfg.residual["base_params"] = pinned_base_params(cfg.residual["base"])  # one base for the whole run
    venv = make_vec(cfg.env_id, cfg.env_kwargs, cfg.residual, cfg.n_envs, seed, cfg.vec_env)
    clock.watch(venv)
    venv, model = _model(cfg, venv, seed, out, resume, verbose, device, clock)
    done_before = int(model.num_timesteps)
    remaining = cfg.n_timesteps - done_before
    if remaining <= 0:
        raise ConfigError(f"resume {resume}: the checkpoint already has {done_before} steps >= "
                          f"n_timesteps {cfg.n_timesteps}; pass a larger --timesteps")
    eval_env, evaluator, checkpoints = _callbacks(cfg, out, clock, verbose)
    model.learn(total_timesteps=remaining, callback=[evaluator, checkpoints, EpisodeMetricsCallback()], reset_num_timesteps=not resume,
                tb_log_name=cfg.algo, progress_bar=False)
    model.save(str(out / "model.zip"))
    venv.save(str(out / "vecnormalize.pkl"))
    venv.close()  # joins subprocess workers, so their CPU time lands in RUSAGE_CHILDREN
    cost = clock.snapshot(model.num_timesteps)

    eval_env.obs_rms = venv.obs_rms
    final = evaluate(model, eval_env, cfg.eval["seed"], cfg.eval["n_episodes"])
    eval_env.close()
    final["curve"] = str(append_final_curve_row(out / "eval" / "curve.jsonl", final, model.num_timesteps, clock))
    card = _training_card(cfg, seed, resume, command, model, cost, done_before, final, evaluator)
    write_json_atomic(out / "training_card.json", card)
    return card


def _model(cfg: TrainConfig, venv, seed: int, out: Path, resume: str | Path | None, verbose: int, device: str,
           clock: TrainingClock):
    """The normalised training env and the model: new, or loaded from the checkpoint ``resume`` with its
    VecNormalize statistics, replay buffer (off-policy) and the cost so far (into ``clock``)."""
    from stable_baselines3.common.vec_env import VecNormalize  # noqa: PLC0415

    algo_cls = cfg.algo_class
    tb = str(out / "tb")
    if resume:
        files = resume_files(resume)
        venv = VecNormalize.load(str(files["vecnormalize"]), venv)
        venv.training = True
        model = algo_cls.load(str(resume), env=venv, tensorboard_log=tb, device=device)
        if files["replay_buffer"] is not None and cfg.algo in OFF_POLICY:
            model.load_replay_buffer(str(files["replay_buffer"]))
        if files["cost"] is not None:
            cost = json.loads(files["cost"].read_text())
            cost = cost.get("cost", cost)
            clock.offset_wall_s, clock.offset_cpu_s = float(cost["wall_s"]), float(cost["cpu_s"])
    else:
        venv = _normalizer(venv, cfg, training=True)
        model = algo_cls(cfg.policy, venv, seed=seed, tensorboard_log=tb, verbose=verbose, device=device,
                         **cfg.model_kwargs())
    return venv, model


def _callbacks(cfg: TrainConfig, out: Path, clock: TrainingClock, verbose: int):
    """The evaluation env and the periodic evaluation and checkpoint callbacks: evaluation on the batched env
    when training uses it (one seeded episode per environment), else on one env."""
    batched = uses_batched(cfg.env_id, cfg.residual, cfg.vec_env, cfg.env_kwargs)
    n_eval_envs = cfg.eval["n_episodes"] if batched else 1
    eval_env = _normalizer(make_vec(cfg.env_id, cfg.env_kwargs, cfg.residual, n_eval_envs, cfg.eval["seed"],
                                    cfg.vec_env), cfg, False)
    evaluator = SeededEvalCallback(eval_env, cfg.eval["seed"], clock=clock, n_eval_episodes=cfg.eval["n_episodes"],
                                   eval_freq=max(cfg.eval["freq"] // cfg.n_envs, 1),
                                   best_model_save_path=str(out / "best"), log_path=str(out / "eval"),
                                   deterministic=True, verbose=verbose)
    checkpoints = CostCheckpointCallback(clock, save_freq=max(cfg.checkpoint_freq // cfg.n_envs, 1),
                                         save_path=str(out / "checkpoints"), name_prefix="model",
                                         save_vecnormalize=True, save_replay_buffer=cfg.algo in OFF_POLICY)
    return eval_env, evaluator, checkpoints


def _training_card(cfg: TrainConfig, seed: int, resume: str | Path | None, command: str, model, cost: dict[str, Any],
                   done_before: int, final: dict[str, Any], evaluator) -> dict[str, Any]:
    """The training card: what was trained and how (config, seeds, board mode, observation), its cost and
    machine, and the final and best evaluations."""
    return {
        "kind": "addedinertia training card",
        "algo": cfg.algo,
        "env_id": cfg.env_id,
        "config": cfg.as_dict(),
        "seed": seed,
        "env_seeds": [seed + k for k in range(cfg.n_envs)],
        "eval_seed": cfg.eval["seed"],
        "action_repeat": effective_action_repeat(cfg.env_kwargs),
        "board_mode": "zoh",  # the environment holds each action (zero-order hold): the board mode of a two-rate bench
        "observation_fields": list(OBSERVATION_FIELDS),
        "residual": cfg.residual if cfg.residual.get("enabled") else None,
        "command": command,
        "resumed_from": str(resume) if resume else None,
        "cost": {**cost, "cpu_minutes": round(cost["cpu_s"] / 60.0, 2), "env_steps_before_resume": done_before},
        "machine": {**machine_info(), "device": str(model.device)},
        "final_eval": final,
        "best_eval_mean_reward": (float(evaluator.best_mean_reward) if np.isfinite(evaluator.best_mean_reward)
                                  else None),  # None: no periodic evaluation ran
    }


def append_final_curve_row(path: Path, final: dict[str, Any], timesteps: int, clock) -> Path:
    """Add the final evaluation to the curve ``path`` (``eval/curve.jsonl``) unless a periodic
    evaluation already ran at ``timesteps``: a run shorter than ``eval.freq`` still has a curve."""
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []
    if rows and rows[-1].get("timesteps") == int(timesteps):
        return path
    row: dict[str, Any] = {"timesteps": int(timesteps), "mean_reward": final["mean_reward"],
                           "n_episodes": final["n_episodes"], "wall_s": round(clock.wall_s, 2),
                           "cpu_s": round(clock.cpu_s, 2), "failed": final.get("failed_estimates", 0),
                           "failure_rate": final.get("failure_rate"), "final": True}
    for key in ("median_abs_rel_error", "mean_abs_rel_error", "mean_energy_J"):
        if key in final:
            row[key] = final[key]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        fh.write(json.dumps(row, allow_nan=False) + "\n")
    return path


def evaluate(model, eval_env, eval_seed: int, n_episodes: int) -> dict[str, Any]:
    """Deterministic episodes on the fixed evaluation seed: reward and, where given, lambda66 error."""
    from stable_baselines3.common.evaluation import evaluate_policy  # noqa: PLC0415

    finals: list[dict[str, Any]] = []

    def grab(local_vars: dict[str, Any], _globals: dict[str, Any]) -> None:
        if local_vars["done"]:
            finals.append(local_vars["info"])

    eval_env.seed(eval_seed)
    rewards, lengths = evaluate_policy(model, eval_env, n_eval_episodes=n_episodes, deterministic=True,
                                       return_episode_rewards=True, callback=grab)
    result: dict[str, Any] = {"n_episodes": n_episodes, "mean_reward": float(np.mean(rewards)),
                              "std_reward": float(np.std(rewards)), "mean_length": float(np.mean(lengths))}
    rel_all = [abs(float(i["rel_error"])) for i in finals if i.get("rel_error") is not None]
    rel = [r for r in rel_all if np.isfinite(r)]
    if rel_all:
        result["failed_estimates"] = len(rel_all) - len(rel)
        result["failure_rate"] = result["failed_estimates"] / len(rel_all)  # as the periodic curve rows say it
    if rel:
        result["mean_abs_rel_error"] = float(np.mean(rel))
        result["median_abs_rel_error"] = float(np.median(rel))
    energy = [float(i["energy_J"]) for i in finals if i.get("energy_J") is not None]
    if energy:
        result["mean_energy_J"] = float(np.mean(energy))
    return result
