"""Evaluation during training (``TrainConfig.eval_interval``): the current actor on the paper's task, every
``eval_interval`` iterations, appended to the run's ``evaluations.jsonl``.

The training episodes measure a noisy policy on the run's own task (which a run may narrow, e.g. nearer goals) while
it changes; this evaluation measures the deterministic mean of the actor on the paper's distribution, one episode per
world as ``dynpush eval`` does (:func:`~dynpush.policies.tables.first_episode_rates`, the same episode loop and
figures). Every evaluation of a run starts the same episodes (``eval_seed``), so that two of them differ by the
policy only. Each line of ``evaluations.jsonl``::

    {"iteration": K, "world_steps": ..., "training_hours": ..., "episodes": N,
     "success_rate": %, "toppled_rate": %, "fallen_rate": %, "constraint_violation_percent": {group: %},
     "outcome_percent": {"success": %, "toppled": %, "robot_fell": %, "at_goal_rotation_off": %, ...}}

``iteration`` K: the actor after K iterations; ``world_steps``: the CaT-PPO world-steps of those K iterations (all
processes); ``training_hours``: the training wall-clock of those iterations, summed over all launches of the run
(:func:`~dynpush.policies.progress.wall_clock_hours`, the learning curve's axis).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING

from tqdm import tqdm

from dynpush.sim.config import PushEnvConfig, SamplingConfig

from .episodes import ActorPolicy
from .progress import EVALUATIONS, read_progress, wall_clock_hours
from .tables import first_episode_rates

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel

    from .train import TrainConfig


def evaluation_env_config(cfg: TrainConfig) -> PushEnvConfig:
    """The run's environment on the paper's task: PushEnvConfig's default sampling, ``eval_episodes`` worlds whose
    first episodes start together, seed ``eval_seed``."""
    return dataclasses.replace(cfg.env, num_envs=cfg.eval_episodes, seed=cfg.eval_seed,
                               randomize_first_episode_length=False, sampling=SamplingConfig()).validate()


def training_hours(run_dir: Path, iterations: int) -> float:
    """Training wall-clock [h] of a run's first ``iterations`` iterations, over all its launches (``progress.jsonl``)."""
    if not (Path(run_dir) / "progress.jsonl").exists():
        return 0.0
    records = [r for r in read_progress(run_dir) if r["iteration"] < iterations]
    return float(wall_clock_hours(records)[-1]) if records else 0.0


class PeriodicEvaluation:
    """Evaluates the actor of a run every ``cfg.eval_interval`` iterations (see the module docstring); rank 0 only."""

    def __init__(self, cfg: TrainConfig, run_dir: Path):
        from dynpush.sim.envs import make_push_env

        self.interval = cfg.eval_interval
        self.run_dir = Path(run_dir)
        self.world_steps_per_iteration = cfg.num_steps_per_env * cfg.env.num_envs  # all processes
        self.env = make_push_env(evaluation_env_config(cfg))
        self.start = self.env.state_dict()  # restored before every evaluation: the same episodes each time

    def due(self, iteration: int) -> bool:
        """Whether the actor is evaluated before ``iteration``."""
        return iteration % self.interval == 0

    def __call__(self, iteration: int, actor: MLPModel) -> dict:
        """Evaluates ``actor`` (after ``iteration`` iterations) and appends its line to ``evaluations.jsonl``."""
        self.env.load_state_dict(self.start)
        rates = first_episode_rates(self.env, ActorPolicy(actor))  # draws no torch random numbers: training's stay
        record = {"iteration": iteration, "world_steps": iteration * self.world_steps_per_iteration,
                  "training_hours": training_hours(self.run_dir, iteration), "episodes": self.env.num_envs, **rates}
        with open(self.run_dir / EVALUATIONS, "a") as f:
            f.write(json.dumps(record) + "\n")
        worst = max(rates["constraint_violation_percent"].items(), key=lambda item: item[1])
        tqdm.write(f"evaluation before it {iteration}: success {rates['success_rate']:.1f} %, toppled"
                   f" {rates['toppled_rate']:.1f} %, at the goal with the rotation off"
                   f" {rates['outcome_percent']['at_goal_rotation_off']:.1f} %, most violated {worst[0]} {worst[1]:.2f} %"
                   " of the time")
        return record

