"""Goal curricula for training (allowed levers of the CPU budget; the task itself is unchanged).

Episodes are drawn as in the paper, but the goal asks for only ``d`` of the drawn yaw change
(``PushEnv.set_goal_difficulty``: goal yaw ``yaw_object + d * dyaw``; the goal position is the drawn
one). Scaling the goal *distance* as well was tried and fails: at small distances a robot that never
touches the object succeeds often, so the policy learns to stay away.
After every iteration the difficulty rises by ``step`` when the success rate of the episodes that
ended during it exceeds ``promote_above``, and falls by ``step`` below ``demote_below``. Evaluation
and export never use it: an environment starts at difficulty 1.

Near-goal starts (a start-state or "reverse" curriculum, Florensa et al. 2017): a share of the training resets
draws the goal next to the object's start with the yaw off by a drawn angle (``PushEnv.set_near_goal_starts``),
where the shipped policy fails most (it ends 39 % of its episodes at the goal with the rotation off). Everything
else is drawn as in the paper. An environment starts with share 0, so evaluation and export never use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dynpush.sim.config import ConfigError


@dataclass
class GoalCurriculumConfig:
    enabled: bool = False
    initial: float = 0.0  # the goal keeps the object's start yaw: push to a position first
    step: float = 0.05
    promote_above: float = 0.3
    demote_below: float = 0.1

    def validate(self, prefix: str = "curriculum") -> None:
        for name in ("initial", "step", "promote_above", "demote_below"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"{prefix}.{name} must lie in [0, 1], got {getattr(self, name)!r}")
        if self.demote_below > self.promote_above:
            raise ConfigError(f"{prefix}.demote_below must be <= {prefix}.promote_above")

    def next_difficulty(self, difficulty: float, success_rate: float | None) -> float:
        """The difficulty for the next iteration; unchanged when no episode ended."""
        if success_rate is None:
            return difficulty
        if success_rate > self.promote_above:
            return min(1.0, difficulty + self.step)
        if success_rate < self.demote_below:
            return max(self.initial, difficulty - self.step)
        return difficulty


@dataclass
class NearGoalStartConfig:
    """Share and spread of the training resets that start near the goal; the defaults are ours, not the paper's
    (its curriculum grows the start states from the goal; we draw them from a fixed band around it)."""

    share: float = 0.0  # fraction of resets drawn near the goal; 0: off, the paper's resets exactly
    goal_radius: float = 0.1  # [m] max distance of the goal from the object's start (the success radius)
    max_yaw: float = 0.6  # [rad] max |goal yaw - object yaw|: the "near goal" set the shipped policy solves in 63 %

    def validate(self, prefix: str = "near_goal_starts") -> None:
        for name, high in (("share", 1.0), ("goal_radius", 2.0), ("max_yaw", math.pi)):
            if not 0.0 <= getattr(self, name) <= high:
                raise ConfigError(f"{prefix}.{name} must lie in [0, {high:g}], got {getattr(self, name)!r}")
