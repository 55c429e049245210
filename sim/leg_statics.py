"""Quasi-static leg torques of the tracked base (a documented deviation: docs/task.md, "Deviations from the
paper", tracked base and leg torques).

The paper constrains the 12 leg joint torques of ANYmal. The tracked-base model has no leg joints,
so the environment maps the applied base wrench to the torques that the legs of the nominal stance
would need to produce it: the wrench is distributed over the four feet by the minimum-norm solution
of ``G f = w`` (``G`` stacks the force and moment of each foot force about the base origin), and
each leg's joint torques are ``J_i^T f_i`` with the leg Jacobian of its HAA (x axis), HFE and KFE
(y axes) joints. Everything here is in the base frame and SI units.
"""

from __future__ import annotations

import numpy as np


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def leg_jacobian(haa: np.ndarray, hfe: np.ndarray, knee: np.ndarray, foot: np.ndarray) -> np.ndarray:
    """3x3 Jacobian d(foot)/d(q_HAA, q_HFE, q_KFE) of one leg: columns ``axis x (foot - joint)``."""
    x_axis, y_axis = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    return np.column_stack([np.cross(x_axis, foot - haa), np.cross(y_axis, foot - hfe), np.cross(y_axis, foot - knee)])


def leg_torque_map(haa: np.ndarray, hfe: np.ndarray, knee: np.ndarray, foot: np.ndarray) -> np.ndarray:
    """(12, 6) matrix from a base-frame wrench (force, torque about the base origin) to leg torques.

    Args:
        haa, hfe, knee, foot: (4, 3) joint and foot positions per leg (LF, RF, LH, RH), base frame [m].
    """
    grasp = np.zeros((6, 12))
    for i in range(4):
        grasp[0:3, 3 * i : 3 * i + 3] = np.eye(3)
        grasp[3:6, 3 * i : 3 * i + 3] = _skew(foot[i])
    foot_forces = np.linalg.pinv(grasp)  # (12, 6): min-norm foot forces for a wrench
    torques = np.zeros((12, 6))
    for i in range(4):
        jac = leg_jacobian(haa[i], hfe[i], knee[i], foot[i])
        torques[3 * i : 3 * i + 3] = jac.T @ foot_forces[3 * i : 3 * i + 3]
    return torques
