"""Goal curriculum for training (an allowed lever of the CPU budget; the task itself is unchanged).

Episodes are drawn as in the paper, but the goal asks for only ``d`` of the drawn yaw change
(``PushEnv.set_goal_difficulty``: goal yaw ``yaw_object + d * dyaw``; the goal position is the drawn
one). Scaling the goal *distance* as well was tried and fails: at small distances a robot that never
touches the object succeeds often, so the policy learns to stay away.
After every iteration the difficulty rises by ``step`` when the success rate of the episodes that
ended during it exceeds ``promote_above``, and falls by ``step`` below ``demote_below``. Evaluation
and export never use it: an environment starts at difficulty 1.
"""

from __future__ import annotations

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
