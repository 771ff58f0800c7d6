"""``addedinertia train --algo ppo|sac|td3|recurrent-ppo``: train a learned controller (docs/LEARNING.md)."""

from __future__ import annotations

import shlex
import sys

from addedinertia_env.cli.common import emit_json, info, positive_int


def register(sub) -> None:
    """Add the ``train`` subcommand and its options to the subparsers ``sub`` (``addedinertia train --help``)."""
    p = sub.add_parser("train", help="train a policy with stable-baselines3 (docs/LEARNING.md)",
                       description="Train a policy on AddedInertia/ReverseStroke-v0 with vectorised environments, "
                                   "VecNormalize, periodic evaluation on fixed seeds, checkpoints and TensorBoard.")
    p.add_argument("--algo", required=True, choices=["ppo", "sac", "td3", "recurrent-ppo"])
    p.add_argument("--config", default=None, help="algorithm YAML (default: configs/algos/<algo>.yaml)")
    p.add_argument("--env", default=None, help="Gymnasium id of the block to use (default: the reverse stroke)")
    p.add_argument("--timesteps", type=positive_int, default=None, help="agent steps in all (default: the config's)")
    p.add_argument("--seed", type=int, default=0, help="training seed (env k is seeded with seed + k)")
    p.add_argument("--n-envs", type=positive_int, default=None, help="parallel environments (default: the config's)")
    p.add_argument("--vec-env", choices=["batched", "dummy", "subproc"], default=None,
                   help="vectorisation: batched (the batched engine; the configs' default for the reverse stroke), "
                        "dummy or subproc (single envs)")
    p.add_argument("--residual", action="store_true",
                   help="learn a correction on top of the config's base controller (default feedforward-pd)")
    p.add_argument("--resume", default=None, metavar="CHECKPOINT", help="model_<N>_steps.zip or model.zip to go on from")
    p.add_argument("--out", default="out/train", help="output folder (model.zip, vecnormalize.pkl, card, tb/)")
    p.add_argument("--device", default="cpu", help="torch device: cpu (default), cuda or auto; nothing needs a GPU")
    p.add_argument("--verbose", action="store_true", help="stable-baselines3 progress on stderr")
    p.add_argument("--json", action="store_true", help="print the training card as one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``addedinertia train`` with the parsed ``args``; trains and writes the model (``model.zip``) and its card under ``--out``; returns 0; bad input raises (the caller, :func:`~addedinertia_env.cli.main`, turns it into one line and exit 2)."""
    from addedinertia_env.learning.config import DEFAULT_ENV_ID, load_config  # noqa: PLC0415 - torch is heavy
    from addedinertia_env.learning.train import train  # noqa: PLC0415

    cfg = load_config(args.algo, args.config, env_id=args.env or DEFAULT_ENV_ID)
    if args.timesteps is not None:
        cfg.n_timesteps = args.timesteps
    if args.n_envs is not None:
        cfg.n_envs = args.n_envs
    if args.vec_env is not None:
        cfg.vec_env = args.vec_env
    if args.residual:
        cfg.residual["enabled"] = True
    command = "addedinertia " + shlex.join(sys.argv[1:]) if sys.argv and "train" in sys.argv else ""
    info(f"training {cfg.algo} on {cfg.env_id} for {cfg.n_timesteps} steps with {cfg.n_envs} env(s), seed {args.seed}"
         f"{' (residual on ' + cfg.residual['base'] + ')' if cfg.residual['enabled'] else ''} -> {args.out}")
    card = train(cfg, seed=args.seed, out=args.out, resume=args.resume, command=command,
                 verbose=1 if args.verbose else 0, device=args.device)
    cost = card["cost"]
    info(f"done: {cost['env_steps']} env steps, {cost['wall_s']:.0f} s wall, {cost['cpu_minutes']:.1f} CPU min; "
         f"wrote {args.out}/model.zip")
    info(final_eval_line(card["final_eval"], card["eval_seed"]))
    info(f"curve: {card['final_eval']['curve']} (one line per evaluation); "
         f"TensorBoard: tensorboard --logdir {args.out}/tb")
    if args.json:
        emit_json(card)
    return 0


def final_eval_line(final: dict, eval_seed: int) -> str:
    """The final evaluation in one line: median |lambda66 error| in percent, the failure rate, the reward."""
    n = final["n_episodes"]
    failed = final.get("failed_estimates")
    if "median_abs_rel_error" in final:
        err = (f"median |lambda66 error| {100 * final['median_abs_rel_error']:.3f} % "
               f"(mean {100 * final['mean_abs_rel_error']:.3f} %) over the episodes with an estimate")
    else:
        err = "no lambda66 estimate in any episode"
    fails = f"{failed} of {n} failed" if failed is not None else "no failure count (the env gives no rel_error)"
    return (f"final evaluation, {n} deterministic episode(s) on eval seed {eval_seed}: {err}; {fails}; "
            f"mean reward {final['mean_reward']:.2f}")
