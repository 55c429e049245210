"""A learned locomotion policy run by the runtime: 6D base command -> 12 leg joint position targets.

Used with ``locomotion.mode: onnx``. The observation is the concatenation of ``scale * term`` for
the configured terms (``locomotion_layout.LOCOMOTION_TERMS``), all from the robot state (state estimator and
IMU, never mocap, so locomotion keeps standing when mocap is lost):

- ``base_linear_velocity_b`` (3) [m/s], ``base_angular_velocity_b`` (3) [rad/s]: base frame
- ``projected_gravity_b`` (3): ``R_imu^T (0, 0, -1)``
- ``base_command`` (6): the absolute command (vx, vy, yaw rate, roll, pitch, height)
- ``leg_joint_position`` (12): ``q_leg - default_joint_positions`` [rad]; ``leg_joint_velocity`` (12)
- ``last_leg_actions`` (12): the previous network output, clipped
- ``arm_joint_position`` (5): ``q_arm - arm default`` (policy contract) [rad]; ``arm_joint_velocity`` (5)

Leg targets = ``default_joint_positions + action_scale * clip(output, -action_clip, action_clip)``, with the push
policy contract's ``action_clip``: the bound at which the simulator's legged push environment clips the same outputs
(``env.actions.clip``, ``kernels/locomotion/actions.py``'s ``process_leg_actions``). A non-finite output stays
non-finite (the kernel counts it as zero), so that the command check stops the robot.

The network's contract (a ``locomotion.onnx`` written by ``dynpush export`` from a ``dynpush train --task
locomotion`` run) is read by ``locomotion_contract.py``, which the simulator's wrapper of the same file reads too;
the runtime refuses a config that disagrees with it. A network without one is described by the config alone.
"""

from __future__ import annotations

import numpy as np

from .actions import ActionScaling
from .config import OnnxLocomotionConfig
from .contract import PolicyContract
from .locomotion_contract import LOCOMOTION_CONTRACT_KEY, LocomotionContract
from .locomotion_layout import LOCOMOTION_TERMS, NUM_LEG_JOINTS
from .observation import GRAVITY_DIRECTION, quat_to_matrix
from .packets import Proprioception
from .policy import OnnxModel


class OnnxLocomotion:
    """The locomotion ONNX of ``cfg`` on one thread, its observation built from the robot state each tick."""

    def __init__(self, cfg: OnnxLocomotionConfig, contract: PolicyContract):
        self.model = OnnxModel(cfg.path, cfg.input_name, cfg.observation_size, cfg.output_name, NUM_LEG_JOINTS,
                               "locomotion.onnx")
        if LOCOMOTION_CONTRACT_KEY in self.model.metadata:
            LocomotionContract.from_metadata(self.model.metadata, f"locomotion.onnx {cfg.path}").check(cfg)
        self._terms = []
        start = 0
        for term in cfg.observation:
            size = LOCOMOTION_TERMS[term.name]
            self._terms.append((term.name, term.scale, slice(start, start + size)))
            start += size
        self.legs = ActionScaling(cfg.default_joint_positions, cfg.action_scale)  # leg targets [rad] of the outputs
        self._arm_default = np.asarray(contract.arm_default_joint_positions, dtype=np.float64)
        self.clip = float(contract.action_clip)  # raw outputs are clipped to +-clip before scaling
        self.last_actions = np.zeros(NUM_LEG_JOINTS)  # the previous outputs, clipped

    def _term(self, name: str, state: Proprioception, base_command: np.ndarray) -> np.ndarray:
        if name == "projected_gravity_b":
            return quat_to_matrix(state.base_quat_xyzw).T @ GRAVITY_DIRECTION
        if name == "leg_joint_position":
            return state.leg_q - self.legs.default
        if name == "arm_joint_position":
            return state.arm_q - self._arm_default
        return {
            "base_linear_velocity_b": state.base_linear_velocity_b,
            "base_angular_velocity_b": state.base_angular_velocity_b,
            "base_command": base_command,
            "leg_joint_velocity": state.leg_qd,
            "last_leg_actions": self.last_actions,
            "arm_joint_velocity": state.arm_qd,
        }[name]

    def step(self, state: Proprioception, base_command: np.ndarray) -> np.ndarray:
        """Leg joint targets (12) [rad] for ``base_command``; the observation stays in ``model.input``, the raw
        network output in ``model.output``."""
        observation = self.model.input[0]
        for name, scale, columns in self._terms:
            observation[columns] = scale * self._term(name, state, base_command)
        actions = self.model.run().astype(np.float64)
        self.last_actions = clipped_outputs(actions, self.clip)
        return self.legs.targets(self.last_actions)


def clipped_outputs(outputs: np.ndarray, clip: float) -> np.ndarray:
    """A locomotion network's raw outputs (..., 12) clipped to ``+-clip``, as the legged simulator clips them; a
    non-finite output stays as it is, for the safety layer's check of the targets."""
    return np.where(np.isfinite(outputs), np.clip(outputs, -clip, clip), outputs)
