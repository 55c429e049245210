"""The paper's simulation Tables I and II (section IV-A/B): its figures, and ours of a policy's first episodes.

- **Table I**: success rate and toppled-object rate [% of episodes], one first episode per world
  (:mod:`dynpush.policies.episodes`).
- **Table II**: per constraint group, the percentage of an episode's steps with any column of the group
  violated (value > 0), averaged over episodes.

Both ``dynpush eval`` (``eval.json``) and the evaluations during training (``evaluations.jsonl``) report them
through :func:`table_rates`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import torch

from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS

from .episodes import FirstEpisodes, Policy, run_first_episodes
from .observers import GoalErrorObserver
from .sample_stats import percent

if TYPE_CHECKING:
    from dynpush.sim.push_env import PushEnv

# Paper Table I (success rate %, toppled object rate %), keyed by
# (reach target sampled on the object surface, object balance constraint on).
PAPER_TABLE_I: dict[tuple[bool, bool], tuple[str, float, float]] = {
    (True, True): ("Ours (with all the above)", 91.35, 3.46),
    (True, False): ("Ours w/o object balance constraint", 90.00, 6.93),
    (False, True): ("Ours w/o sampling on object surface", 49.80, 4.50),
    (False, False): ("Ours w/o sampling on object surface & object balance constraint", 88.70, 7.73),
}
# Paper Table II: average proportion of time (%) each constraint group is violated.
PAPER_TABLE_II: dict[str, float] = {
    "base_command": 0.059, "arm_command": 0.014, "arm_action_rate": 0.032, "arm_joint_position": 0.011,
    "arm_joint_velocity": 0.007, "arm_joint_torque": 0.189, "leg_joint_torque": 0.473, "collision": 0.01,
    "object_balance": 0.298,
}


def paper_table_i_row(training_config: dict) -> tuple[str, float, float]:
    """The paper's Table I row (name, success %, toppled %) of the ablation a training config describes."""
    surface = training_config["env"]["sampling"]["reach_target_on_surface"]
    balance = "object_balance" not in training_config["disabled_constraint_groups"]
    return PAPER_TABLE_I[(surface, balance)]


class ConstraintObserver:
    """Counts, per world and constraint group, the first-episode steps with any column violated (> 0)."""

    def __init__(self, env: PushEnv):
        self.env = env
        self.violated = torch.zeros(env.num_envs, len(env.constraint_groups), dtype=torch.long, device=env.device)

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        self.violated += self.env.violated_groups_t & in_episode[:, None]

    @staticmethod
    def percent_of_time(violated_steps: np.ndarray, length: np.ndarray) -> dict[str, float]:
        """Table II: per constraint group, the share of each episode's steps with the group violated [%],
        averaged over episodes; ``violated_steps`` (episodes, groups) counts, ``length`` (episodes,) steps."""
        violation = 100.0 * (violated_steps / length[:, None]).mean(axis=0)
        return {name: float(v) for (name, _), v in zip(CONSTRAINT_GROUPS, violation)}


def table_rates(episodes: FirstEpisodes, violated_steps: np.ndarray) -> dict:
    """Tables I and II of ``episodes``: success and toppled rate [% of episodes] and, per constraint group, the time
    it is violated [% of an episode, mean over episodes]; ``violated_steps`` (episodes, groups) as
    :class:`ConstraintObserver` counts them. Beside them the rate of episodes ended by the robot falling (ours: the
    paper's tracked base rarely does, a legged robot may)."""
    return {"success_rate": percent(episodes.success), "toppled_rate": percent(episodes.toppled),
            "fallen_rate": percent(episodes.fallen),
            "constraint_violation_percent": ConstraintObserver.percent_of_time(violated_steps, episodes.length)}


def first_episode_rates(env: PushEnv, policy: Policy) -> dict:
    """:func:`table_rates` of every world's first episode in ``env``, as ``eval.json`` reports them, and how the
    episodes end (``outcome_percent``: at the goal with the rotation off, rotation right away from the goal, ...; as
    in ``eval.json``'s ``goal_error``)."""
    constraints = ConstraintObserver(env)
    goal_errors = GoalErrorObserver(env, env.num_envs)
    episodes = run_first_episodes(env, policy, [constraints, goal_errors])
    rewards = env.cfg.rewards
    outcome = GoalErrorObserver.summary([goal_errors], episodes, rewards.success_distance,
                                        math.radians(rewards.success_angle_deg))["outcome_percent"]
    return {**table_rates(episodes, constraints.violated.cpu().numpy()), "outcome_percent": outcome}
