"""``dynpush eval policy.onnx``: an exported push policy (run by onnxruntime) on the paper's simulation tables
(section IV-A/B), one first episode per world (:mod:`dynpush.policies.episodes`), written to ``eval.json`` and
``eval.png``:

- Tables I and II (:mod:`dynpush.policies.tables`): success and toppled-object rate, and per constraint group the
  time it is violated, beside the paper's row for the policy's training config; ``reached_rate`` counts episodes
  that met the tolerance at any step;
- time to success (the first step with the success flag, successful episodes only) and the breakdown by object
  shape;
- ``while_touching``, ``goal_error`` and ``rewards`` (:mod:`dynpush.policies.observers`).

The environment is the one the policy was trained in: its config comes from the ``training_config`` of the
policy's ONNX metadata (:func:`~dynpush.policies.trained_env.env_config_for`), changed only by ``--num-envs``,
``--noise/--no-noise`` and ``--set env.field=value`` overrides.

Ablations of Table I are separate trainings, then the same evaluation::

    dynpush train --name no_surface --set env.sampling.reach_target_on_surface=False
    dynpush train --name no_balance --set "disabled_constraint_groups=('object_balance',)"
    dynpush train --name no_surface_no_balance --set env.sampling.reach_target_on_surface=False \
        "disabled_constraint_groups=('object_balance',)"
    dynpush export runs/no_balance && dynpush eval runs/no_balance/policy.onnx

The other studies are commands of their own: ``dynpush scenario`` (goal sequences,
:mod:`dynpush.policies.scenarios`), ``dynpush footprints`` (the footprint study,
:mod:`dynpush.policies.footprints`) and, for a locomotion policy, ``dynpush eval-locomotion``
(:mod:`dynpush.policies.locomotion_eval`).

Frames and units: world frame Z-up (every environment has its origin at the world origin), SI units,
quaternions (x, y, z, w).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dynpush.sim.config import ConfigError
from dynpush.sim.episode import SHAPES
from dynpush.sim.envs import make_push_env

from .episodes import FirstEpisodes, run_first_episodes
from .eval_plot import plot_eval
from .observers import ContactMotionObserver, GoalErrorObserver, RewardObserver
from .onnx_policy import OnnxPolicy
from .sample_stats import describe, percent
from .tables import PAPER_TABLE_II, ConstraintObserver, paper_table_i_row, table_rates
from .trained_env import env_config_for


@dataclass
class EvalConfig:
    """``dynpush eval`` (Tables I and II)."""

    episodes: int = 4096  # IV-A: 4096 environments, a single episode each
    num_envs: int | None = None  # worlds simulated together (default: min(episodes, 1024)); rounds run until done
    noise: bool | None = None  # actor observation noise (None: as in training)
    device: str = "cpu"
    seed: int = 0
    overrides: tuple[str, ...] = ()  # env.field=value

    def validate(self) -> EvalConfig:
        if not isinstance(self.episodes, int) or self.episodes < 1:
            raise ConfigError(f"episodes must be an integer >= 1, got {self.episodes!r}")
        if self.num_envs is not None and (not isinstance(self.num_envs, int) or self.num_envs < 1):
            raise ConfigError(f"num_envs must be an integer >= 1, got {self.num_envs!r}")
        return self

    @property
    def worlds(self) -> int:
        return min(self.episodes, self.num_envs or 1024)


def evaluate(policy_path: Path, cfg: EvalConfig, out_dir: Path) -> dict:
    """Runs ``cfg.episodes`` first episodes and writes ``eval.json`` and ``eval.png`` into ``out_dir``."""
    cfg.validate()
    policy = OnnxPolicy(policy_path, batched=True)
    env_cfg = env_config_for(policy, cfg.worlds, cfg.noise, cfg.device, cfg.seed, cfg.overrides)
    env = make_push_env(env_cfg)
    rounds = math.ceil(cfg.episodes / cfg.worlds)
    parts, violated, motions, rewards, goal_errors = [], [], [], [], []
    start = time.perf_counter()
    world_steps = rounds * cfg.worlds * env.max_episode_length
    with tqdm(total=world_steps, desc="eval", unit="world-step", unit_scale=True) as bar:
        for k in range(rounds):
            constraints = ConstraintObserver(env)
            motions.append(ContactMotionObserver(env, env_cfg.control_dt, cfg.episodes - k * cfg.worlds))
            rewards.append(RewardObserver(env, cfg.episodes - k * cfg.worlds))
            goal_errors.append(GoalErrorObserver(env, min(cfg.worlds, cfg.episodes - k * cfg.worlds)))
            parts.append(run_first_episodes(env, policy, [constraints, motions[-1], rewards[-1], goal_errors[-1]], bar))
            violated.append(constraints.violated.cpu().numpy())
    elapsed = time.perf_counter() - start
    episodes = FirstEpisodes.concatenate(parts, cfg.episodes)
    violated_steps = np.concatenate(violated)[: cfg.episodes]

    dt = env_cfg.control_dt
    time_to_success = episodes.first_success_step[episodes.success] * dt
    by_shape = {}
    for index, name in enumerate(SHAPES):
        mask = episodes.shape == index
        by_shape[name] = {"episodes": int(mask.sum()), "success_rate": percent(episodes.success[mask]),
                          "toppled_rate": percent(episodes.toppled[mask]),
                          "time_to_success_s": describe(episodes.first_success_step[mask & episodes.success] * dt)}
    paper_name, paper_success, paper_toppled = paper_table_i_row(policy.contract.training_config)
    gamma = policy.contract.training_config["ppo"]["gamma"]  # the discount it was trained with
    result = {
        "policy": str(policy_path),
        "episodes": cfg.episodes,
        **table_rates(episodes, violated_steps),
        "reached_rate": percent(episodes.first_success_step > 0),
        "time_to_success_s": describe(time_to_success),
        "episode_length_s": describe(episodes.length * dt),
        "while_touching": {key: describe(ContactMotionObserver.pooled(motions, name)) for key, name in (
            ("ee_vertical_speed_m_s", "ee_vertical_speed"), ("object_horizontal_acceleration_m_s2", "object_acceleration"),
            ("base_commanded_vx_m_s", "base_commanded_vx"), ("base_forward_speed_m_s", "base_forward_speed"),
            ("object_sliding_force_n", "object_sliding_force"))}
        | {"base_speed_by_sliding_force": ContactMotionObserver.base_speed_by_sliding_force(motions)},
        "by_shape": by_shape,
        "goal_error": GoalErrorObserver.summary(goal_errors, episodes, env_cfg.rewards.success_distance,
                                                math.radians(env_cfg.rewards.success_angle_deg)),
        "rewards": RewardObserver.summary(rewards, gamma),
        "paper": {"table_I_row": paper_name, "success_rate": paper_success, "toppled_rate": paper_toppled,
                  "constraint_violation_percent": PAPER_TABLE_II},
        "runtime": {"seconds": elapsed, "world_steps": world_steps, "rounds": rounds, "worlds": cfg.worlds,
                    "seconds_per_1000_world_steps": 1000.0 * elapsed / world_steps},
        "config": {"eval": dataclasses.asdict(cfg), "env": dataclasses.asdict(env_cfg),
                   "training_config_sha256": policy.contract.training_config_sha256},
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "eval.json").write_text(json.dumps(result, indent=2, allow_nan=False))
    final = (GoalErrorObserver.pooled(goal_errors, "final_distance"), np.degrees(GoalErrorObserver.pooled(goal_errors, "final_angle")))
    plot_eval(result, time_to_success, final, episodes, out_dir / "eval.png")
    return result
