"""Actor observation ``o_t`` of the deployment runtime (paper Table "Observations"), in numpy only.

The runtime measures the base and object poses (motion capture), the base twist (state estimator),
the end-effector position (arm forward kinematics) and the arm joint readings, and turns them into
the 54-d vector the push policy was trained on. The layout and frames are those of the simulator's
``compute_observations`` kernel (``kernels/push/observations.py``), without its training noise; a test
checks that both agree. This module must not import torch, warp or newton.

Conventions: world frame Z-up, SI units (m, rad, m/s, rad/s), quaternions (x, y, z, w), rotation
matrices act on column vectors (``p_world = R_wb @ p_b``). ``R_b``, ``R_o``, ``R_g`` are the world
rotations of the base, object and goal frames.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, DTypeLike

# (name, size) of each actor term, in order (the simulator's ``POLICY_TERMS``).
POLICY_OBSERVATION_LAYOUT: tuple[tuple[str, int], ...] = (
    ("ee_to_object_b", 3),  # R_b^T (p_e - p_o) [m]
    ("object_rotation_b", 9),  # R_b^T R_o, row-major
    ("arm_joint_position", 5),  # q_j - q_default [rad]
    ("base_linear_velocity_b", 3),  # R_b^T v_b [m/s]
    ("base_angular_velocity_b", 3),  # R_b^T omega_b [rad/s]
    ("arm_joint_velocity", 5),  # qd_j [rad/s]
    ("projected_gravity_b", 3),  # R_b^T (0, 0, -1)
    ("object_to_goal_b", 3),  # R_b^T (p_g - p_o) [m]
    ("goal_rotation_o", 9),  # R_o^T R_g, row-major
    ("last_actions", 11),  # a_{t-1}
)
POLICY_OBSERVATION_SIZE = sum(size for _, size in POLICY_OBSERVATION_LAYOUT)  # 54
NUM_ARM_JOINTS = 5
NUM_ACTIONS = 11
GRAVITY_DIRECTION = np.array([0.0, 0.0, -1.0])  # world frame


def quat_to_matrix(q: ArrayLike) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of quaternions ``(..., 4)`` stored (x, y, z, w).

    The quaternions are normalized first, so a slightly denormalized measurement is accepted.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternions must have shape (..., 4) (x, y, z, w), got {q.shape}")
    norm2 = np.einsum("...i,...i->...", q, q)
    if np.any(norm2 < 1e-18):
        raise ValueError("quaternions must be non-zero")
    # Element by element (one pass, no stacking: this runs three times per 50 Hz tick).
    x, y, z, w = np.moveaxis(q, -1, 0)
    s = 2.0 / norm2  # normalises the quaternion
    xx, yy, zz, xy, xz, yz = s * x * x, s * y * y, s * z * z, s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    m = np.empty((*q.shape[:-1], 3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 0, 2] = 1.0 - yy - zz, xy - wz, xz + wy
    m[..., 1, 0], m[..., 1, 1], m[..., 1, 2] = xy + wz, 1.0 - xx - zz, yz - wx
    m[..., 2, 0], m[..., 2, 1], m[..., 2, 2] = xz - wy, yz + wx, 1.0 - xx - yy
    return m


def _vectors(name: str, value: ArrayLike, size: int) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape[-1:] != (size,):
        raise ValueError(f"{name} must have shape (..., {size}), got {array.shape}")
    return array


def _rows(matrix: np.ndarray) -> np.ndarray:
    """Row-major flattening of (..., 3, 3) matrices to (..., 9)."""
    return matrix.reshape(*matrix.shape[:-2], 9)


def policy_observation(
    *,
    base_position: ArrayLike,
    base_quat: ArrayLike,
    base_linear_velocity_w: ArrayLike,
    base_angular_velocity_w: ArrayLike,
    object_position: ArrayLike,
    object_quat: ArrayLike,
    ee_position: ArrayLike,
    arm_joint_position: ArrayLike,
    arm_joint_velocity: ArrayLike,
    arm_default: ArrayLike,
    goal_position: ArrayLike,
    goal_quat: ArrayLike,
    last_actions: ArrayLike,
    dtype: DTypeLike = np.float32,
) -> np.ndarray:
    """The noiseless actor observation ``o_t``, shape ``(..., 54)``, laid out as ``POLICY_OBSERVATION_LAYOUT``.

    Every argument is an array ``(..., k)``; the leading (batch) dimensions broadcast together.

    Args:
        base_position: ``p_b`` (3), base frame origin, world frame [m]. Every actor term is
            relative, so ``p_b`` does not enter ``o_t``; it is taken so that callers hand over the
            measured pose whole, and only its shape is checked.
        base_quat: orientation of the base frame in the world (4, x y z w).
        base_linear_velocity_w: ``v_b`` (3), velocity of the base frame origin, world frame [m/s].
        base_angular_velocity_w: ``omega_b`` (3), world frame [rad/s].
        object_position: ``p_o`` (3), object frame origin (its centroid), world frame [m].
        object_quat: object orientation in the world (4, x y z w).
        ee_position: ``p_e`` (3), end-effector point, world frame [m].
        arm_joint_position: ``q_j`` (5), readings of the first five arm joints [rad].
        arm_joint_velocity: ``qd_j`` (5) [rad/s].
        arm_default: ``q_default`` (5), the default arm configuration [rad].
        goal_position: ``p_g`` (3), object centroid at the goal, world frame [m].
        goal_quat: goal orientation in the world (4, x y z w).
        last_actions: ``a_{t-1}`` (11), the previous (clipped) policy actions.
        dtype: dtype of the result (the ONNX policy takes float32).
    """
    p_b = _vectors("base_position", base_position, 3)
    v_b = _vectors("base_linear_velocity_w", base_linear_velocity_w, 3)
    omega_b = _vectors("base_angular_velocity_w", base_angular_velocity_w, 3)
    p_o = _vectors("object_position", object_position, 3)
    p_e = _vectors("ee_position", ee_position, 3)
    q = _vectors("arm_joint_position", arm_joint_position, NUM_ARM_JOINTS)
    qd = _vectors("arm_joint_velocity", arm_joint_velocity, NUM_ARM_JOINTS)
    q_default = _vectors("arm_default", arm_default, NUM_ARM_JOINTS)
    p_g = _vectors("goal_position", goal_position, 3)
    actions = _vectors("last_actions", last_actions, NUM_ACTIONS)
    R_b = quat_to_matrix(base_quat)
    R_o = quat_to_matrix(object_quat)
    R_g = quat_to_matrix(goal_quat)

    batch = np.broadcast_shapes(
        *(a.shape[:-1] for a in (p_b, v_b, omega_b, p_o, p_e, q, qd, q_default, p_g, actions)),
        *(r.shape[:-2] for r in (R_b, R_o, R_g)),
    )
    # The five vectors expressed in the base frame, in one product: (R_b^T v)^T = v^T R_b.
    vectors = np.stack(np.broadcast_arrays(p_e - p_o, v_b, omega_b, GRAVITY_DIRECTION, p_g - p_o), axis=-2)
    ee_to_object_b, v_b_b, omega_b_b, gravity_b, object_to_goal_b = np.moveaxis(vectors @ R_b, -2, 0)
    terms = (
        ee_to_object_b,
        _rows(np.swapaxes(R_b, -1, -2) @ R_o),
        q - q_default,
        v_b_b,
        omega_b_b,
        qd,
        gravity_b,
        object_to_goal_b,
        _rows(np.swapaxes(R_o, -1, -2) @ R_g),
        actions,
    )
    columns = [np.broadcast_to(t, (*batch, size)) for t, (_, size) in zip(terms, POLICY_OBSERVATION_LAYOUT)]
    return np.concatenate(columns, axis=-1).astype(dtype)
