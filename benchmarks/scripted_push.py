"""The scripted pushing baseline (``dynpush.policies.scripted``): how far does a hand-written controller
that reads the true state get on the training task?

Not a learned policy and not a benchmark of speed: a feasibility reference for training and the expert
that ``dynpush imitate`` distils. Prints one JSON object (success, object ever within ``d_success`` of
the goal, toppled, undesired-collision and EE-contact share of the steps, per column, and the share of
each episode every constraint group is violated, Table II as in ``dynpush eval``; how the episodes end and
the success per goal rotation and distance, ``goal_error`` as in ``dynpush eval``) and writes a top-down PNG of
the first episodes (``dynpush play``'s drawing).

    python benchmarks/scripted_push.py [--num-envs 64] [--goal-yaw-difficulty 1.0] [--png scripted.png]
        [--set push_speed=0.8 object_size=0.4]   # ScriptedPusherConfig fields
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch


class ContactObserver:
    """Per step: the worlds whose object is within ``d_success`` of the goal, and the contact columns."""

    def __init__(self, env, probe):
        self.env, self.probe = env, probe
        self.goal = env.task.goal_pos.numpy()[:, :2].copy()
        self.reached = np.zeros(env.num_envs, dtype=bool)
        self.contact_steps = np.zeros(env.task.contacts.shape[1])
        self.collision_steps, self.steps = 0, 0

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        in_episode, continuing = in_episode.cpu().numpy(), continuing.cpu().numpy()
        distance = np.linalg.norm(self.probe.object()[:, :2] - self.goal, axis=1)
        self.reached |= continuing & (distance <= self.env.cfg.rewards.success_distance)
        contacts = self.env.task.contacts.numpy() * in_episode[:, None]  # the last column is the EE-object contact
        self.contact_steps += contacts.sum(0)
        self.collision_steps += int((contacts[:, :-1].sum(1) > 0).sum())
        self.steps += int(in_episode.sum())


def run(num_envs: int, goal_yaw_difficulty: float, seed: int, png: Path | None, overrides: tuple[str, ...] = ()) -> dict:
    from dynpush.policies.episodes import run_first_episodes
    from dynpush.policies.observers import GoalErrorObserver
    from dynpush.policies.tables import ConstraintObserver
    from dynpush.policies.scripted import ScriptedPusher
    from dynpush.policies.fine_tune import scripted_expert
    from dynpush.policies.play import TrajectoryObserver, Trajectories, episode_row, episode_setup, plot_play
    from dynpush.sim.config import ObservationNoiseConfig, PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    env = PushEnv(PushEnvConfig(num_envs=num_envs, seed=seed, noise=ObservationNoiseConfig(enabled=False)))
    env.set_goal_difficulty(goal_yaw_difficulty)
    env.reset(randomize_episode_step=False)
    controller = ScriptedPusher(env, scripted_expert(None, overrides, "--set"))
    contacts, paths, constraints = ContactObserver(env, controller.probe), TrajectoryObserver(env), ConstraintObserver(env)
    goal_errors = GoalErrorObserver(env, num_envs)
    setups = [episode_setup(env, w) for w in range(num_envs)]
    outcome = run_first_episodes(env, controller, [contacts, paths, constraints, goal_errors], started=True)
    rewards = env.cfg.rewards
    steps = contacts.steps
    result = {
        "episodes": num_envs, "goal_yaw_difficulty": goal_yaw_difficulty, "seed": seed, "overrides": list(overrides),
        "success_rate": float(outcome.success.mean()), "reached_within_d_success_rate": float(contacts.reached.mean()),
        "toppled_rate": float(outcome.toppled.mean()),
        "undesired_collision_percent_of_steps": float(100.0 * contacts.collision_steps / steps),
        "collision_percent_of_steps_per_column": [round(float(100.0 * v / steps), 3) for v in contacts.contact_steps[:-1]],
        "ee_contact_percent_of_steps": float(100.0 * contacts.contact_steps[-1] / steps),
        "constraint_violation_percent": ConstraintObserver.percent_of_time(constraints.violated.cpu().numpy(), outcome.length),
        "goal_error": GoalErrorObserver.summary([goal_errors], outcome, rewards.success_distance,
                                                np.radians(rewards.success_angle_deg)),
    }
    if png is not None:
        shown = min(num_envs, 8)
        rows = [episode_row(setups[w], env.cfg.control_dt, bool(outcome.success[w]), bool(outcome.toppled[w]),
                            int(outcome.length[w]), int(outcome.first_success_step[w])) for w in range(shown)]
        recorded = paths.paths
        plot_play({"policy": "scripted baseline", "episodes": rows},
                  Trajectories(*([a[:shown] for a in getattr(recorded, name)] for name in ("base", "ee", "object"))), png)
        result["png"] = str(png)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--goal-yaw-difficulty", type=float, default=1.0,
                        help="share of the drawn goal yaw change (the training curriculum; 1 = the paper's task)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--png", default=None, help="top-down picture of the first 8 episodes")
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE",
                        help="ScriptedPusherConfig overrides, e.g. push_speed=0.8 object_size=0.4")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(json.dumps(run(args.num_envs, args.goal_yaw_difficulty, args.seed, Path(args.png) if args.png else None, args.set),
                     indent=1))


if __name__ == "__main__":
    main()
