"""World-frame state of a push environment, read from its Newton state for evaluation and the scripted pusher.

Frames and units: world frame Z-up (every environment has its origin at the world origin), SI units,
quaternions (x, y, z, w).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch
import warp as wp

from dynpush.kernels.push.observations import POLICY_TERMS, PRIVILEGED_TERMS
from dynpush.runtime.observation import NUM_ARM_JOINTS, quat_to_matrix

if TYPE_CHECKING:
    from dynpush.sim.push_env import PushEnv


def critic_column(name: str) -> int:
    """First column of a term in the critic observation (``PushEnv.critic_obs_t``)."""
    column = 0
    for term, size in (*POLICY_TERMS, *PRIVILEGED_TERMS):
        if term == name:
            return column
        column += size
    raise KeyError(f"no critic observation term {name!r}")


EE_CONTACT_COLUMN = critic_column("ee_object_contact")  # 54: 1 while the end-effector touches the object


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
        """(n, 6) the absolute base command of the last step as the base received it, clamped to the command limits
        (vx, vy [m/s] heading frame, yaw rate [rad/s], roll, pitch [rad], height [m])."""
        return self.env.base_target.numpy().astype(np.float64)

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
