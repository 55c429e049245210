"""Does PPO improve the policy it starts from? Fine-tune the shipped policy where success is seconds away.

The "near goal" distribution puts the object at its goal position (within 10 cm) with the yaw off by at most 34 deg
(0.6 rad); the shipped policy succeeds there in about 63 % of the episodes. This script fine-tunes it there
(``--init-from`` the shipped ONNX, critic warm-up first) in one process and evaluates chosen checkpoints
deterministically on the same distribution (the ``dynpush eval`` code path, fixed seed). A loop that serves the
deterministic policy keeps or raises the starting success at every checkpoint; one that erodes it loses it within
tens of updates (docs/ppo_fine_tuning.md has the measured runs and what each change did).

``--distribution full`` trains and evaluates on the paper's distribution instead (the issue's second test: at equal
world-steps a fine-tune must end above its start there too).

Prints one JSON object: the start's success, and per evaluated checkpoint its actor updates, world-steps and
deterministic success and toppled rates. Exits 1 when a checkpoint falls below the start by more than ``--tolerance``
percentage points, 2 on a bad input (one line).

    python benchmarks/finetune_near_goal.py [--iterations 101] [--checkpoints 50 100] [--episodes 256]
        [--distribution near_goal|full] [--out runs/finetune_near_goal] [--set network.init_noise_std=0.1 ...]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
from pathlib import Path

NEAR_GOAL = ("env.sampling.goal_radius=(0.0, 0.1)", "env.sampling.object_yaw=(0.0, 0.0)",
             "env.sampling.goal_yaw=(-0.6, 0.6)")
"""The near-goal distribution, for training and evaluation."""

FINE_TUNE = (
    "network.actor_hidden=(512, 256, 128)", "network.critic_hidden=(512, 256, 128)",  # the shipped networks
    "env.rewards.sigma_task=1.7", "p_max_overrides={'collision': (0.1, 1.0)}",  # the shipped recipe's task
    "env.num_envs=512", "fine_tune.critic_warmup_iterations=40",
    "fine_tune.critic_warmup_learning_rate=1e-3",
    "ppo.schedule=fixed", "ppo.entropy_coef=0.002", "ppo.gamma=0.998",
    # Noise 0.1 with a learning rate scaled down with it keeps the start's success with CaT off; noise 0.2 erodes
    # the mean. With CaT on (as here) the success still falls: the open part of docs/ppo_fine_tuning.md.
    "network.init_noise_std=0.1", "ppo.learning_rate=1.5e-5",
)
"""The fine-tune's TrainConfig overrides (on the ``cpu`` preset); ``--set`` changes any of them."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iterations", type=int, default=101, help="training iterations, critic warm-up included")
    parser.add_argument("--checkpoints", type=int, nargs="+", default=[50, 100],
                        help="iterations whose checkpoints (model_K.pt, saved after iteration K) are evaluated: "
                             "multiples of --save-interval, or the last iteration")
    parser.add_argument("--save-interval", type=int, default=25)
    parser.add_argument("--episodes", type=int, default=256)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--tolerance", type=float, default=2.0, help="percentage points below the start allowed")
    parser.add_argument("--distribution", choices=("near_goal", "full"), default="near_goal",
                        help="where to train and evaluate: near the goal, or the paper's distribution")
    parser.add_argument("--init-from", default=None, help="policy.onnx to start from (default: the shipped one)")
    parser.add_argument("--out", default=None, help="run folder (default: a temporary one)")
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE", help="more TrainConfig overrides")
    args = parser.parse_args()
    for k in args.checkpoints:
        if not (0 < k < args.iterations and (k % args.save_interval == 0 or k == args.iterations - 1)):
            parser.error(f"--checkpoints: {k} is neither a multiple of --save-interval {args.save_interval} nor the"
                         f" last iteration, in [1, {args.iterations - 1}]")

    from dynpush.errors import UserError
    from dynpush.policies.evaluate import EvalConfig, evaluate
    from dynpush.policies.export import export_policy
    from dynpush.policies.run_folder import check_new_run
    from dynpush.policies.train import TrainConfig, apply_overrides, train
    from dynpush.shipped import shipped_file

    distribution = NEAR_GOAL if args.distribution == "near_goal" else ()
    overrides = [*FINE_TUNE, *distribution, f"iterations={args.iterations}", f"save_interval={args.save_interval}",
                 *args.set]
    run_dir = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="finetune_near_goal_")) / "run"
    try:  # every input checked before the first evaluation
        init_from = Path(args.init_from) if args.init_from else shipped_file("policy.onnx")
        if not init_from.is_file():
            raise FileNotFoundError(f"--init-from {init_from} not found")
        cfg = apply_overrides(TrainConfig.preset_config("cpu"), overrides).validate()
        check_new_run(run_dir)
    except (UserError, FileNotFoundError) as error:
        print(f"finetune_near_goal: {error}", file=sys.stderr)
        return 2
    eval_cfg = EvalConfig(episodes=args.episodes, seed=args.seed, overrides=distribution)

    def rates(policy: Path, out: Path) -> dict:
        summary = evaluate(policy, eval_cfg, out)
        return {"success": summary["success_rate"], "toppled": summary["toppled_rate"]}

    steps_per_iteration = cfg.env.num_envs * cfg.num_steps_per_env
    checkpoints = []
    with contextlib.redirect_stdout(sys.stderr):  # rsl_rl and the evaluations print; stdout carries the JSON only
        start = rates(init_from, run_dir / "eval_start")
        train(cfg, run_dir, command=" ".join(sys.argv), init_from=init_from)
        for k in args.checkpoints:
            policy = export_policy(run_dir, checkpoint=f"model_{k}.pt", out=run_dir / f"eval_{k}" / "policy.onnx")
            checkpoints.append({"iteration": k, "actor_updates": max(0, k + 1 - cfg.fine_tune.critic_warmup_iterations),
                                "world_steps": (k + 1) * steps_per_iteration, **rates(policy, run_dir / f"eval_{k}")})
    worst = min(c["success"] for c in checkpoints)
    print(json.dumps({"run_dir": str(run_dir), "overrides": overrides, "start": start, "checkpoints": checkpoints,
                      "kept_start": worst >= start["success"] - args.tolerance}, indent=2))
    return 0 if worst >= start["success"] - args.tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
