"""Does the critic see the success boundary? Its error and the advantages around success, on a trained run.

Success is a step in the task reward (``r1 = 2`` once the object is within the success distance and angle of its
goal, at most 1 just outside), so the value of the states inside the success region jumps above that of their
neighbours just outside. A critic that smooths the step over- values the states just outside and under-values those
inside; with GAE's bootstrapping that error enters the advantages: an action that takes the object into the region
is credited less than it earned, one that takes it out more. This script measures both on a checkpoint's own
rollouts, with its actor (sampled actions, as in training), its critic and the training code's CaT and GAE:

- the critic's error against the discounted returns (CaT's ``1 - delta`` included) of long rollouts, by region:
  inside success (the environment's success flag), just outside (within ``--margin`` times the success distance and
  angle), and the rest. A state counts if its return sums ``--horizon`` steps (default: until ``gamma`` to that power
  is below 2 %) and its episode does not time out within them: at a time-out rsl_rl adds the critic's own value to the
  reward, which would enter the return it is compared with;
- the mean advantage (GAE at ``lam`` 0.95 and at 1, the run's ``gamma``, one rollout of ``num_steps_per_env`` at a
  time as PPO computes it, before normalisation) of the transitions that enter success, leave it, stay in it and stay
  out, in reward-per-step units as the critic learns them.

Prints one JSON object. The world count, rollouts and seed are arguments; the rest is the run's ``config.json`` (its
curricula at their saved levels, ``p_max`` at the checkpoint's iteration).

    python benchmarks/critic_at_success.py campaigns/long2 [--checkpoint model_K.pt] [--num-envs 256]
        [--rollouts 40] [--margin 2.0] [--horizon STEPS] [--seed 3] [--set FIELD=VALUE ...]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import math
import sys
from pathlib import Path

import numpy as np
import torch

LAMBDAS = (0.95, 1.0)
"""GAE's lambda: rsl_rl's default, and advantages without the critic's part (its value only as a baseline)."""


def discounted_returns(rewards: torch.Tensor, continues: torch.Tensor, gamma: float) -> torch.Tensor:
    """``G_t = r_t + gamma * c_t * G_{t+1}`` over ``[T, N]`` (``c_t``: probability the episode goes on after step t),
    with ``G_T = 0``: exact up to ``gamma ** (T - t)`` of the value after the last step."""
    returns = torch.zeros_like(rewards)
    following = torch.zeros_like(rewards[0])
    for t in reversed(range(rewards.shape[0])):
        following = rewards[t] + gamma * continues[t] * following
        returns[t] = following
    return returns


def transition_groups(before: torch.Tensor, after: torch.Tensor, valid: torch.Tensor) -> dict[str, torch.Tensor]:
    """Masks of the transitions that enter success (``before`` 0, ``after`` 1), leave it, stay in and stay out,
    among the ``valid`` ones."""
    before, after = before.bool(), after.bool()
    return {
        "enter": valid & ~before & after,
        "leave": valid & before & ~after,
        "stay_in": valid & before & after,
        "stay_out": valid & ~before & ~after,
    }


def scored_states(time_outs: torch.Tensor, horizon: int) -> torch.Tensor:
    """Mask ``[T, N]`` of the states whose return sums ``horizon`` steps of the collected ones and meets no time-out
    within them (steps ``t .. t + horizon - 1``)."""
    steps = time_outs.shape[0]
    scored = torch.zeros_like(time_outs, dtype=torch.bool)
    if steps <= horizon:
        return scored
    count = torch.cat([torch.zeros_like(time_outs[:1], dtype=torch.long), time_outs.long().cumsum(0)])
    scored[: steps - horizon] = (count[horizon:steps] - count[: steps - horizon]) == 0
    return scored


def masked_mean(values: torch.Tensor, mask: torch.Tensor) -> float | None:
    return float(values[mask].mean()) if bool(mask.any()) else None


def collect(env, alg, rollouts: int, steps: int) -> dict[str, torch.Tensor]:
    """Runs ``rollouts`` rollouts of ``steps`` steps as PPO collects them (sampled actions, CaT, rsl_rl's storage),
    without updates. Returns ``[rollouts * steps, num_envs]`` tensors: the stored reward (reward-per-step units,
    CaT's ``1 - delta`` and the time-out bootstrap included), the probability the episode goes on, the critic's value,
    the success flag before and after each step (``valid`` False where the state before was a new episode's first,
    whose flag is not read), the object's distance [m] and rotation angle [rad] to its goal in the state before, whether
    the step timed out, and the advantages at each of ``LAMBDAS``."""
    from dynpush.policies.env_probe import EnvProbe
    from dynpush.runtime.frames import rotation_angle

    storage, probe = alg.storage, EnvProbe(env)
    rows = collections.defaultdict(list)
    obs = env.get_observations()
    success_before = env.success_t.clone()
    valid_before = torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)
    with torch.inference_mode():
        for _ in range(rollouts):
            for _ in range(steps):
                obj = probe.object()
                distance = torch.as_tensor(np.linalg.norm(env.task.goal_pos.numpy() - obj[:, :3], axis=1))
                angle = torch.as_tensor(rotation_angle(obj[:, 3:], env.task.goal_quat.numpy()))
                actions = alg.act(obs)
                obs, rewards, dones, extras = env.step(actions)
                alg.process_env_step(obs, rewards, dones, extras)
                success_after = env.success_t.clone()
                for name, row in (("distance", distance.to(env.device)), ("angle", angle.to(env.device)),
                                  ("success_before", success_before),
                                  ("success_after", success_after), ("valid", valid_before),
                                  ("time_out", extras["time_outs"].to(env.device))):
                    rows[name].append(row.unsqueeze(0))
                done = dones.bool()
                success_before, valid_before = success_after.masked_fill(done, 0), ~done
            rows["reward"].append(storage.rewards.squeeze(-1).clone())
            rows["continues"].append((1.0 - storage.dones.squeeze(-1).float()) * (1.0 - alg.deltas.squeeze(-1)))
            rows["value"].append(storage.values.squeeze(-1).clone())
            for lam in LAMBDAS:
                alg.lam = lam
                alg.compute_returns(obs)
                rows[f"advantage_{lam}"].append((storage.returns - storage.values).squeeze(-1).clone())
            storage.clear()
    return {name: torch.cat(parts) for name, parts in rows.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="a run folder (config.json and model_K.pt)")
    parser.add_argument("--checkpoint", default=None, help="model_K.pt in the run (default: the newest)")
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--rollouts", type=int, default=40, help="rollouts of num_steps_per_env steps, no update")
    parser.add_argument("--margin", type=float, default=2.0, help="'just outside': within this many times the "
                                                                   "success distance and angle")
    parser.add_argument("--horizon", type=int, default=None,
                        help="steps after a state that its return sums (default: until gamma**steps < 0.02)")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE", help="overrides of the run's config")
    args = parser.parse_args()

    from dynpush.errors import UserError
    from dynpush.policies.run_folder import latest_checkpoint, read_run_config
    from dynpush.policies.overrides import apply_overrides
    from dynpush.policies.runner import CaTOnPolicyRunner
    from dynpush.policies.train import TrainConfig

    try:
        cfg = TrainConfig.from_dict(read_run_config(args.run))
        cfg = apply_overrides(cfg, [f"env.num_envs={args.num_envs}", f"env.seed={args.seed}", *args.set]).validate()
        checkpoint = args.run / args.checkpoint if args.checkpoint else latest_checkpoint(args.run)
        if checkpoint is None or not checkpoint.is_file():
            raise UserError(f"{args.run}: no checkpoint {args.checkpoint or 'model_K.pt'}")
        horizon = args.horizon or math.ceil(math.log(0.02) / math.log(cfg.ppo.gamma))
        if args.rollouts * cfg.num_steps_per_env <= horizon:
            raise UserError(f"--rollouts x num_steps_per_env ({args.rollouts * cfg.num_steps_per_env}) must exceed"
                            f" the horizon of {horizon} steps")
        torch.set_num_threads(1)
        torch.manual_seed(args.seed)
        with contextlib.redirect_stdout(sys.stderr):  # rsl_rl prints the models; stdout carries the JSON only
            env = cfg.make_env(cfg.env)
            runner = CaTOnPolicyRunner(env, cfg.runner_cfg(), log_dir=None, device=env.device)
            runner.load(str(checkpoint))  # one process: fresh episodes at the saved curricula levels
    except UserError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2

    iteration = runner.current_learning_iteration
    runner.apply_curricula(iteration, fresh_run=False)
    runner.apply_schedules(iteration, cfg.iterations)
    if runner.near_goal_starts.share > 0:  # as CaTOnPolicyRunner.learn sets up the training episodes
        runner.apply_near_goal_starts()
    if runner.behind_starts.share > 0:
        runner.apply_behind_starts()
    distance_limit = cfg.env.rewards.success_distance
    angle_limit = float(env.success_angle.numpy()[0])  # [rad] where the goal curriculum left it
    data = collect(env, runner.alg, args.rollouts, cfg.num_steps_per_env)

    returns = discounted_returns(data["reward"], data["continues"], runner.alg.gamma)
    value = data["value"]
    usable = scored_states(data["time_out"], horizon) & data["valid"]  # valid: the state's success flag is known
    inside = data["success_before"].bool()
    near = ~inside & (data["distance"] <= args.margin * distance_limit) & (data["angle"] <= args.margin * angle_limit)
    regions = {"inside": inside, "just_outside": near, "rest": ~inside & ~near}
    critic = {name: {"states": int((mask & usable).sum()), "mean_value": masked_mean(value, mask & usable),
                     "mean_return": masked_mean(returns, mask & usable),
                     "mean_error": masked_mean(value - returns, mask & usable)}
              for name, mask in regions.items()}

    groups = transition_groups(data["success_before"], data["success_after"], data["valid"])
    advantages = {name: {"transitions": int(mask.sum()),
                         **{f"lam_{lam}": masked_mean(data[f"advantage_{lam}"], mask) for lam in LAMBDAS}}
                  for name, mask in groups.items()}
    spread = {f"lam_{lam}": float(data[f"advantage_{lam}"].std()) for lam in LAMBDAS}
    print(json.dumps({
        "run": str(args.run), "checkpoint": checkpoint.name, "iteration": iteration, "num_envs": env.num_envs,
        "steps": int(returns.shape[0]), "gamma": runner.alg.gamma, "success_distance_m": distance_limit,
        "success_angle_deg": math.degrees(angle_limit), "margin": args.margin, "horizon": horizon,
        "overrides": args.set,
        "critic_error_by_region": critic,
        "advantage_by_transition": advantages, "advantage_std": spread,
    }, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
