"""A scripted pushing baseline: how far does a hand-written controller get on the training task?

Not a learned policy and not a benchmark of speed: a feasibility reference for training. Per world
it reads the true poses (world frame) and commands the push environment with the policy's own
actions (6D base command about the default, arm held at the default pose):

1. go around the object (keeping ``clearance`` from its centre) to a point behind it, on the line
   from the goal through the object, facing the goal;
2. walk toward the goal at ``push_speed`` with the end-effector on the object's rear face,
   re-approaching when the object slides off the line; back away once it is within 4 cm.

The object's yaw is not controlled. Prints one JSON object (success, object ever within
``d_success`` of the goal, toppled, undesired-collision and EE-contact share of the steps, per
column) and writes a top-down PNG of the first episodes (``dynpush play``'s drawing).

    python benchmarks/scripted_push.py [--num-envs 64] [--goal-yaw-difficulty 1.0] [--png scripted.png]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

EE_AHEAD = 0.75  # m: end-effector centre ahead of the base origin at the default arm pose (robot.usda)


def wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


class ScriptedPusher:
    """The controller of the module docstring for all worlds of a PushEnv, called once per step like a policy."""

    def __init__(self, env, push_speed: float = 0.35, clearance: float = 1.1):
        from dynpush.policies.evaluate import EnvProbe, yaw_of

        self.env, self.probe, self.yaw_of = env, EnvProbe(env), yaw_of
        self.push_speed, self.clearance = push_speed, clearance
        self.base_default = np.asarray(env.cfg.actions.base_default)
        self.base_scale = np.asarray(env.cfg.actions.base_scale)
        self.pushing = np.zeros(env.num_envs, dtype=bool)

    def _rear_distance(self, push_dir: np.ndarray, object_yaw: np.ndarray) -> np.ndarray:
        """Centre-to-surface distance of the object opposite to ``push_dir`` [m]."""
        dims, shape = self.env.task.object_dims.numpy(), self.env.task.object_shape.numpy()
        c, s = np.cos(object_yaw), np.sin(object_yaw)
        local_x, local_y = c * push_dir[:, 0] + s * push_dir[:, 1], -s * push_dir[:, 0] + c * push_dir[:, 1]
        box = 0.5 * (np.abs(local_x) * dims[:, 0] + np.abs(local_y) * dims[:, 1])
        box = np.minimum(box, 0.5 * np.hypot(dims[:, 0], dims[:, 1]))
        return np.where(shape == 1, 0.5 * dims[:, 0], box)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Actions of every world from the true poses (``observations`` unused: a policy's call signature)."""
        base, obj = self.probe.base(), self.probe.object()
        p_base, yaw_base = base[:, :2], self.yaw_of(base[:, 3:])
        p_obj = obj[:, :2]
        to_goal = self.env.task.goal_pos.numpy()[:, :2] - p_obj
        distance = np.linalg.norm(to_goal, axis=1)
        push_dir = to_goal / np.maximum(distance[:, None], 1e-6)
        side_dir = np.stack([-push_dir[:, 1], push_dir[:, 0]], axis=1)
        rear = self._rear_distance(push_dir, self.yaw_of(obj[:, 3:]))
        stand = p_obj - push_dir * (rear + EE_AHEAD)[:, None]  # base origin with the EE on the rear face
        behind = stand - 0.3 * push_dir
        ahead_of_object = ((p_base - p_obj) * push_dir).sum(1)  # > -rear: not behind the object
        lateral = ((p_base - stand) * side_dir).sum(1)
        heading = np.arctan2(push_dir[:, 1], push_dir[:, 0])
        at_start = (np.linalg.norm(p_base - behind, axis=1) < 0.2) & (np.abs(wrap(heading - yaw_base)) < 0.3)
        self.pushing = np.where(self.pushing, (np.abs(lateral) < 0.3) & (ahead_of_object < -rear), at_start)
        side = np.sign(((p_base - p_obj) * side_dir).sum(1) + 1e-9)
        around = p_obj + side_dir * (side * (rear + self.clearance))[:, None] - push_dir * (rear + 0.8)[:, None]
        go_around = (ahead_of_object > -rear - 0.5) & ~self.pushing
        target = np.where(self.pushing[:, None], stand + 0.5 * push_dir, np.where(go_around[:, None], around, behind))
        error = target - p_base
        c, s = np.cos(yaw_base), np.sin(yaw_base)
        limit = np.where(self.pushing, self.push_speed, 0.8)
        vx = np.clip(1.5 * (c * error[:, 0] + s * error[:, 1]), -limit, limit)
        vy = np.clip(1.5 * (-s * error[:, 0] + c * error[:, 1]), -0.5, 0.5)
        yaw_rate = np.clip(2.0 * wrap(heading - yaw_base), -1.0, 1.0)
        arrived = distance < 0.04
        vx, vy, yaw_rate = np.where(arrived, -0.2, vx), np.where(arrived, 0.0, vy), np.where(arrived, 0.0, yaw_rate)
        command = np.stack([vx, vy, yaw_rate, 0 * vx, 0 * vx, np.full_like(vx, self.base_default[5])], axis=1)
        actions = np.zeros((self.env.num_envs, self.env.num_actions), dtype=np.float32)
        actions[:, :6] = (command - self.base_default) / self.base_scale  # arm actions 0: the default pose
        return actions


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


def run(num_envs: int, goal_yaw_difficulty: float, seed: int, png: Path | None) -> dict:
    from dynpush.policies.evaluate import run_first_episodes
    from dynpush.policies.play import TrajectoryObserver, Trajectories, episode_row, episode_setup, plot_play
    from dynpush.sim.config import ObservationNoiseConfig, PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    env = PushEnv(PushEnvConfig(num_envs=num_envs, seed=seed, noise=ObservationNoiseConfig(enabled=False)))
    env.set_goal_difficulty(goal_yaw_difficulty)
    env.reset(randomize_episode_step=False)
    controller = ScriptedPusher(env)
    contacts, paths = ContactObserver(env, controller.probe), TrajectoryObserver(env)
    setups = [episode_setup(env, w) for w in range(num_envs)]
    outcome = run_first_episodes(env, controller, [contacts, paths], started=True)
    steps = contacts.steps
    result = {
        "episodes": num_envs, "goal_yaw_difficulty": goal_yaw_difficulty, "seed": seed,
        "success_rate": float(outcome.success.mean()), "reached_within_d_success_rate": float(contacts.reached.mean()),
        "toppled_rate": float(outcome.toppled.mean()),
        "undesired_collision_percent_of_steps": float(100.0 * contacts.collision_steps / steps),
        "collision_percent_of_steps_per_column": [round(float(100.0 * v / steps), 3) for v in contacts.contact_steps[:-1]],
        "ee_contact_percent_of_steps": float(100.0 * contacts.contact_steps[-1] / steps),
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
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(json.dumps(run(args.num_envs, args.goal_yaw_difficulty, args.seed, Path(args.png) if args.png else None), indent=1))


if __name__ == "__main__":
    main()
