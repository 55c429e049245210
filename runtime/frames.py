"""Poses and frame conventions of the runtime: world Z-up, metres, quaternions (x, y, z, w).

Every external pose (motion capture, UDP stream) passes :class:`PoseConverter` exactly once, at the
boundary where it enters the runtime; everything behind it uses the runtime convention only.

Conventions of a source (:class:`FrameConvention`):

- ``up_axis``: ``"z"`` (already Z-up) or ``"y"`` (Y-up, as OptiTrack Motive streams by default). A
  Y-up world is rotated by +90 deg about x, ``(x, y, z) -> (x, -z, y)``. The bodies' own frames are
  assumed to follow the same axis convention as the source's world (a rigid body defined aligned with
  the world axes), so orientations are conjugated: ``R' = C R C^T``.
- ``quaternion_order``: ``"xyzw"`` or ``"wxyz"`` (scalar last or first).
- ``units``: ``"m"`` or ``"mm"`` for positions.

After conversion a per-body :class:`BodyOffset` maps the tracked frame (where the markers' rigid body
was defined) to the frame the policy expects (robot base frame, object centroid frame):
``p = p_t + R_t offset_position``, ``q = q_t * offset_quat``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .observation import quat_to_matrix

UP_AXES = ("z", "y")
QUATERNION_ORDERS = ("xyzw", "wxyz")
UNITS = {"m": 1.0, "mm": 1.0e-3}

_SQRT_HALF = math.sqrt(0.5)
_Y_UP_TO_Z_UP = np.array([_SQRT_HALF, 0.0, 0.0, _SQRT_HALF])  # +90 deg about x, (x, y, z, w)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions (x, y, z, w): rotation ``b`` first, then ``a``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ])


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


def yaw_quat(yaw: float) -> np.ndarray:
    """Rotation by ``yaw`` [rad] about world z, (x, y, z, w)."""
    return np.array([0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)])


def tilt_angle(q: ArrayLike) -> float | np.ndarray:
    """Angle [rad] between the body's z axis and world z for quaternions (..., 4) (x, y, z, w)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.arccos(np.clip(1.0 - 2.0 * (q[..., 0] ** 2 + q[..., 1] ** 2), -1.0, 1.0))


def rotation_angle(q_a: ArrayLike, q_b: ArrayLike) -> float | np.ndarray:
    """Angle [rad] of the rotation between two orientations (..., 4) (x, y, z, w), in [0, pi]."""
    a = np.asarray(q_a, dtype=np.float64)
    b = np.asarray(q_b, dtype=np.float64)
    dot = np.abs((a * b).sum(-1)) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return 2.0 * np.arccos(np.minimum(1.0, dot))


@dataclass
class Pose:
    """A frame in the world: ``position`` (3) [m], Z-up world frame; ``quat_xyzw`` (4), unit."""

    position: np.ndarray
    quat_xyzw: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        """``R`` (3, 3) with ``p_world = R @ p_body``."""
        return quat_to_matrix(self.quat_xyzw)


@dataclass
class FrameConvention:
    """Axis, quaternion and unit conventions of a pose source (see the module docstring)."""

    up_axis: str = "z"
    quaternion_order: str = "xyzw"
    units: str = "m"

    def is_runtime_convention(self) -> bool:
        return (self.up_axis, self.quaternion_order, self.units) == ("z", "xyzw", "m")


@dataclass
class BodyOffset:
    """The policy's frame in the tracked frame: ``position`` [m] and ``quat_xyzw``, Z-up body axes."""

    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    quat_xyzw: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0, 1.0])


class PoseConverter:
    """Converts raw (position, quaternion) of one source and body into a runtime :class:`Pose`."""

    def __init__(self, convention: FrameConvention, offset: BodyOffset):
        self._scale = UNITS[convention.units]
        self._wxyz = convention.quaternion_order == "wxyz"
        self._y_up = convention.up_axis == "y"
        self._offset_position = np.asarray(offset.position, dtype=np.float64)
        q = np.asarray(offset.quat_xyzw, dtype=np.float64)
        self._offset_quat = q / np.linalg.norm(q)
        self._identity_offset = not self._offset_position.any() and np.allclose(self._offset_quat, [0, 0, 0, 1])

    def __call__(self, position: ArrayLike, quat: ArrayLike) -> Pose:
        """The converted pose; raises ``ValueError`` for non-finite values or a zero quaternion."""
        p = np.asarray(position, dtype=np.float64) * self._scale
        q = np.asarray(quat, dtype=np.float64)
        norm = float(np.linalg.norm(q))
        if not (np.isfinite(p).all() and math.isfinite(norm) and norm > 1e-9):
            raise ValueError("pose with non-finite values or a zero quaternion")
        if self._wxyz:
            q = q[[1, 2, 3, 0]]
        q = q / norm
        if self._y_up:
            p = np.array([p[0], -p[2], p[1]])
            q = quat_multiply(quat_multiply(_Y_UP_TO_Z_UP, q), quat_conjugate(_Y_UP_TO_Z_UP))
        if not self._identity_offset:
            p = p + quat_to_matrix(q) @ self._offset_position
            q = quat_multiply(q, self._offset_quat)
        return Pose(position=p, quat_xyzw=q)
