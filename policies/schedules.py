"""Training-iteration schedules: CaT ``p_max`` curricula, the push task's reach-reward weight, the imitation
weight of expert-regularised runs and the locomotion task's disturbance ramp.

The numbers are those of Dadiotis et al. (ICRA 2025), Table "Rewards and constraints" and Sec. "Rewards &
constraints". The paper trains for 20000 iterations; a shorter run compresses every schedule by its length
(``ScheduleConfig.scale_with_run_length``) so that, e.g., a 2000-iteration run ramps ``p_max`` over its first 1200
iterations. Runs at least as long as the paper's keep the paper's absolute iteration counts.

Both schedules are pure functions of ``(iteration, total_iterations)``;
:class:`~dynpush.policies.runner.CaTOnPolicyRunner` applies them at the start of every learning iteration.
"""

from __future__ import annotations

import torch
from collections.abc import Sequence
from dataclasses import dataclass, field

from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS
from dynpush.sim.config import ConfigError, RewardConfig


def _paper_p_max() -> dict[str, tuple[float, float]]:
    # Table "Rewards and constraints", column p_i^max: (initial, final); collision and object balance are fixed.
    return {
        "base_command": (0.01, 0.2),
        "arm_command": (0.05, 0.9),
        "arm_action_rate": (0.0, 0.05),
        "arm_joint_position": (0.05, 0.9),
        "arm_joint_velocity": (0.05, 0.9),
        "arm_joint_torque": (0.0, 0.015),
        "leg_joint_torque": (0.0, 0.01),
        "collision": (1.0, 1.0),
        "object_balance": (0.25, 0.25),
    }


@dataclass
class ConstraintCurriculumConfig:
    """Linear ``p_max`` curriculum per constraint group."""

    p_max: dict[str, tuple[float, float]] = field(default_factory=_paper_p_max)
    """Group name -> (initial, final) maximum termination probability (Table "Rewards and constraints")."""

    ramp_iterations: int = 12000
    """Iterations over which ``p_max`` rises from initial to final, in paper iterations (Table: 0 -> 12e3)."""

    follow_curricula: bool = False
    """True (ours): ``p_max`` rises with the training curricula's mean level instead of the iteration count, from
    initial at their easiest levels to final at the paper's task, and falls back when they are demoted. From scratch,
    CaT at the paper's initial values keeps the robot from pushing at all (docs/ppo_fine_tuning.md)."""


@dataclass
class ReachWeightConfig:
    """Step schedule of the reach-reward weight ``w2``."""

    weight: float = field(default_factory=lambda: RewardConfig().reach_weight)
    """Initial weight ``w2``: a training run's ``env.rewards.reach_weight`` (``TrainConfig.runner_cfg`` passes it)."""

    divisor: float = 4.0
    """``w2`` is divided by this factor after the switch (Sec. "Rewards & constraints")."""

    switch_iteration: int = 1500
    """Iteration of the switch, in paper iterations (Sec. "Rewards & constraints")."""


@dataclass
class DisturbanceRampConfig:
    """Linear ramp of the locomotion task's random arm motions and base pushes (ours): none before
    ``start_iteration``, their full size from ``end_iteration`` on. With them from the start, PPO learned to
    stand instead of walking; without them it walked (docs/experiments/legged_fidelity.md)."""

    start_iteration: int = 0
    end_iteration: int = 0

    def validate(self, prefix: str = "disturbance_ramp") -> None:
        if not 0 <= self.start_iteration <= self.end_iteration:
            raise ConfigError(f"{prefix} must be (start, end) iterations with 0 <= start <= end,"
                              f" got ({self.start_iteration}, {self.end_iteration})")


@dataclass
class ScheduleConfig:
    """All iteration schedules of a training run."""

    constraints: ConstraintCurriculumConfig = field(default_factory=ConstraintCurriculumConfig)
    """CaT ``p_max`` curricula."""

    reach: ReachWeightConfig | None = field(default_factory=ReachWeightConfig)
    """Reach-reward weight schedule; None for a task without a reach reward (locomotion)."""

    disturbance: DisturbanceRampConfig | None = None
    """Disturbance ramp; None for a task without random disturbances to ramp (push)."""

    paper_iterations: int = 20000
    """Length of the paper's training run (Sec. "RL goal pushing environment": 20000 iterations)."""

    scale_with_run_length: bool = True
    """Compress schedules of runs shorter than ``paper_iterations`` by ``total_iterations / paper_iterations``.

    False keeps the paper's absolute iteration counts whatever the run length."""

    @classmethod
    def from_dict(cls, cfg: dict) -> ScheduleConfig:
        """Build from a nested dict (e.g. the ``"schedule"`` entry of a runner config); missing keys keep defaults."""
        cfg = dict(cfg)
        constraints = dict(cfg.pop("constraints", {}))
        if "p_max" in constraints:
            constraints["p_max"] = {name: (float(a), float(b)) for name, (a, b) in constraints["p_max"].items()}
        reach = cfg.pop("reach", {})
        disturbance = cfg.pop("disturbance", None)
        return cls(
            constraints=ConstraintCurriculumConfig(**constraints),
            reach=None if reach is None else ReachWeightConfig(**reach),
            disturbance=None if disturbance is None else DisturbanceRampConfig(**disturbance),
            **cfg,
        )


def scaled_iterations(paper_iterations: float, total_iterations: int, cfg: ScheduleConfig) -> float:
    """Map an iteration count of the paper's run onto a run of ``total_iterations``."""
    if not cfg.scale_with_run_length or total_iterations >= cfg.paper_iterations:
        return float(paper_iterations)
    return paper_iterations * total_iterations / cfg.paper_iterations


def p_max_at(
    iteration: int,
    total_iterations: int,
    cfg: ScheduleConfig | None = None,
    groups: Sequence[tuple[str, int]] = CONSTRAINT_GROUPS,
) -> torch.Tensor:
    """Per-column maximum termination probability at ``iteration`` of a run of ``total_iterations``.

    Args:
        iteration: Learning iteration (0-based).
        total_iterations: Length of the run in iterations.
        cfg: Schedules; paper defaults when None.
        groups: Constraint groups ``(name, dim)`` in column order.

    Returns:
        Float tensor of shape ``[sum(dims)]``.
    """
    cfg = cfg or ScheduleConfig()
    ramp = scaled_iterations(cfg.constraints.ramp_iterations, total_iterations, cfg)
    return p_max_at_progress(iteration / ramp if ramp > 0 else 1.0, cfg, groups)


def p_max_at_progress(
    progress: float, cfg: ScheduleConfig | None = None, groups: Sequence[tuple[str, int]] = CONSTRAINT_GROUPS,
) -> torch.Tensor:
    """Per-column maximum termination probability at ``progress`` (clipped to [0, 1]) from each group's initial to its
    final value; the shape is that of :func:`p_max_at`."""
    cfg = cfg or ScheduleConfig()
    progress = min(max(progress, 0.0), 1.0)
    values = []
    for name, dim in groups:
        initial, final = cfg.constraints.p_max[name]
        values += [initial + (final - initial) * progress] * dim
    return torch.tensor(values, dtype=torch.float)


def reach_weight_at(iteration: int, total_iterations: int, cfg: ScheduleConfig | None = None) -> float:
    """Reach-reward weight ``w2`` at ``iteration`` of a run of ``total_iterations``."""
    cfg = cfg or ScheduleConfig()
    switch = scaled_iterations(cfg.reach.switch_iteration, total_iterations, cfg)
    return cfg.reach.weight / cfg.reach.divisor if iteration >= switch else cfg.reach.weight


def imitation_weight_at(iteration: int, total_iterations: int, weight: tuple[float, float]) -> float:
    """Weight of the expert-imitation loss term (:mod:`dynpush.policies.expert_regularization`, ours) at
    ``iteration``: linear from ``weight[0]`` at the first iteration to ``weight[1]`` at the last of the run."""
    progress = min(max(iteration / max(total_iterations - 1, 1), 0.0), 1.0)
    return weight[0] + (weight[1] - weight[0]) * progress


def disturbance_scale_at(iteration: int, cfg: DisturbanceRampConfig) -> float:
    """Share in [0, 1] of the full random arm motions and base pushes at ``iteration`` (absolute iterations)."""
    if iteration >= cfg.end_iteration:
        return 1.0
    if iteration < cfg.start_iteration:
        return 0.0
    return (iteration - cfg.start_iteration) / (cfg.end_iteration - cfg.start_iteration)
