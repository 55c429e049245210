"""What ``eval.json`` reports beside Tables I and II, each from a step observer of the first episodes
(:class:`~dynpush.policies.episodes.StepObserver`):

- ``while_touching`` (:class:`ContactMotionObserver`): the end-effector's vertical speed and the object's horizontal
  acceleration while they touch, which tell a smooth push from a shaking one, and the base's commanded and achieved
  forward speed, which tell whether the base keeps its speed against the object, also per bin of the force that
  slides the object;
- ``goal_error`` (:class:`GoalErrorObserver`): how the episodes end, and success by what the goal asks;
- ``rewards`` (:class:`RewardObserver`): the discounted return-to-go the policy collects (training's gamma) and the
  mean reward terms, beside its success: whether what PPO maximises and what the tables count agree.

Frames and units: world frame Z-up, SI units, quaternions (x, y, z, w).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import torch

from dynpush.runtime.frames import rotation_angle

from .env_probe import EE_CONTACT_COLUMN, EnvProbe, yaw_of
from .episodes import FirstEpisodes
from .sample_stats import describe, percent

if TYPE_CHECKING:
    from dynpush.sim.push_env import PushEnv


class ContactMotionObserver:
    """While the end-effector touches the object, by finite differences of the poses over the control step:
    its vertical speed |v_z| [m/s], the object's horizontal acceleration |a_xy| [m/s^2] (world frame), and the
    base's forward speed [m/s] (along its heading at the step's start) beside the forward speed the push policy
    commanded for the step.

    A sample needs the world's episode to have gone on through the two previous steps (three poses of one
    episode). Only the first ``count`` worlds are recorded. On the legged robot the gait shakes the arm, and
    the object takes the shocks; and a base that stalls against the object falls short of its command: these
    figures show both (docs/legged.md)."""

    SAMPLES = ("ee_vertical_speed", "object_acceleration", "base_commanded_vx", "base_forward_speed", "object_sliding_force")
    SLIDING_FORCE_BINS = (0.0, 30.0, 60.0, 90.0, np.inf)  # [N] of mu m g: the task's objects need 4-123 N

    def __init__(self, env: PushEnv, control_dt: float, count: int):
        self.env, self.dt, self.probe = env, control_dt, EnvProbe(env)
        self.recorded = np.arange(env.num_envs) < count
        self.steps_in_episode = np.zeros(env.num_envs, dtype=int)  # consecutive continuing steps
        self.ee_z = self.object_xy = self.object_velocity = self.base_pose = None
        self.samples: dict[str, list[np.ndarray]] = {name: [] for name in self.SAMPLES}

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        going_on = continuing.cpu().numpy()
        self.steps_in_episode = np.where(going_on, self.steps_in_episode + 1, 0)
        ee_z, object_xy, base_pose = self.probe.ee_position()[:, 2], self.probe.object()[:, :2], self.probe.base()
        if self.ee_z is not None:
            object_velocity = (object_xy - self.object_xy) / self.dt
            if self.object_velocity is not None:
                touching = self.env.critic_obs_t[:, EE_CONTACT_COLUMN].cpu().numpy() > 0.5
                sampled = self.recorded & touching & (self.steps_in_episode >= 3)
                heading = yaw_of(self.base_pose[:, 3:])
                forward = np.einsum("ni,ni->n", base_pose[:, :2] - self.base_pose[:, :2],
                                    np.column_stack([np.cos(heading), np.sin(heading)])) / self.dt
                values = {"ee_vertical_speed": np.abs(ee_z - self.ee_z) / self.dt,
                          "object_acceleration": np.linalg.norm(object_velocity - self.object_velocity, axis=1) / self.dt,
                          "base_commanded_vx": self.probe.base_command()[:, 0], "base_forward_speed": forward,
                          "object_sliding_force": self.probe.object_sliding_force()}
                for name, value in values.items():
                    self.samples[name].append(value[sampled])
            self.object_velocity = object_velocity
        self.ee_z, self.object_xy, self.base_pose = ee_z, object_xy, base_pose

    @staticmethod
    def pooled(observers: list[ContactMotionObserver], name: str) -> np.ndarray:
        """The samples ``name`` (one of ``SAMPLES``) of all ``observers`` in one array."""
        return np.concatenate([x for o in observers for x in o.samples[name]] or [[]])

    @classmethod
    def base_speed_by_sliding_force(cls, observers: list[ContactMotionObserver]) -> list[dict]:
        """Per bin of the object's ``mu m g``: the samples' count and the medians of the commanded and the achieved
        forward speed of the base [m/s]. A base that stalls against heavy objects keeps its speed only on light ones."""
        force = cls.pooled(observers, "object_sliding_force")
        commanded, achieved = cls.pooled(observers, "base_commanded_vx"), cls.pooled(observers, "base_forward_speed")
        rows = []
        for low, high in zip(cls.SLIDING_FORCE_BINS[:-1], cls.SLIDING_FORCE_BINS[1:]):
            inside = (force >= low) & (force < high)
            rows.append({"sliding_force_n": [low, None if np.isinf(high) else high], "count": int(inside.sum()),
                         "commanded_vx_median": float(np.median(commanded[inside])) if inside.any() else None,
                         "forward_speed_median": float(np.median(achieved[inside])) if inside.any() else None})
        return rows


GOAL_ANGLE_BINS_DEG = (0.0, 30.0, 90.0, 150.0, 180.01)  # the rotation a goal asks of the object (ours)
GOAL_DISTANCE_BINS_M = (0.0, 0.5, 1.0, 1.5, 2.01)  # the goal's distance from the object's start (III-B: r <= 2 m)
START_SIDE_BINS_DEG = (0.0, 45.0, 90.0, 135.0, 180.01)  # where the robot starts around the object (ours, start_side)


def start_side(base_xy: np.ndarray, object_xy: np.ndarray, goal_xy: np.ndarray) -> np.ndarray:
    """Angle [rad] at the object between the robot base and the side opposite the goal, in the floor plane (world
    frame, (n, 2) positions in m): 0 when the robot starts behind the object as seen from the goal, where one walk
    forward pushes it there, pi when it starts between the object and the goal and must walk round the object
    first. NaN for a goal on the object's start position or a base above it."""
    behind, robot = object_xy - goal_xy, base_xy - object_xy
    norms = np.linalg.norm(behind, axis=1) * np.linalg.norm(robot, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = np.where(norms > 1e-9, np.sum(behind * robot, axis=1) / norms, np.nan)
    return np.arccos(np.clip(cosine, -1.0, 1.0))


class GoalErrorObserver:
    """Per world: the object's distance [m] and rotation angle [rad] to its goal (the success test's quantities) at
    the first step, what the goal asks, and at the last step before the first episode ends (one control step
    before its end: at the ending step the world is already reset); and the robot's :func:`start_side` [rad] at
    the first step."""

    def __init__(self, env: PushEnv, count: int):
        self.env, self.probe, self.count = env, EnvProbe(env), count
        self.asked_distance = self.asked_angle = self.final_distance = self.final_angle = self.start_side = None

    def _to_goal(self, obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        task = self.env.task
        distance = np.linalg.norm(task.goal_pos.numpy() - obj[:, :3], axis=1)
        return distance, rotation_angle(obj[:, 3:], task.goal_quat.numpy())

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        obj = self.probe.object()
        distance, angle = self._to_goal(obj)
        if self.asked_distance is None:
            self.asked_distance, self.asked_angle = distance, angle
            self.start_side = start_side(self.probe.base()[:, :2], obj[:, :2], self.env.task.goal_pos.numpy()[:, :2])
            self.final_distance, self.final_angle = distance.copy(), angle.copy()
        continuing = continuing.cpu().numpy()
        self.final_distance = np.where(continuing, distance, self.final_distance)
        self.final_angle = np.where(continuing, angle, self.final_angle)

    @staticmethod
    def pooled(observers: list[GoalErrorObserver], name: str) -> np.ndarray:
        """``name`` (e.g. ``final_distance``) of every evaluated episode, in episode order."""
        return np.concatenate([getattr(o, name)[: o.count] for o in observers])

    @staticmethod
    def summary(observers: list[GoalErrorObserver], episodes: FirstEpisodes, success_distance: float,
                success_angle: float) -> dict:
        """How the episodes end (percent of all episodes): success, toppled, the robot fallen (the object upright),
        and of the others at the goal with the rotation off, rotation right but away from the goal, both off; the
        rotation error of those at the goal, and the success rate per bin of the rotation and the distance the goal
        asks (``GOAL_ANGLE_BINS_DEG``, ``GOAL_DISTANCE_BINS_M``) and of where the robot starts
        (``START_SIDE_BINS_DEG``)."""
        def pooled(name: str) -> np.ndarray:
            return GoalErrorObserver.pooled(observers, name)

        distance, angle = pooled("final_distance"), pooled("final_angle")
        fell, failed = episodes.fell, episodes.failed
        near, aligned = distance <= success_distance, angle <= success_angle
        at_goal_rotation_off = failed & near & ~aligned

        def by_bins(asked: np.ndarray, edges: tuple[float, ...], scale: float) -> list[dict]:
            rows = []
            for low, high in zip(edges[:-1], edges[1:]):
                mask = (asked >= low / scale) & (asked < high / scale)
                rows.append({"from": low, "to": high, "episodes": int(mask.sum()), "success_rate": percent(episodes.success[mask])})
            return rows

        return {
            "outcome_percent": {"success": percent(episodes.success), "toppled": percent(episodes.toppled),
                                "robot_fell": percent(fell),
                                "at_goal_rotation_off": percent(at_goal_rotation_off),
                                "rotation_right_away_from_goal": percent(failed & ~near & aligned),
                                "away_from_goal_rotation_off": percent(failed & ~near & ~aligned)},
            "rotation_error_deg_at_goal_rotation_off": describe(np.degrees(angle[at_goal_rotation_off])),
            "success_by_goal_rotation_deg": by_bins(pooled("asked_angle"), GOAL_ANGLE_BINS_DEG, 180.0 / math.pi),
            "success_by_goal_distance_m": by_bins(pooled("asked_distance"), GOAL_DISTANCE_BINS_M, 1.0),
            "success_by_start_side_deg": by_bins(pooled("start_side"), START_SIDE_BINS_DEG, 180.0 / math.pi),
        }


class RewardObserver:
    """The reward of every first-episode step (the environment's weighted sum r1..r4 and each raw term).

    ``rewards``: what training maximises, so that a policy's returns can be set beside its success: the mean
    over the episodes' steps of the discounted return-to-go ``G_t = sum_k gamma^k r_{t+k}`` (within the episode;
    an episode's last steps sum fewer rewards, as for every policy) and the mean per step of each term. The weights
    are the evaluated environment's (its config's: training divides the reach weight by 4 after its first 7.5 %)."""

    def __init__(self, env: PushEnv, count: int):
        self.env = env
        self.recorded = np.arange(env.num_envs) < count  # the first ``count`` worlds
        self.steps: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (in_episode, reward, terms) per step

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        self.steps.append((in_episode.cpu().numpy() & self.recorded, self.env.reward_t.cpu().numpy().copy(),
                           self.env.reward_terms_t.cpu().numpy().copy()))

    def returns_to_go(self, gamma: float) -> np.ndarray:
        """``G_t`` of every step of every first episode, pooled [steps]."""
        going, following = [], np.zeros(self.env.num_envs)
        for in_episode, reward, _ in reversed(self.steps):  # a step outside the episode contributes and passes on 0
            following = np.where(in_episode, reward + gamma * following, 0.0)
            going.append(following[in_episode])
        return np.concatenate(going)

    @staticmethod
    def summary(observers: list[RewardObserver], gamma: float) -> dict:
        """The ``rewards`` entry of ``eval.json`` from the observers of all rounds: statistics of ``G_t``, the mean
        per step of each raw term (before its weight) and the weights, pooled over the episodes' steps."""
        env = observers[0].env
        terms = np.concatenate([terms[in_episode] for o in observers for in_episode, _, terms in o.steps])
        return {"gamma": gamma, "return_to_go": describe(np.concatenate([o.returns_to_go(gamma) for o in observers])),
                "term_means_per_step": {name: float(v) for name, v in zip(env.reward_names, terms.mean(axis=0))},
                "weights": {name: float(w) for name, w in zip(env.reward_names, env.task.reward_weights.numpy())}}

