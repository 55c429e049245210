"""A task any correct PPO learns from scratch on a 2-core machine: does the training loop learn?

A 0.5 m cube, the robot 1.25 m behind it and facing it, the goal 0.5 m straight ahead of the cube, the goal's yaw
ignored (success: the cube's centre within ``d_success`` = 10 cm of the goal), 8 s episodes, CaT's terminations off;
everything else is the ``cpu`` preset (its PPO, networks and the paper's rewards). A loop whose updates do not follow
the task's return (a broken advantage, value target or reward) never gets there; a correct one does within an hour.
CaT is off because it checks PPO, not the constraints: with the paper's initial ``p_max`` (collision 1.0) the robot
learns within 300 iterations to keep away from the cube.

Trains from scratch in one process and prints one JSON object: the training success rate (episodes ended in an
iteration, mean of ``--window`` iterations) against world-steps, the world-steps and minutes at which it first
reaches ``--threshold``, and the deterministic success of the final actor on ``--eval-episodes`` fresh episodes (the
``dynpush eval`` code path). Exits 1 when the threshold is not reached.

    python benchmarks/ppo_sanity.py [--iterations 600] [--num-envs 256] [--threshold 0.8] [--out runs/ppo_sanity]
        [--set ppo.gamma=0.99 ...]   # more TrainConfig overrides
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS

SANITY_TASK = [
    "scale_schedules_with_run_length=False", "env.episode_length_s=8.0",
    "env.sampling.robot_radius=(1.25, 1.25)", f"env.sampling.robot_bearing=({math.pi}, {math.pi})",
    "env.sampling.base_yaw=(0.0, 0.0)", "env.sampling.object_yaw=(0.0, 0.0)", "env.sampling.goal_yaw=(0.0, 0.0)",
    "env.sampling.goal_bearing=(0.0, 0.0)", "env.sampling.goal_radius=(0.5, 0.5)",
    "env.randomization.size_x=(0.5, 0.5)", "env.randomization.size_y=(0.5, 0.5)", "env.randomization.size_z=(0.4, 0.4)",
    "env.randomization.cylinder_probability=0.0", "env.rewards.success_angle_deg=180.0",
    f"disabled_constraint_groups={tuple(name for name, _ in CONSTRAINT_GROUPS)!r}",
]
"""TrainConfig overrides of the sanity task (on the ``cpu`` preset)."""


def first_crossing(success: np.ndarray, window: int, threshold: float) -> int | None:
    """Index of the first iteration whose trailing mean success over ``window`` iterations is >= ``threshold``."""
    if len(success) < window:
        return None
    trailing = np.convolve(success, np.ones(window) / window, mode="valid")
    hits = np.flatnonzero(trailing >= threshold)
    return int(hits[0]) + window - 1 if hits.size else None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iterations", type=int, default=600)
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--threshold", type=float, default=0.8, help="training success rate to reach")
    parser.add_argument("--window", type=int, default=10, help="iterations averaged for the success rate")
    parser.add_argument("--eval-episodes", type=int, default=256)
    parser.add_argument("--out", default=None, help="run folder (default: a temporary one)")
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE", help="more TrainConfig overrides")
    args = parser.parse_args()

    from dynpush.policies.evaluate import EvalConfig, evaluate
    from dynpush.policies.export import export_policy
    from dynpush.policies.train import TrainConfig, apply_overrides, train

    overrides = [*SANITY_TASK, f"env.num_envs={args.num_envs}", f"iterations={args.iterations}",
                 f"save_interval={args.iterations}", *args.set]
    cfg = apply_overrides(TrainConfig.preset_config("cpu"), overrides)
    run_dir = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="ppo_sanity_")) / "run"
    start = time.perf_counter()
    with contextlib.redirect_stdout(sys.stderr):  # rsl_rl prints; stdout carries the JSON only
        train(cfg, run_dir, command=" ".join(sys.argv))
    minutes = (time.perf_counter() - start) / 60.0

    records = [json.loads(line) for line in (run_dir / "progress.jsonl").read_text().splitlines()]
    success = np.array([r.get("/episode/success", np.nan) for r in records], dtype=float)
    success = np.nan_to_num(success, nan=0.0)  # an iteration in which no episode ended
    steps_per_iteration = cfg.env.num_envs * cfg.num_steps_per_env
    crossing = first_crossing(success, args.window, args.threshold)
    policy = export_policy(run_dir)  # its metadata carries the sanity task, which the evaluation rebuilds
    with contextlib.redirect_stdout(sys.stderr):
        summary = evaluate(policy, EvalConfig(episodes=args.eval_episodes, seed=0), run_dir / "eval")
    result = {
        "task": SANITY_TASK,
        "num_envs": cfg.env.num_envs,
        "iterations": len(records),
        "world_steps": len(records) * steps_per_iteration,
        "minutes": round(minutes, 2),
        "threshold": args.threshold,
        "reached_at_iteration": crossing,
        "reached_at_world_steps": None if crossing is None else (crossing + 1) * steps_per_iteration,
        "reached_at_minutes": None if crossing is None else round(minutes * (crossing + 1) / len(records), 2),
        "training_success_every_25_iterations": [round(float(s), 3) for s in success[::25]],
        "final_training_success": round(float(success[-args.window:].mean()), 3),
        "deterministic_success": summary["success_rate"],
        "deterministic_toppled": summary["toppled_rate"],
    }
    print(json.dumps(result, indent=2))
    return 0 if crossing is not None else 1


if __name__ == "__main__":
    sys.exit(main())
