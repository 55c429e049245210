"""Evaluation of an exported push policy (``policy.onnx``, run by onnxruntime) in the push environment.

``dynpush eval policy.onnx`` reproduces the paper's simulation tables (section IV-A/B):

- **Table I**: success rate and toppled-object rate over one episode per world. All worlds start
  together (``PushEnv.reset()`` without randomized episode steps) and are stepped for exactly one
  episode length; a world that ends early is auto-reset by the environment and its later steps are
  masked, so every world contributes exactly its first episode. Success is the success flag at the
  episode's last step (as in training logs); ``reached_rate`` counts episodes that met the tolerance at
  any step.
- **Table II**: per constraint group, the percentage of an episode's steps with any column of the group
  violated (value > 0), averaged over episodes.
- time to success (the first step with the success flag, successful episodes only) and the breakdown
  by object shape.
- ``while_touching``: the end-effector's vertical speed and the object's horizontal acceleration while
  they touch (:class:`ContactMotionObserver`), which tell a smooth push from a shaking one, and the base's
  commanded and achieved forward speed, which tell whether the base keeps its speed against the object,
  also per bin of the force that slides the object (``base_speed_by_sliding_force``).
- ``rewards``: the discounted return-to-go the policy collects (training's gamma) and the mean reward terms,
  beside its success: whether what PPO maximises and what the tables count agree (:class:`RewardObserver`).

The environment is the one the policy was trained in: its config comes from the ``training_config``
of the policy's ONNX metadata, changed only by ``--num-envs``, ``--noise/--no-noise`` and ``--set
env.field=value`` overrides.

Ablations of Table I are separate trainings, then the same evaluation::

    dynpush train --name no_surface --set env.sampling.reach_target_on_surface=False
    dynpush train --name no_balance --set "disabled_constraint_groups=('object_balance',)"
    dynpush train --name no_surface_no_balance --set env.sampling.reach_target_on_surface=False \
        "disabled_constraint_groups=('object_balance',)"
    dynpush export runs/no_balance && dynpush eval runs/no_balance/policy.onnx

``eval.json`` names the paper row that matches the policy's training config.

``dynpush eval policy.onnx --footprints`` is the study of the paper's Fig. "EE height boxplot"
(IV-D): cuboids with six square xy-footprints across the training range, fixed height, mass, CoM and
friction, observation noise off, N successful episodes per footprint; the end-effector height (world z,
m) while it touches the object.

Frames and units: world frame Z-up (every environment has its origin at the world origin), SI units,
quaternions (x, y, z, w).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
import torch
from tqdm import tqdm

from dynpush.kernels.constraints import CONSTRAINT_GROUPS
from dynpush.kernels.observations import POLICY_TERMS, PRIVILEGED_TERMS
from dynpush.runtime.frames import rotation_angle
from dynpush.runtime.observation import NUM_ARM_JOINTS, quat_to_matrix
from dynpush.sim.config import ConfigError, LeggedModeConfig, PushEnvConfig
from dynpush.sim.episode import SHAPES
from dynpush.sim.envs import make_push_env
from dynpush.sim.push_env import PushEnv

from .export import OnnxPolicy

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel

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


def critic_column(name: str) -> int:
    """First column of a term in the critic observation (``PushEnv.critic_obs_t``)."""
    column = 0
    for term, size in (*POLICY_TERMS, *PRIVILEGED_TERMS):
        if term == name:
            return column
        column += size
    raise KeyError(f"no critic observation term {name!r}")


EE_CONTACT_COLUMN = critic_column("ee_object_contact")  # 54: 1 while the end-effector touches the object


# ---------------------------------------------------------------------------------------------- environment
def env_config_for(policy: OnnxPolicy, num_envs: int, noise: bool | None = None, device: str = "cpu",
                   seed: int = 0, overrides: tuple[str, ...] | list[str] = (), legs_from_outside: bool = False) -> PushEnvConfig:
    """The environment a policy was trained in (from its metadata), for evaluation.

    ``noise`` switches the actor observation noise (None keeps the training value); ``overrides`` are
    ``env.field=value`` strings applied last. Episodes start synchronized (no randomized first length).
    Legged mode needs ``env.legged.locomotion_policy`` unless ``legs_from_outside`` (sim-to-sim: the runtime
    runs the locomotion policy and sends the leg targets).
    """
    from .train import TrainConfig
    from .training import apply_overrides

    cfg = TrainConfig.from_dict(policy.contract.training_config)
    if not cfg.env.legged.enabled:  # trained on the tracked base: legged mode, if asked for, has today's settings
        cfg.env.legged = LeggedModeConfig()
    cfg.env.num_envs = num_envs
    cfg.env.device = device
    cfg.env.seed = seed
    cfg.env.randomize_first_episode_length = False
    if noise is not None:
        cfg.env.noise.enabled = noise
    for item in overrides:
        if not item.startswith("env."):
            raise ConfigError(f"evaluation overrides address the environment (env.field=value), got {item!r}")
    apply_overrides(cfg, list(overrides))
    if cfg.env.legged.enabled and not cfg.env.legged.locomotion_policy and not legs_from_outside:
        raise ConfigError("env.legged.locomotion_policy must name a locomotion.onnx in legged mode (without one the legs"
                          " hold their default targets), e.g. the shipped dynpush/shipped/locomotion/locomotion.onnx")
    return cfg.env.validate()


def yaw_of(quat: np.ndarray) -> np.ndarray:
    """Yaw [rad] of quaternions (..., 4) stored (x, y, z, w)."""
    x, y, z, w = np.moveaxis(quat, -1, 0)
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class EnvProbe:
    """World-frame poses of every world's base, object and end-effector, read from the environment's state.

    Reads the Newton state ``state_0`` (after a control step it holds the step's final state) through a
    zero-copy view; positions in m, quaternions (x, y, z, w).
    """

    def __init__(self, env: PushEnv):
        import warp as wp

        self.env = env
        self.body_q = wp.to_torch(env.state_0.body_q)  # (bodies, 7): position, quaternion
        self.joint_q = wp.to_torch(env.state_0.joint_q)
        scene = env.scene
        self.base_body = torch.as_tensor(scene.base_body, dtype=torch.long, device=self.body_q.device)
        self.object_body = torch.as_tensor(scene.object_body, dtype=torch.long, device=self.body_q.device)
        self.ee_body = torch.as_tensor(scene.ee_body, dtype=torch.long, device=self.body_q.device)
        arm_q_index = np.asarray(scene.arm_q_start)[:, None] + np.arange(NUM_ARM_JOINTS)
        self.arm_q_index = torch.as_tensor(arm_q_index, dtype=torch.long, device=self.body_q.device)
        self.ee_offset = np.asarray(scene.ee_offset, dtype=np.float64)  # in the EE body frame
        self.gravity = float(np.linalg.norm(scene.model.gravity.numpy()[0]))  # [m/s^2]

    def _pose(self, bodies: torch.Tensor) -> np.ndarray:
        return self.body_q[bodies].cpu().numpy().astype(np.float64)

    def base(self) -> np.ndarray:
        """(n, 7) base pose: position (m), quaternion (x, y, z, w)."""
        return self._pose(self.base_body)

    def object(self) -> np.ndarray:
        """(n, 7) object frame pose (the centroid): position (m), quaternion (x, y, z, w)."""
        return self._pose(self.object_body)

    def ee_position(self) -> np.ndarray:
        """(n, 3) end-effector point (world, m)."""
        pose = self._pose(self.ee_body)
        return pose[:, :3] + quat_to_matrix(pose[:, 3:]) @ self.ee_offset

    def base_command(self) -> np.ndarray:
        """(n, 6) the push policy's absolute base command of the last step (vx, vy [m/s] heading frame, yaw rate
        [rad/s], roll, pitch [rad], height [m])."""
        return self.env.task.base_command.numpy().astype(np.float64)

    def object_sliding_force(self) -> np.ndarray:
        """(n,) mu m g [N]: the horizontal force that slides the object over the floor (Coulomb; mu the combined
        coefficient, the mean of the object's own and the floor's as Newton combines them)."""
        friction = 0.5 * (self.env.task.object_friction.numpy() + self.env.scene.ground_friction)
        return friction * self.env.task.object_mass.numpy() * self.gravity

    def arm_q(self) -> np.ndarray:
        """(n, 5) absolute positions [rad] of the 5 controlled arm joints."""
        return self.joint_q[self.arm_q_index].cpu().numpy().astype(np.float64)

    def ee_in_object(self) -> np.ndarray:
        """(n, 3) end-effector point in the object frame (m)."""
        pose = self.object()
        return np.einsum("nji,nj->ni", quat_to_matrix(pose[:, 3:]), self.ee_position() - pose[:, :3])


# ---------------------------------------------------------------------------------------------- rollout
Policy = Callable[[np.ndarray], np.ndarray]
"""Actions [B, 11] (float32) for actor observations [B, 54] (float32): an :class:`OnnxPolicy` or an :class:`ActorPolicy`."""


class ActorPolicy:
    """The deterministic mean of an in-memory actor (rsl_rl ``MLPModel``), so that training evaluates its current actor
    as ``dynpush eval`` evaluates an exported one: a copy of its observation normaliser and MLP (rsl_rl's export
    module, the graph ``dynpush export`` writes to ONNX), on the CPU, which later updates of the actor leave alone."""

    def __init__(self, actor: MLPModel):
        self.module = actor.as_jit().to("cpu").eval()

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return self.module(torch.from_numpy(obs)).numpy()


class StepObserver(Protocol):
    """Receives every control step of a first-episode rollout."""

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        """Called after ``env.step`` number ``step`` (0-based).

        ``in_episode``: worlds whose first episode contained this step; values the step computes before
        its auto-reset (``constraints_t``, ``success_t``) are theirs. ``continuing``: the subset whose first
        episode goes on, whose post-step state and observations (``critic_obs_t``, :class:`EnvProbe`) are
        still that episode's.
        """


@dataclass
class FirstEpisodes:
    """Outcome of every world's first episode (arrays over worlds)."""

    length: np.ndarray  # control steps in the episode
    success: np.ndarray  # bool: success flag at the last step
    toppled: np.ndarray  # bool: ended by the object toppling
    first_success_step: np.ndarray  # 1-based step of the first success flag, 0 if never
    shape: np.ndarray  # 0 cuboid, 1 cylinder

    @staticmethod
    def concatenate(parts: list[FirstEpisodes], count: int) -> FirstEpisodes:
        """The first ``count`` worlds of several rounds."""
        return FirstEpisodes(**{f.name: np.concatenate([getattr(p, f.name) for p in parts])[:count]
                                for f in dataclasses.fields(FirstEpisodes)})


def run_first_episodes(env: PushEnv, policy: Policy, observers: list[StepObserver] = (),
                       progress: tqdm | None = None, started: bool = False) -> FirstEpisodes:
    """Resets all worlds together and runs the policy for one episode length; see the module docstring.

    ``started``: the caller has just called ``env.reset(randomize_episode_step=False)`` itself (to read
    the episodes before creating its observers).
    """
    n = env.num_envs
    if not started:
        env.reset(randomize_episode_step=False)
    obs = env.get_observations()["policy"]
    shape = env.task.object_shape.numpy().copy()
    in_episode = torch.ones(n, dtype=torch.bool, device=env.device)
    length = torch.zeros(n, dtype=torch.long, device=env.device)
    first_success = torch.zeros(n, dtype=torch.long, device=env.device)
    success = torch.zeros(n, dtype=torch.bool, device=env.device)
    toppled = torch.zeros(n, dtype=torch.bool, device=env.device)
    for step in range(env.max_episode_length):
        actions = policy(obs.cpu().numpy())
        obs = env.step(torch.from_numpy(actions).to(env.device))[0]["policy"]
        ended = in_episode & (env.reset_t != 0)
        continuing = in_episode & ~ended
        length += in_episode
        reached = in_episode & (env.success_t != 0) & (first_success == 0)
        first_success[reached] = step + 1
        success[ended] = env.episode_success_t[ended] == 1
        toppled[ended] = env.episode_toppled_t[ended] == 1
        for observer in observers:
            observer.observe(step, in_episode, continuing)
        in_episode = continuing
        if progress is not None:
            progress.update(n)
    if bool(in_episode.any()):
        raise RuntimeError("a world's first episode outlasted the episode length (environment time-out broken)")
    return FirstEpisodes(length=length.cpu().numpy(), success=success.cpu().numpy(), toppled=toppled.cpu().numpy(),
                         first_success_step=first_success.cpu().numpy(), shape=shape)


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


def first_episode_rates(env: PushEnv, policy: Policy) -> dict:
    """Tables I and II of every world's first episode in ``env``, as ``eval.json`` reports them: success and toppled
    rate [% of episodes] and, per constraint group, the time it is violated [% of an episode, mean over episodes]."""
    constraints = ConstraintObserver(env)
    episodes = run_first_episodes(env, policy, [constraints])
    return {"success_rate": _percent(episodes.success), "toppled_rate": _percent(episodes.toppled),
            "constraint_violation_percent": ConstraintObserver.percent_of_time(constraints.violated.cpu().numpy(),
                                                                               episodes.length)}


class ContactHeightObserver:
    """Collects, per world, the end-effector height (world z, m) at every step it touches the object."""

    def __init__(self, env: PushEnv):
        self.env = env
        self.probe = EnvProbe(env)
        self.heights: list[list[float]] = [[] for _ in range(env.num_envs)]

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        touching = (continuing & (self.env.critic_obs_t[:, EE_CONTACT_COLUMN] > 0.5)).cpu().numpy()
        if touching.any():
            z = self.probe.ee_position()[:, 2]
            for w in np.flatnonzero(touching):
                self.heights[w].append(float(z[w]))


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


class GoalErrorObserver:
    """Per world: the object's distance [m] and rotation angle [rad] to its goal (the success test's quantities) at
    the first step, what the goal asks, and at the last step before the first episode ends (one control step
    before its end: at the ending step the world is already reset)."""

    def __init__(self, env: PushEnv, count: int):
        self.env, self.probe, self.count = env, EnvProbe(env), count
        self.asked_distance = self.asked_angle = self.final_distance = self.final_angle = None

    def _to_goal(self) -> tuple[np.ndarray, np.ndarray]:
        obj, task = self.probe.object(), self.env.task
        distance = np.linalg.norm(task.goal_pos.numpy() - obj[:, :3], axis=1)
        return distance, rotation_angle(obj[:, 3:], task.goal_quat.numpy())

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        distance, angle = self._to_goal()
        if self.asked_distance is None:
            self.asked_distance, self.asked_angle = distance, angle
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
        """How the episodes end (percent of all episodes): success, toppled, at the goal with the rotation off,
        rotation right but away from the goal, both off; the rotation error of those at the goal, and the
        success rate per bin of the rotation and the distance the goal asks (``GOAL_ANGLE_BINS_DEG``,
        ``GOAL_DISTANCE_BINS_M``)."""
        def pooled(name: str) -> np.ndarray:
            return GoalErrorObserver.pooled(observers, name)

        distance, angle = pooled("final_distance"), pooled("final_angle")
        failed = ~episodes.success & ~episodes.toppled
        near, aligned = distance <= success_distance, angle <= success_angle
        at_goal_rotation_off = failed & near & ~aligned

        def by_bins(asked: np.ndarray, edges: tuple[float, ...], scale: float) -> list[dict]:
            rows = []
            for low, high in zip(edges[:-1], edges[1:]):
                mask = (asked >= low / scale) & (asked < high / scale)
                rows.append({"from": low, "to": high, "episodes": int(mask.sum()), "success_rate": _percent(episodes.success[mask])})
            return rows

        return {
            "outcome_percent": {"success": _percent(episodes.success), "toppled": _percent(episodes.toppled),
                                "at_goal_rotation_off": _percent(at_goal_rotation_off),
                                "rotation_right_away_from_goal": _percent(failed & ~near & aligned),
                                "away_from_goal_rotation_off": _percent(failed & ~near & ~aligned)},
            "rotation_error_deg_at_goal_rotation_off": _stats(np.degrees(angle[at_goal_rotation_off])),
            "success_by_goal_rotation_deg": by_bins(pooled("asked_angle"), GOAL_ANGLE_BINS_DEG, 180.0 / math.pi),
            "success_by_goal_distance_m": by_bins(pooled("asked_distance"), GOAL_DISTANCE_BINS_M, 1.0),
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
        return {"gamma": gamma, "return_to_go": _stats(np.concatenate([o.returns_to_go(gamma) for o in observers])),
                "term_means_per_step": {name: float(v) for name, v in zip(env.reward_names, terms.mean(axis=0))},
                "weights": {name: float(w) for name, w in zip(env.reward_names, env.task.reward_weights.numpy())}}


GOAL_ANGLE_BINS_DEG = (0.0, 30.0, 90.0, 150.0, 180.01)  # the rotation a goal asks of the object (ours)
GOAL_DISTANCE_BINS_M = (0.0, 0.5, 1.0, 1.5, 2.01)  # the goal's distance from the object's start (III-B: r <= 2 m)


def _percent(mask: np.ndarray) -> float | None:
    """Percentage of True entries; None (JSON null) for no entries."""
    return 100.0 * float(mask.mean()) if mask.size else None


def _stats(values: np.ndarray) -> dict[str, float | int]:
    if values.size == 0:
        return {"count": 0}
    q = np.percentile(values, [10, 25, 50, 75, 90])
    return {"count": int(values.size), "mean": float(values.mean()), "p10": float(q[0]), "p25": float(q[1]),
            "median": float(q[2]), "p75": float(q[3]), "p90": float(q[4]), "min": float(values.min()),
            "max": float(values.max())}


# ---------------------------------------------------------------------------------------------- Tables I and II
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
        by_shape[name] = {"episodes": int(mask.sum()), "success_rate": _percent(episodes.success[mask]),
                          "toppled_rate": _percent(episodes.toppled[mask]),
                          "time_to_success_s": _stats(episodes.first_success_step[mask & episodes.success] * dt)}
    paper_name, paper_success, paper_toppled = paper_table_i_row(policy.contract.training_config)
    gamma = policy.contract.training_config["ppo"]["gamma"]  # the discount it was trained with
    result = {
        "policy": str(policy_path),
        "episodes": cfg.episodes,
        "success_rate": _percent(episodes.success),
        "toppled_rate": _percent(episodes.toppled),
        "reached_rate": _percent(episodes.first_success_step > 0),
        "constraint_violation_percent": ConstraintObserver.percent_of_time(violated_steps, episodes.length),
        "time_to_success_s": _stats(time_to_success),
        "episode_length_s": _stats(episodes.length * dt),
        "while_touching": {key: _stats(ContactMotionObserver.pooled(motions, name)) for key, name in (
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


def plot_eval(result: dict, time_to_success: np.ndarray, final: tuple[np.ndarray, np.ndarray], episodes: FirstEpisodes,
              path: Path) -> None:
    """Table II beside the paper's values, Table I (success/toppled) beside the paper's, time to success, where the
    episodes end (``final``: distance [m] and rotation error [deg] to the goal) and success by the rotation asked."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    fig = Figure(figsize=(24, 4.8), layout="constrained")
    ax_constraints, ax_rates, ax_time, ax_final, ax_asked = fig.subplots(1, 5, width_ratios=(2.2, 1.2, 1.2, 1.2, 1.0))
    names = list(result["constraint_violation_percent"])
    x = np.arange(len(names))
    ours = [result["constraint_violation_percent"][n] for n in names]
    paper = [result["paper"]["constraint_violation_percent"][n] for n in names]
    for offset, values, label, color in ((-0.2, ours, "this policy", None), (0.2, paper, "paper (Table II)", "tab:gray")):
        drawn = ax_constraints.bar(x + offset, values, 0.4, label=label, color=color)
        ax_constraints.bar_label(drawn, fmt="%.3g", fontsize=6)
    ax_constraints.set_xticks(x, [n.replace("_", "\n") for n in names], fontsize=8)
    ax_constraints.set_yscale("symlog", linthresh=0.01)
    ax_constraints.set_ylabel("time violated [% of episode]")
    ax_constraints.set_title("Constraint violation (Table II)")
    ax_constraints.legend()

    groups = ["success", "toppled"]
    bars = [(f"this policy ({result['episodes']})", result, None)]
    bars += [(f"{shape} ({stats['episodes']})", stats, None) for shape, stats in result["by_shape"].items()]
    bars += [("paper: " + result["paper"]["table_I_row"], result["paper"], "tab:gray")]
    width = 0.8 / len(bars)
    x = np.arange(len(groups))
    for index, (label, source, color) in enumerate(bars):
        values = [np.nan if source[k] is None else source[k] for k in ("success_rate", "toppled_rate")]
        drawn = ax_rates.bar(x - 0.4 + width * (index + 0.5), values, width, label=label, color=color)
        ax_rates.bar_label(drawn, fmt="%.1f", fontsize=7)
    ax_rates.set_xticks(x, groups)
    ax_rates.set_ylim(0, 105)
    ax_rates.set_ylabel("rate [%]")
    ax_rates.set_title("Success and toppled objects (Table I)")
    ax_rates.legend(fontsize=7, loc="upper right")

    if time_to_success.size:
        ax_time.hist(time_to_success, bins=30, color="tab:green")
        ax_time.axvline(float(np.median(time_to_success)), color="k", ls="--", label="median")
        ax_time.legend()
    else:
        ax_time.text(0.5, 0.5, "no successful episode", ha="center", va="center", transform=ax_time.transAxes)
    ax_time.set_xlabel("time to success [s]")
    ax_time.set_ylabel("episodes")
    ax_time.set_title("Time to success")

    distance, angle = final
    success_distance = result["config"]["env"]["rewards"]["success_distance"]
    success_angle = result["config"]["env"]["rewards"]["success_angle_deg"]
    failed = ~episodes.success & ~episodes.toppled
    for mask, label, color in ((episodes.success, "success", "tab:green"), (failed, "failed", "tab:red"),
                               (episodes.toppled, "toppled", "k")):
        ax_final.scatter(np.maximum(distance[mask], 1e-3), angle[mask], s=4, alpha=0.5, color=color,
                         label=f"{label} ({int(mask.sum())})")
    ax_final.add_patch(Rectangle((1e-3, 0.0), success_distance - 1e-3, success_angle, fill=False, ls="--", color="k"))
    ax_final.set_xscale("log")
    ax_final.set_xlabel("object-goal distance at the end [m]")
    ax_final.set_ylabel("rotation error at the end [deg]")
    ax_final.set_title("Where episodes end (box: success tolerance)")
    ax_final.legend(fontsize=7, markerscale=3)

    bins = result["goal_error"]["success_by_goal_rotation_deg"]
    labels = [f"{b['from']:.0f}-{min(b['to'], 180.0):.0f}" for b in bins]
    drawn = ax_asked.bar(labels, [np.nan if b["success_rate"] is None else b["success_rate"] for b in bins], color="tab:green")
    ax_asked.bar_label(drawn, labels=[f"{b['episodes']}" for b in bins], fontsize=7)
    ax_asked.set_ylim(0, 105)
    ax_asked.set_xlabel("rotation the goal asks [deg]")
    ax_asked.set_ylabel("success [%] (bar label: episodes)")
    ax_asked.set_title("Success by goal rotation")
    noise = "on" if result["config"]["env"]["noise"]["enabled"] else "off"
    fig.suptitle(f"{result['policy']}: {result['episodes']} episodes of {result['config']['env']['episode_length_s']:g} s,"
                 f" observation noise {noise}")
    fig.savefig(path, dpi=110)


# ---------------------------------------------------------------------------------------------- footprints
@dataclass
class FootprintConfig:
    """The object-footprint study (paper IV-D, Fig. "EE height boxplot").

    Square xy-footprints equally spaced across the training range of ``randomization.size_x/size_y``;
    height, mass, CoM and friction fixed at mid-range values; cuboids only; no observation noise.
    """

    sides: tuple[float, ...] = (0.25, 0.35, 0.45, 0.55, 0.65, 0.75)  # m: six footprints over [0.25, 0.75]
    height: float = 0.7  # m (mid-range of [0.4, 1.0])
    mass: float = 5.0  # kg
    friction: float = 0.8  # combined object-floor coefficient
    successful_episodes: int = 1000  # per footprint (IV-D)
    max_rounds: int = 50  # per footprint; stops a policy that rarely succeeds
    num_envs: int = 512
    device: str = "cpu"
    seed: int = 0
    overrides: tuple[str, ...] = ()  # env.field=value, applied before the study's own settings

    def validate(self) -> FootprintConfig:
        if not self.sides or not all(0.05 <= s <= 2.0 for s in self.sides):
            raise ConfigError(f"footprints.sides must be lengths in [0.05, 2.0] m, got {self.sides!r}")
        for name in ("successful_episodes", "max_rounds", "num_envs"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(f"footprints.{name} must be an integer >= 1, got {getattr(self, name)!r}")
        return self

    def env_overrides(self, side: float) -> list[str]:
        """``env.*`` overrides that pin the object to one footprint."""
        fixed = {"size_x": (side, side), "size_y": (side, side), "size_z": (self.height, self.height),
                 "mass": (self.mass, self.mass), "friction": (self.friction, self.friction),
                 "com_fraction_x": (0.0, 0.0), "com_fraction_y": (0.0, 0.0), "com_fraction_z": (0.0, 0.0),
                 "cylinder_probability": 0.0}
        return [*self.overrides, *(f"env.randomization.{k}={v!r}" for k, v in fixed.items()), "env.noise.enabled=False"]


def footprint_study(policy_path: Path, cfg: FootprintConfig, out_dir: Path) -> dict:
    """Runs the footprint study; writes ``footprints.json`` and ``footprints.png`` into ``out_dir``."""
    cfg.validate()
    policy = OnnxPolicy(policy_path, batched=True)
    rows, heights = [], []
    for side in cfg.sides:
        env = make_push_env(env_config_for(policy, cfg.num_envs, None, cfg.device, cfg.seed, cfg.env_overrides(side)))
        samples: list[float] = []
        attempted = successful = 0
        with tqdm(total=cfg.successful_episodes, desc=f"footprint {side:.2f} m", unit="success") as bar:
            for _ in range(cfg.max_rounds):
                observer = ContactHeightObserver(env)
                episodes = run_first_episodes(env, policy, [observer])
                attempted += env.num_envs
                for w in np.flatnonzero(episodes.success)[: cfg.successful_episodes - successful]:
                    samples.extend(observer.heights[w])
                    successful += 1
                    bar.update(1)
                if successful >= cfg.successful_episodes:
                    break
        values = np.asarray(samples)
        heights.append(values)
        rows.append({"side_m": side, "episodes": attempted, "successful_episodes": successful,
                     "ee_height_in_contact_m": _stats(values)})
    result = {"policy": str(policy_path), "footprints": rows,
              "config": dataclasses.asdict(cfg) | {"training_config_sha256": policy.contract.training_config_sha256}}
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "footprints.json").write_text(json.dumps(result, indent=2, allow_nan=False))
    plot_footprints(result, heights, out_dir / "footprints.png")
    return result


def plot_footprints(result: dict, heights: list[np.ndarray], path: Path) -> None:
    """Box plot of the EE height in contact per footprint (the paper's Fig. "EE height boxplot")."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.subplots()
    rows = result["footprints"]
    labels = [f"{r['side_m']:.2f}x{r['side_m']:.2f}\n({r['successful_episodes']} ep.)" for r in rows]
    ax.boxplot([h if h.size else [np.nan] for h in heights], tick_labels=labels, showfliers=False)
    ax.axhline(result["config"]["height"], color="gray", ls=":", label="object top")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_xlabel("object xy-footprint [m] (successful episodes)")
    ax.set_ylabel("EE height in contact, world z [m]")
    ax.set_title(f"EE height while pushing, object height {result['config']['height']} m")
    ax.grid(axis="y", alpha=0.3)
    fig.savefig(path, dpi=110)
