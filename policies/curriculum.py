"""Training curricula (allowed levers of the CPU budget; the task itself is unchanged).

Goal difficulty: episodes are drawn as in the paper, but the goal asks for only ``d`` of the drawn yaw change
(``PushEnv.set_goal_difficulty``: goal yaw ``yaw_object + d * dyaw``; the goal position is the drawn
one), and, with ``initial_success_angle_deg`` set, success tolerates a rotation from ``initial_success_angle_deg`` at 0
down to the paper's 10 deg at 1 (``PushEnv.set_success_angle``): at level 0 a goal asking for no turn still needs
the object pushed without turning it more than 10 deg, which a policy learning from scratch rarely manages
(docs/ppo_fine_tuning.md). Scaling the goal *distance* toward 0 was tried and fails: at small distances a robot
that never touches the object succeeds often, so the policy learns to stay away.

Goal distance: the goals are first drawn from a band away from the success radius (``initial_radius``, 0.4-0.6 m,
the sanity task's 0.5 m), which widens to the configured ``sampling.goal_radius`` (``PushEnv.set_goal_radius_range``):
no goal of the band is reached by staying away, and far goals are what slows learning most after the walk round the
object (docs/ppo_fine_tuning.md).

Object mass: the objects' masses are drawn from ``[m_low, m_high(d)]`` with ``m_high`` rising from ``initial_max`` to
the configured ``randomization.mass`` maximum (``PushEnv.set_object_mass_range``). Our arm's PD joints yield
under a heavy object: pushing one takes the legs, the base or a folded arm, and each such push is a collision that
CaT terminates; on the sanity task (``benchmarks/ppo_sanity.py``) with the paper's collision ``p_max`` of 1.0 a policy
learning from scratch on 1-10 kg objects learns to keep away, while on 1-2 kg objects it learns to push
(docs/ppo_fine_tuning.md).

The levels follow the training success rate (:class:`SuccessGatedLevel`): once at least ``curriculum_window_episodes``
training episodes have ended (over all processes) since the levels last moved, a level rises by ``step`` when their
success rate exceeds ``promote_above`` and falls by ``step`` below ``demote_below``. Evaluation and export never
use them: an environment starts with the paper's goals, starts and success angle and the configured masses.

Near-goal starts (a start-state or "reverse" curriculum, Florensa et al. 2017): a share of the training resets
draws the goal next to the object's start with the yaw off by a drawn angle (``PushEnv.set_near_goal_starts``),
where the shipped policy fails most (many of its episodes end at the goal with the rotation off). Everything
else is drawn as in the paper. An environment starts with share 0, so evaluation and export never use it.

Starts behind the object: a share of the training resets puts the robot behind the object as seen from the goal,
facing it (``PushEnv.set_behind_starts``), where a push toward the goal is one walk forward, as in the sanity task
(a goal 0.5 m ahead, learnt from scratch within a few hundred iterations); from the paper's starts, anywhere around
the object and facing anywhere, a policy must first learn to walk round it. On the sanity task a goal at a random
bearing instead of straight ahead is what slows learning most (docs/ppo_fine_tuning.md), so the spread of these
starts can follow the training success (a :class:`SuccessGatedLevel` too): from the aligned geometry to any
bearing and heading, which at full spread and share 1 are the paper's starts again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dynpush.sim.config import ConfigError


@dataclass
class SuccessGatedLevel:
    """A training difficulty in ``[initial, 1]`` (1: the paper's task) that follows the training success rate."""

    enabled: bool = False
    initial: float = 0.0
    step: float = 0.05
    promote_above: float = 0.3
    demote_below: float = 0.1

    def validate(self, prefix: str) -> None:
        for name in ("initial", "step", "promote_above", "demote_below"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"{prefix}.{name} must lie in [0, 1], got {getattr(self, name)!r}")
        if self.demote_below > self.promote_above:
            raise ConfigError(f"{prefix}.demote_below must be <= {prefix}.promote_above")

    def progress(self, difficulty: float) -> float:
        """Where ``difficulty`` lies between ``initial`` (0) and the paper's task (1)."""
        return 1.0 if self.initial >= 1.0 else (difficulty - self.initial) / (1.0 - self.initial)

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
class GoalCurriculumConfig(SuccessGatedLevel):
    """At difficulty ``d`` the goal asks for ``d`` of the drawn yaw change; ``initial`` 0: push to a position first.
    With ``initial_success_angle_deg`` the success angle also moves from it at 0 to the configured one at 1."""

    initial_success_angle_deg: float | None = None  # [deg] None: the configured success angle at every level

    def validate(self, prefix: str = "curriculum", configured_angle_deg: float = 10.0) -> None:
        super().validate(prefix)
        angle = self.initial_success_angle_deg
        if angle is not None and not configured_angle_deg <= angle <= 180.0:
            raise ConfigError(f"{prefix}.initial_success_angle_deg must lie in [env.rewards.success_angle_deg ="
                              f" {configured_angle_deg:g}, 180], got {angle!r}")

    def success_angle_deg(self, difficulty: float, configured_angle_deg: float) -> float:
        """The success angle [deg] at ``difficulty`` (the configured one without ``initial_success_angle_deg``)."""
        if self.initial_success_angle_deg is None:
            return configured_angle_deg
        return self.initial_success_angle_deg + difficulty * (configured_angle_deg - self.initial_success_angle_deg)


@dataclass
class ObjectMassCurriculumConfig(SuccessGatedLevel):
    """At difficulty ``d`` the object's mass is drawn from ``[m_low, initial_max + d (m_high - initial_max)]``, with
    ``(m_low, m_high)`` the configured ``randomization.mass``. The defaults are ours, not the paper's."""

    initial_max: float = 2.0  # [kg] the heaviest object at difficulty 0
    step: float = 0.025  # 0.2 kg of the 8 kg between 2 and 10 kg
    promote_above: float = 0.2
    demote_below: float = 0.05

    def validate(self, prefix: str = "mass_curriculum", configured: tuple[float, float] = (1.0, 10.0)) -> None:
        super().validate(prefix)
        if self.enabled and not configured[0] <= self.initial_max <= configured[1]:
            raise ConfigError(f"{prefix}.initial_max must lie in env.randomization.mass {tuple(configured)} kg,"
                              f" got {self.initial_max!r}")

    def mass_range(self, difficulty: float, configured: tuple[float, float]) -> tuple[float, float]:
        """The (low, high) [kg] object masses at ``difficulty``, within the ``configured`` range."""
        return configured[0], self.initial_max + difficulty * (configured[1] - self.initial_max)


@dataclass
class GoalDistanceCurriculumConfig(SuccessGatedLevel):
    """At difficulty ``d`` the goal lies ``lo(d)``-``hi(d)`` from the object's start (uniform by area), each bound
    moving linearly from ``initial_radius`` at 0 to the configured ``sampling.goal_radius`` at 1. Ours, not the
    paper's."""

    initial_radius: tuple[float, float] = (0.4, 0.6)  # [m] the band at difficulty 0, beyond the 0.1 m success radius

    def validate(self, prefix: str = "distance_curriculum", configured: tuple[float, float] = (0.0, 2.0)) -> None:
        super().validate(prefix)
        low, high = self.initial_radius
        if not low <= high or self.enabled and not configured[0] <= low <= high <= configured[1]:
            raise ConfigError(f"{prefix}.initial_radius must be (low, high) with low <= high within"
                              f" env.sampling.goal_radius {tuple(configured)} m, got {self.initial_radius!r}")

    def radius_range(self, difficulty: float, configured: tuple[float, float]) -> tuple[float, float]:
        """The (low, high) [m] goal distances at ``difficulty``, within the ``configured`` range."""
        (low0, high0), (low1, high1) = self.initial_radius, configured
        return low0 + difficulty * (low1 - low0), high0 + difficulty * (high1 - high0)


@dataclass
class NearGoalStartConfig:
    """Share and spread of the training resets that start near the goal; the defaults are ours, not the paper's
    (its curriculum grows the start states from the goal; we draw them from a fixed band around it)."""

    share: float = 0.0  # fraction of resets drawn near the goal; 0: off, the paper's resets exactly
    goal_radius: float = 0.1  # [m] max distance of the goal from the object's start (the success radius)
    max_yaw: float = 0.6  # [rad] max |goal yaw - object yaw|: the "near goal" set of docs/ppo_fine_tuning.md

    def validate(self, prefix: str = "near_goal_starts") -> None:
        for name, high in (("share", 1.0), ("goal_radius", 2.0), ("max_yaw", math.pi)):
            if not 0.0 <= getattr(self, name) <= high:
                raise ConfigError(f"{prefix}.{name} must lie in [0, {high:g}], got {getattr(self, name)!r}")


@dataclass
class BehindStartConfig(SuccessGatedLevel):
    """Share and spread of the training resets that start behind the object; the defaults are ours, not the paper's.

    With ``enabled`` the spread follows the training success: at difficulty ``d`` it is ``spread + d (pi - spread)``,
    so difficulty 1 draws any bearing and heading (with share 1: the paper's starts)."""

    share: float = 0.0  # fraction of resets that start behind the object; 0: off, the paper's resets exactly
    spread: float = 0.5  # [rad] max deviation of the robot's bearing and heading from the aligned ones (difficulty 0)
    step: float = 0.02  # 0.05 rad of spread per promotion from 0.5 rad: widened slowly, the task changes with it
    promote_above: float = 0.4
    demote_below: float = 0.2

    def validate(self, prefix: str = "behind_starts") -> None:
        super().validate(prefix)
        for name, high in (("share", 1.0), ("spread", math.pi)):
            if not 0.0 <= getattr(self, name) <= high:
                raise ConfigError(f"{prefix}.{name} must lie in [0, {high:g}], got {getattr(self, name)!r}")
        if self.enabled and self.share == 0.0:
            raise ConfigError(f"{prefix}.enabled widens the spread of starts behind the object: set {prefix}.share > 0")

    def spread_at(self, difficulty: float) -> float:
        """The spread [rad] of the starts at ``difficulty`` (``spread`` at 0, pi at 1)."""
        return self.spread + difficulty * (math.pi - self.spread)
