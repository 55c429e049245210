"""The push policy's actions and the commands they stand for (paper III-C), in numpy only: the one definition.

Actions ``a`` (11) are ``a_base`` (6, ``BASE_COMMAND_NAMES``) then ``a_arm`` (5, the controlled arm joints in the
contract's order). The raw policy output is clipped to ``+-clip``, then

- ``u_base = base_default + base_scale * a_base``: vx, vy [m/s] and yaw rate [rad/s] in the heading frame (the base's
  yaw frame), roll and pitch [rad], height [m]: the 6D command of the locomotion controller;
- ``q_arm = arm_default + arm_scale * a_arm`` [rad]: the arm's joint position targets.

Who uses it: the runtime's controller turns the ONNX output into commands with the parameters of the policy's
contract (``PolicyContract.action_mapping``); the simulator builds its own from its config and robot
(``PushEnv.action_mapping``) and launches the same formula on the GPU as the Warp kernel ``kernels/push/actions.py``
(``tests/test_action_mapping.py`` checks that both agree on random actions); sim-to-sim hands the runtime's commands
to the simulator as they are (``PushEnv.step_commands``), so the mapping is applied once. :meth:`ActionMapping.actions`
(targets back to actions) serves where a policy-side quantity is wanted of commands: the runtime's previous action
outside PUSH (the observation's ``last_actions``) and the scripted policies. The locomotion policy's leg targets use
:class:`ActionScaling` too.

A non-finite action stays non-finite here, because the runtime must notice it and stop the robot; the kernel counts
it as zero instead, so that one diverged world cannot poison a training batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .observation import NUM_ACTIONS, NUM_ARM_JOINTS

NUM_BASE_COMMANDS = NUM_ACTIONS - NUM_ARM_JOINTS  # 6: the base command's share of the actions
BASE_COMMAND_NAMES = ("vx", "vy", "yaw_rate", "roll", "pitch", "height")  # also the locomotion policy's command
ACTION_LAYOUT: tuple[tuple[str, int], ...] = (
    ("base_command", NUM_BASE_COMMANDS),
    ("arm_joint_position", NUM_ARM_JOINTS),
)


@dataclass(frozen=True, eq=False)
class ActionScaling:
    """One block of policy outputs as targets: ``target = default + scale * a``, in the units of ``default``."""

    default: np.ndarray  # (n,) the target of a zero action
    scale: np.ndarray  # (n,) or a scalar, > 0: target units per unit action

    def __post_init__(self) -> None:
        object.__setattr__(self, "default", np.asarray(self.default, dtype=np.float64))
        object.__setattr__(self, "scale", np.asarray(self.scale, dtype=np.float64))

    def targets(self, actions: ArrayLike) -> np.ndarray:
        """The targets (..., n) of ``actions`` (..., n)."""
        return self.default + self.scale * np.asarray(actions, dtype=np.float64)

    def actions(self, targets: ArrayLike) -> np.ndarray:
        """The actions (..., n) whose targets are ``targets`` (..., n): the inverse of :meth:`targets`."""
        return (np.asarray(targets, dtype=np.float64) - self.default) / self.scale


@dataclass(frozen=True, eq=False)
class ActionMapping:
    """The push policy's 11 actions as the base command (6) and the arm joint targets (5) [rad] (module docstring)."""

    base: ActionScaling  # (6,) in BASE_COMMAND_NAMES order and units
    arm: ActionScaling  # (5,) [rad], one scale for every joint
    clip: float  # raw actions are clipped to +-clip before scaling

    def __post_init__(self) -> None:
        if self.base.default.shape != (NUM_BASE_COMMANDS,) or self.arm.default.shape != (NUM_ARM_JOINTS,):
            raise ValueError(f"action mapping: {NUM_BASE_COMMANDS} base and {NUM_ARM_JOINTS} arm defaults expected,"
                             f" got {self.base.default.shape} and {self.arm.default.shape}")

    def clipped(self, actions: ArrayLike) -> np.ndarray:
        """Raw actions (..., 11) clipped to ``+-clip``."""
        return np.clip(np.asarray(actions, dtype=np.float64), -self.clip, self.clip)

    def commands(self, actions: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(u_base (..., 6), q_arm (..., 5) [rad])`` of raw actions (..., 11), which are clipped first."""
        a = self.clipped(actions)
        return self.base.targets(a[..., :NUM_BASE_COMMANDS]), self.arm.targets(a[..., NUM_BASE_COMMANDS:])

    def actions(self, base_command: ArrayLike, arm_targets: ArrayLike) -> np.ndarray:
        """The actions (..., 11) whose commands are ``base_command`` (..., 6) and ``arm_targets`` (..., 5) [rad]: the
        inverse of :meth:`commands` for commands within the clip range."""
        return np.concatenate([self.base.actions(base_command), self.arm.actions(arm_targets)], axis=-1)
