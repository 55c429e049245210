"""A hand-written pushing controller that reads the true state: the feasibility baseline and the expert
that :mod:`dynpush.policies.imitation` distils into a policy.

Per world, from the true poses (world frame, m, rad) it commands the push environment with the policy's
own 11 actions (6D base command and 5 arm joints about their defaults):

1. **Approach**: go around the object (keeping ``clearance`` from its surface) to a point behind it on
   the line from the goal through the object, facing the goal.
2. **Push** toward the goal at ``push_speed`` with the end-effector low on the object's rear face
   (``push_arm_action``, ``push_height``: the end-effector about 0.1 m above the floor, so that the
   push does not tip narrow objects on high-friction floors). The contact is shifted sideways by
   ``yaw_gain`` per radian of yaw error (at most ``max_offset`` of the face): a push that misses the
   centre of mass turns the object, so the object's yaw is steered toward the goal's while it moves.
3. **Turn**: within ``turn_radius`` of the goal with the yaw still off, push along the robot's heading
   at the largest offset, slowly, which turns the object more than it moves it.
4. **Release**: at the goal (position and yaw within ``0.6`` of the success tolerances) back away.

The controller has no memory: its action is a function of the current state, so that a memoryless
policy can imitate it. The object's dimensions and shape are read from the task (a privileged input no
policy observes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-pi, pi)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@dataclass
class ScriptedPusherConfig:
    """Gains and geometry of :class:`ScriptedPusher` (ours: tuned on the training distribution)."""

    push_speed: float = 0.5  # m/s while in contact, far from the goal (slower within 0.35 m)
    approach_speed: float = 0.8  # m/s
    clearance: float = 0.9  # m between the base path and the object's surface while going around it
    # Arm actions of the push pose (SH_ROT, SH_FLE, EL_FLE, FA_ROT, WRIST_1, in units of the action
    # scale): shoulder forward, wrist down. With the base at push_height the end-effector is ~0.1 m
    # above the floor and ee_ahead in front of the base origin (measured in the environment).
    push_arm_action: tuple[float, ...] = (0.0, 0.2, -0.8, 0.0, 0.6)
    push_height: float = 0.42  # m, base height command while pushing
    push_pitch: float = 0.15  # rad, base pitch command while pushing (nose down)
    ee_ahead: float = 0.86  # m
    yaw_gain: float = 0.5  # m of contact offset per rad of yaw error
    max_offset: float = 0.4  # share of the face's half width the contact may be shifted
    turn_radius: float = 0.08  # m: closer than this to the goal, only the yaw is corrected
    turn_speed: float = 0.15  # m/s
    slip_margin: float = 0.3  # m the base may come closer to the object than the push stance
    align_tolerance: float = 0.3  # rad between the base heading and the push direction while pushing
    line_tolerance: float = 0.15  # m between the base and the push line while pushing


class ScriptedPusher:
    """The controller of the module docstring for all worlds of a PushEnv, called once per step like a policy."""

    def __init__(self, env, cfg: ScriptedPusherConfig | None = None):
        from dynpush.policies.evaluate import EnvProbe

        self.env, self.cfg, self.probe = env, cfg or ScriptedPusherConfig(), EnvProbe(env)
        self.base_default = np.asarray(env.cfg.actions.base_default)
        self.base_scale = np.asarray(env.cfg.actions.base_scale)
        rewards = env.cfg.rewards
        self.done_distance = 0.6 * rewards.success_distance
        self.done_angle = 0.6 * np.radians(rewards.success_angle_deg)

    def _half_extent(self, direction: np.ndarray, object_yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centre-to-surface distance of the object along ``direction`` (unit, world xy) and the half width
        of the face it meets, across ``direction`` [m]."""
        dims, shape = self.env.task.object_dims.numpy(), self.env.task.object_shape.numpy()
        c, s = np.cos(object_yaw), np.sin(object_yaw)
        local_x = np.abs(c * direction[:, 0] + s * direction[:, 1])
        local_y = np.abs(-s * direction[:, 0] + c * direction[:, 1])
        x_face = local_x * dims[:, 1] >= local_y * dims[:, 0]  # the ray leaves through an x face
        depth = np.where(x_face, 0.5 * dims[:, 0] / np.maximum(local_x, 1e-6), 0.5 * dims[:, 1] / np.maximum(local_y, 1e-6))
        width = np.where(x_face, 0.5 * dims[:, 1], 0.5 * dims[:, 0])
        cylinder = shape == 1
        return np.where(cylinder, 0.5 * dims[:, 0], depth), np.where(cylinder, 0.5 * dims[:, 0], width)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Actions of every world from the true state (``observations`` unused: a policy's call signature)."""
        from dynpush.policies.evaluate import yaw_of

        cfg = self.cfg
        base, obj = self.probe.base(), self.probe.object()
        p_base, yaw_base = base[:, :2], yaw_of(base[:, 3:])
        p_obj, yaw_obj = obj[:, :2], yaw_of(obj[:, 3:])
        to_goal = self.env.task.goal_pos.numpy()[:, :2] - p_obj
        yaw_error = wrap(yaw_of(self.env.task.goal_quat.numpy()) - yaw_obj)
        distance = np.linalg.norm(to_goal, axis=1)
        turning = distance < cfg.turn_radius
        heading_dir = np.stack([np.cos(yaw_base), np.sin(yaw_base)], axis=1)
        push_dir = np.where(turning[:, None], heading_dir, to_goal / np.maximum(distance[:, None], 1e-6))
        side_dir = np.stack([-push_dir[:, 1], push_dir[:, 0]], axis=1)  # push_dir turned +90 deg
        depth, half_width = self._half_extent(-push_dir, yaw_obj)
        # A contact offset s along side_dir turns the object by -s x push force: steer with s ~ -yaw error.
        max_offset = cfg.max_offset * half_width
        offset = np.clip(-cfg.yaw_gain * yaw_error, -max_offset, max_offset)
        offset = np.where(turning, -np.sign(yaw_error) * max_offset, offset)
        contact = p_obj - push_dir * depth[:, None] + side_dir * offset[:, None]
        stand = contact - push_dir * cfg.ee_ahead  # base origin with the end-effector on the contact point
        behind = stand - 0.3 * push_dir
        along = ((p_base - p_obj) * push_dir).sum(1)  # > -depth: not behind the object
        lateral = ((p_base - stand) * side_dir).sum(1)
        heading = np.arctan2(push_dir[:, 1], push_dir[:, 0])
        # Push while the base is on the line behind the contact, facing along it, and not past the push stance
        # (closer to the object than the end-effector's reach: the end-effector slipped off the face).
        stance_along = -(depth + cfg.ee_ahead)
        pushing = ((np.abs(wrap(heading - yaw_base)) < cfg.align_tolerance) & (np.abs(lateral) < cfg.line_tolerance)
                   & (along < stance_along + cfg.slip_margin) & (along > stance_along - 0.45))
        side = np.sign(((p_base - p_obj) * side_dir).sum(1) + 1e-9)
        radius = np.maximum(depth, half_width) + cfg.clearance
        approach_along = depth + cfg.ee_ahead + 0.3  # how far behind the object's centre the approach ends
        around = p_obj + side_dir * (side * radius)[:, None] - push_dir * approach_along[:, None]
        go_around = (along > -approach_along + 0.3) & ~pushing
        speed = np.where(turning, cfg.turn_speed, np.minimum(cfg.push_speed, cfg.turn_speed + distance))  # slow near the goal
        target = np.where(pushing[:, None], stand + push_dir, np.where(go_around[:, None], around, behind))
        error = target - p_base
        c, s = np.cos(yaw_base), np.sin(yaw_base)
        limit = np.where(pushing, speed, cfg.approach_speed)
        vx = np.clip(2.0 * (c * error[:, 0] + s * error[:, 1]), -limit, limit)
        vy = np.clip(2.0 * (-s * error[:, 0] + c * error[:, 1]), -0.5, 0.5)
        yaw_rate = np.clip(2.5 * wrap(heading - yaw_base), -1.0, 1.0)
        done = (distance < self.done_distance) & (np.abs(yaw_error) < self.done_angle)
        vx, vy, yaw_rate = np.where(done, -0.3, vx), np.where(done, 0.0, vy), np.where(done, 0.0, yaw_rate)
        low = pushing | done
        pitch = np.where(low, cfg.push_pitch, self.base_default[4])
        height = np.where(low, cfg.push_height, self.base_default[5])
        command = np.stack([vx, vy, yaw_rate, 0 * vx, pitch, height], axis=1)
        actions = np.zeros((self.env.num_envs, self.env.num_actions), dtype=np.float32)
        actions[:, :6] = (command - self.base_default) / self.base_scale
        actions[:, 6:] = np.asarray(cfg.push_arm_action, dtype=np.float32)
        return actions
