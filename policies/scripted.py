"""A hand-written pushing controller that reads the true state: the feasibility baseline and the expert
that :mod:`dynpush.policies.imitation` distils into a policy.

Per world, from the true poses (world frame, m, rad) it commands the push environment with the policy's
own 11 actions (6D base command and 5 arm joints about their defaults):

1. **Approach**: walk to a stance behind the object on the line from the goal through the object, facing
   the goal. A base that is not yet behind the object walks around it along a circle ``clearance`` from its
   surface, with the arm pulled in (``carry_arm_action``) so that turning near the object does not sweep
   the arm through it.
2. **Push** toward the goal at ``push_speed`` with the end-effector low on the object's rear face
   (``push_arm_action``, ``push_height``: the end-effector about 0.18 m above the floor, so that the
   push does not tip narrow objects on high-friction floors; pitching the base further down lowers it
   but brings the elbow onto the object). The push is steered on the measured
   end-effector position, not the base's: under load the arm deflects by up to ~0.25 m. The base's
   sideways velocity and yaw rate keep the end-effector on the contact point as the object turns. The
   contact is on the line of push through the object's centre of mass (read from the task: the
   randomised offset reaches a quarter of the object's size), shifted sideways by ``yaw_gain`` per
   radian of yaw error (within ``max_offset`` of the face). A push that misses the centre of mass
   turns the object, so the yaw is steered toward the goal's while the object moves. An object that tilts
   by more than ``tilt_limit`` is released (the base backs off at ``back_off_speed``) until it settles.
3. **Turn**: within ``turn_radius`` of the goal with the yaw still off, push along the robot's heading
   at the largest offset, slowly, which turns the object more than it moves it.
4. **Release**: at the goal (position and yaw within ``0.6`` of the success tolerances) back away.

The controller has no memory: its action is a function of the current state, so that a memoryless
policy can imitate it. The object's dimensions, shape and centre of mass are read from the task
(privileged inputs no policy observes), unless ``object_size`` is set: the controller then assumes every
object is a cuboid of that edge with its centre of mass at its centre, and acts only on what the policy
observes too (object and end-effector poses, goal), so that a student can imitate it exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from dynpush.runtime.frames import tilt_angle
from dynpush.sim.config import ConfigError, check_positive

from .env_probe import EnvProbe, yaw_of


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-pi, pi)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@dataclass
class ScriptedPusherConfig:
    """Gains and geometry of :class:`ScriptedPusher` (ours: tuned on the training distribution)."""

    push_speed: float = 0.65  # m/s while in contact, far from the goal (slower within 0.35 m)
    approach_speed: float = 1.0  # m/s
    clearance: float = 0.9  # m between the base path and the object's surface while going around it
    # Arm actions of the push pose (SH_ROT, SH_FLE, EL_FLE, FA_ROT, WRIST_1, in units of the action
    # scale): shoulder forward, wrist down. With the base at push_height and push_pitch the end-effector is
    # ~0.18 m above the floor and ee_ahead in front of the base origin (measured in the environment).
    push_arm_action: tuple[float, ...] = (0.0, 0.2, -0.8, 0.0, 0.6)
    # Arm actions while walking: the end-effector pulled in (the elbow command stays inside its limit), so
    # that turning near the object does not sweep the arm through it.
    carry_arm_action: tuple[float, ...] = (0.0, -1.0, 1.6, 0.0, 0.0)
    push_height: float = 0.42  # m, base height command while pushing
    push_pitch: float = 0.05  # rad, base pitch command while pushing (nose down)
    ee_ahead: float = 0.86  # m
    yaw_gain: float = 1.0  # m of contact offset per rad of yaw error
    max_offset: float = 0.6  # share of the face's half width the contact may be shifted
    turn_radius: float = 0.08  # m: closer than this to the goal, only the yaw is corrected
    turn_speed: float = 0.3  # m/s
    align_tolerance: float = 0.4  # rad between the base heading and the push direction while pushing
    line_tolerance: float = 0.25  # m between the end-effector and the contact point across the push
    face_share: float = 0.9  # share of the face's half width the end-effector may be off its centre while pushing
    engage_distance: float = 0.45  # m: the push starts with the end-effector this close behind the contact
    slip_margin: float = 0.3  # m the end-effector may be pressed past the contact point (arm deflection)
    lateral_gain: float = 4.0  # 1/s: base velocity across the push per m of end-effector offset
    lateral_yaw_gain: float = 2.0  # rad/s of base yaw rate per m of end-effector offset across the push
    around_step: float = 0.6  # rad of arc the walk around the object aims ahead of the base
    behind_margin: float = 0.5  # m the base origin must be behind the object's rear face to walk straight to the push stance
    tilt_limit: float = 0.1  # rad of object tilt (its z axis from the world's) above which a push backs off
    back_off_speed: float = 0.3  # m/s
    object_size: float | None = None  # m: None reads the true size, shape and centre of mass; else a nominal cuboid edge
    # Share of each arm joint's velocity limit that the arm action may move at per control step, in (0, 1]: the
    # expert then keeps the arm action-rate constraint, which its jumps between the carry and push poses violate
    # (a student cloned from them inherits that, and CaT-PPO then trades success for smoother arm motion).
    # None: the jumps (the teacher of the shipped policy).
    arm_rate_share: float | None = None

    def validate(self) -> None:
        """Raises a ConfigError naming the first field outside its allowed range."""
        speeds = ("push_speed", "approach_speed", "turn_speed", "back_off_speed")
        shares = ("max_offset", "face_share")
        for field in fields(self):
            name, value = field.name, getattr(self, field.name)
            if name in ("push_arm_action", "carry_arm_action"):
                if len(value) != 5 or not np.all(np.isfinite(value)):
                    raise ConfigError(f"scripted.{name} must be 5 finite arm actions, got {value!r}")
            elif name == "object_size":
                check_object_size(f"scripted.{name}", value)
            elif name in speeds and not 0.0 < value <= 1.0:
                raise ConfigError(f"scripted.{name} must be in (0, 1] m/s (the base command's forward limit), got {value!r}")
            elif name == "arm_rate_share":
                if value is not None and not 0.0 < value <= 1.0:
                    raise ConfigError(f"scripted.{name} must be None or in (0, 1] (a share of the arm joints' velocity"
                                      f" limits), got {value!r}")
            elif name in shares and not 0.0 < value <= 1.0:
                raise ConfigError(f"scripted.{name} must be in (0, 1] (a share of the face's half width), got {value!r}")
            elif name == "push_pitch":
                if not np.isfinite(value):
                    raise ConfigError(f"scripted.{name} must be a finite angle [rad], got {value!r}")
            else:
                check_positive(f"scripted.{name}", value, allow_zero=True)


def check_object_size(name: str, size: float | None) -> None:
    """Raises a ConfigError naming ``name`` unless ``size`` is None or a nominal object edge in (0, 2] m."""
    if size is not None and not 0.0 < size <= 2.0:
        raise ConfigError(f"{name} must be None or in (0, 2] m, got {size!r}")


class ScriptedPusher:
    """The controller of the module docstring for all worlds of a PushEnv, called once per step like a policy."""

    def __init__(self, env, cfg: ScriptedPusherConfig | None = None):
        self.env, self.cfg, self.probe = env, cfg or ScriptedPusherConfig(), EnvProbe(env)
        self.cfg.validate()
        self.base_command = env.action_mapping.base  # the 6D command's default and its actions
        rewards = env.cfg.rewards
        self.done_distance = 0.6 * rewards.success_distance
        self.done_angle = 0.6 * np.radians(rewards.success_angle_deg)
        # Largest change of each arm action per step that keeps the action-rate constraint
        # (arm_scale * |a_t - a_{t-1}| / control_dt <= velocity limit, kernels/push/constraints.py) with the share's
        # margin.
        velocity_limit = env.scene.robot.arm_velocity_limit[: env.num_actions - 6]
        self.max_arm_step = (None if self.cfg.arm_rate_share is None else
                             self.cfg.arm_rate_share * velocity_limit * env.cfg.control_dt / env.cfg.actions.arm_scale)

    def _object_geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per world: the object's full side lengths (n, 3) [m], shape (n,) (0 cuboid, 1 cylinder) and centre of
        mass in its frame (n, 3) [m]; the task's, or with a nominal ``object_size`` a centred cuboid of that edge."""
        task, n = self.env.task, self.env.num_envs
        if self.cfg.object_size is None:
            return task.object_dims.numpy(), task.object_shape.numpy(), task.object_com_o.numpy()
        return np.full((n, 3), self.cfg.object_size), np.zeros(n, dtype=int), np.zeros((n, 3))

    def _half_extent(self, direction: np.ndarray, object_yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centre-to-surface distance of the object along ``direction`` (unit, world xy) and the half width
        of the face it meets, across ``direction`` [m]."""
        dims, shape, _ = self._object_geometry()
        c, s = np.cos(object_yaw), np.sin(object_yaw)
        local_x = np.abs(c * direction[:, 0] + s * direction[:, 1])
        local_y = np.abs(-s * direction[:, 0] + c * direction[:, 1])
        x_face = local_x * dims[:, 1] >= local_y * dims[:, 0]  # the ray leaves through an x face
        depth = np.where(x_face, 0.5 * dims[:, 0] / np.maximum(local_x, 1e-6), 0.5 * dims[:, 1] / np.maximum(local_y, 1e-6))
        width = np.where(x_face, 0.5 * dims[:, 1], 0.5 * dims[:, 0])
        cylinder = shape == 1
        return np.where(cylinder, 0.5 * dims[:, 0], depth), np.where(cylinder, 0.5 * dims[:, 0], width)

    def _com_across(self, side_dir: np.ndarray, object_yaw: np.ndarray) -> np.ndarray:
        """Offset [m] of the object's centre of mass from its frame origin along ``side_dir`` (unit, world xy)."""
        com_o = self._object_geometry()[2][:, :2]
        c, s = np.cos(object_yaw), np.sin(object_yaw)
        com_w = np.stack([c * com_o[:, 0] - s * com_o[:, 1], s * com_o[:, 0] + c * com_o[:, 1]], axis=1)
        return (com_w * side_dir).sum(1)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Actions of every world from the true state (``observations`` unused: a policy's call signature)."""
        cfg = self.cfg
        base, obj = self.probe.base(), self.probe.object()
        p_base, yaw_base = base[:, :2], yaw_of(base[:, 3:])
        p_obj, yaw_obj = obj[:, :2], yaw_of(obj[:, 3:])
        p_ee = self.probe.ee_position()[:, :2]
        to_goal = self.env.task.goal_pos.numpy()[:, :2] - p_obj
        yaw_error = wrap(yaw_of(self.env.task.goal_quat.numpy()) - yaw_obj)
        distance = np.linalg.norm(to_goal, axis=1)
        turning = distance < cfg.turn_radius
        heading_dir = np.stack([np.cos(yaw_base), np.sin(yaw_base)], axis=1)
        push_dir = np.where(turning[:, None], heading_dir, to_goal / np.maximum(distance[:, None], 1e-6))
        side_dir = np.stack([-push_dir[:, 1], push_dir[:, 0]], axis=1)  # push_dir turned +90 deg
        depth, half_width = self._half_extent(-push_dir, yaw_obj)
        # A contact offset s along side_dir from the line through the centre of mass turns the object by
        # -s x push force: steer with s ~ -yaw error (the push through the centre of mass goes straight).
        com_lateral = self._com_across(side_dir, yaw_obj)
        max_offset = cfg.max_offset * half_width
        offset = np.clip(com_lateral - cfg.yaw_gain * yaw_error, -max_offset, max_offset)
        offset = np.where(turning, -np.sign(yaw_error) * max_offset, offset)
        contact = p_obj - push_dir * depth[:, None] + side_dir * offset[:, None]
        heading = np.arctan2(push_dir[:, 1], push_dir[:, 0])
        heading_error = wrap(heading - yaw_base)
        # Push while the end-effector is near the contact point (behind it, or pressed into the face), the base
        # faces along the push and stands behind the object: the end-effector's own position absorbs the arm's
        # deflection under load.
        ee_along, ee_lateral = ((p_ee - contact) * push_dir).sum(1), ((p_ee - contact) * side_dir).sum(1)
        base_along = ((p_base - p_obj) * push_dir).sum(1)  # < -depth: behind the object
        on_face = np.abs(offset + ee_lateral) < cfg.face_share * half_width
        pushing = ((np.abs(heading_error) < cfg.align_tolerance) & (np.abs(ee_lateral) < cfg.line_tolerance) & on_face
                   & (ee_along > -cfg.engage_distance) & (ee_along < cfg.slip_margin) & (base_along < -depth - 0.2))
        speed = np.where(turning, cfg.turn_speed, np.minimum(cfg.push_speed, cfg.turn_speed + distance))  # slow near the goal
        push_velocity = push_dir * speed[:, None] - side_dir * (cfg.lateral_gain * ee_lateral)[:, None]
        tilted = tilt_angle(obj[:, 3:]) > cfg.tilt_limit
        push_velocity = np.where(tilted[:, None], -cfg.back_off_speed * push_dir, push_velocity)
        # Otherwise walk to the stance behind the contact, around the object if the base is not behind it.
        stand = contact - push_dir * cfg.ee_ahead
        behind = stand - 0.3 * push_dir
        # Walking around: along the circle of ``radius`` about the object, toward the bearing behind it, at most
        # ``around_step`` of arc ahead of the base's own bearing (a straight line would cut through the object).
        radius = np.maximum(depth, half_width) + cfg.clearance
        bearing = np.arctan2(p_base[:, 1] - p_obj[:, 1], p_base[:, 0] - p_obj[:, 0])
        bearing_step = np.clip(wrap(heading + np.pi - bearing), -cfg.around_step, cfg.around_step)
        around = p_obj + radius[:, None] * np.stack([np.cos(bearing + bearing_step), np.sin(bearing + bearing_step)], axis=1)
        go_around = (base_along > -depth - cfg.behind_margin) & ~pushing
        target = np.where(go_around[:, None], around, behind)
        walk_velocity = 2.0 * (target - p_base)
        walk_speed = np.linalg.norm(walk_velocity, axis=1, keepdims=True)
        walk_velocity *= np.minimum(1.0, cfg.approach_speed / np.maximum(walk_speed, 1e-9))
        velocity = np.where(pushing[:, None], push_velocity, walk_velocity)  # world frame
        c, s = np.cos(yaw_base), np.sin(yaw_base)
        vx = np.clip(c * velocity[:, 0] + s * velocity[:, 1], -1.0, 1.0)
        vy = np.clip(-s * velocity[:, 0] + c * velocity[:, 1], -0.5, 0.5)
        # While pushing, turning the base also swings the end-effector (ee_ahead in front) across the push.
        yaw_rate = np.clip(2.5 * heading_error - np.where(pushing, cfg.lateral_yaw_gain * ee_lateral, 0.0), -1.0, 1.0)
        done = (distance < self.done_distance) & (np.abs(yaw_error) < self.done_angle)
        vx, vy, yaw_rate = np.where(done, -0.3, vx), np.where(done, 0.0, vy), np.where(done, 0.0, yaw_rate)
        low = ~go_around | done  # the push pose, except while walking around the object
        pitch = np.where(low, cfg.push_pitch, self.base_command.default[4])
        height = np.where(low, cfg.push_height, self.base_command.default[5])
        command = np.stack([vx, vy, yaw_rate, 0 * vx, pitch, height], axis=1)
        actions = np.zeros((self.env.num_envs, self.env.num_actions), dtype=np.float32)
        actions[:, :6] = self.base_command.actions(command)
        arm = np.where(low[:, None], np.asarray(cfg.push_arm_action), np.asarray(cfg.carry_arm_action))
        if self.max_arm_step is not None:  # toward the pose from the arm actions the environment executed last
            previous = self.env.task.actions.numpy()[:, 6:]
            arm = previous + np.clip(arm - previous, -self.max_arm_step, self.max_arm_step)
        actions[:, 6:] = arm
        return actions
