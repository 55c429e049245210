"""Action processing (paper III-C): deviations about the default base state and arm configuration.

The mapping is defined once, in numpy, by ``dynpush.runtime.actions`` (the deployment runtime applies it to the ONNX
output); this kernel is the same formula for all worlds on the simulator's device, launched with the parameters of
``PushEnv.action_mapping``, and ``tests/test_action_mapping.py`` checks that both agree on random actions.
``apply_commands`` is the entry for commands that were mapped outside (``PushEnv.step_commands``, sim-to-sim): it
writes them where ``process_actions`` writes its own and records the caller's actions in the action history.

Both keep two versions of each command. ``task.base_command`` and ``task.arm_command`` are what the policy asks for:
the constraints price them (``constraints.py``: a command beyond its limit is a violation). What the robot receives
is that command clamped to :class:`CommandLimits`, as the runtime's safety layer clamps every command it sends
(``dynpush.runtime.safety.CommandLimits``): the base follows ``base_target`` (the tracking wrench, or the locomotion
policy's command on legs) and the arm's position drives get the clamped targets. A policy that asks for more than
the limits is then trained on what it will get on the robot.
"""

import warp as wp

from ..common import clipped_action
from .views import NUM_ACTIONS, NUM_ARM_JOINTS, NUM_BASE_COMMANDS, PushTask, RobotView

wp.set_module_options({"enable_backward": False})


@wp.struct
class CommandLimits:
    """Bounds of what the robot receives (the policy contract's, which the runtime's safety layer clamps to)."""

    base_lower: wp.array(dtype=float)  # (6,) base command: vx, vy [m/s], yaw rate [rad/s], roll, pitch [rad], height [m]
    base_upper: wp.array(dtype=float)  # (6,)
    arm_lower: wp.array(dtype=float)  # (5,) arm joint targets [rad]
    arm_upper: wp.array(dtype=float)  # (5,)


@wp.func
def send_commands(robot: RobotView, task: PushTask, limits: CommandLimits, w: int,
                  base_target: wp.array2d(dtype=float), joint_target_q: wp.array(dtype=float)):
    """World ``w``'s ``task.base_command`` and ``task.arm_command``, clamped to ``limits``, to the base
    (``base_target``) and the arm's position drives (``joint_target_q``)."""
    for i in range(NUM_BASE_COMMANDS):
        base_target[w, i] = wp.clamp(task.base_command[w, i], limits.base_lower[i], limits.base_upper[i])
    start = robot.arm_q_start[w]
    for j in range(NUM_ARM_JOINTS):
        joint_target_q[start + j] = wp.clamp(task.arm_command[w, j], limits.arm_lower[j], limits.arm_upper[j])


@wp.func
def record_actions(raw_actions: wp.array2d(dtype=float), task: PushTask, clip: float, w: int):
    """Shifts world ``w``'s action history: ``last_actions = actions``, ``actions = clip(raw_actions)`` (a
    non-finite raw action counts as zero)."""
    for i in range(NUM_ACTIONS):
        task.last_actions[w, i] = task.actions[w, i]
        task.actions[w, i] = clipped_action(raw_actions[w, i], clip)


@wp.kernel
def process_actions(
    raw_actions: wp.array2d(dtype=float),
    robot: RobotView,
    task: PushTask,
    base_default: wp.array(dtype=float),
    base_scale: wp.array(dtype=float),
    arm_scale: float,
    clip: float,
    limits: CommandLimits,
    base_target: wp.array2d(dtype=float),
    joint_target_q: wp.array(dtype=float),
):
    """Shifts the action history, turns the policy output into absolute commands and sends them.

    ``u_base^cmd = base_default + base_scale * a[0:6]`` (vx, vy [m/s] and yaw rate [rad/s] in the
    heading frame; roll, pitch [rad]; height [m]) and ``q_j^cmd = q_default + arm_scale * a[6:11]``
    [rad] (``task.arm_default`` holds ``q_default``), with ``a`` clipped to ``+-clip``; both clamped to ``limits``
    go to the base (``base_target``) and the arm's joint position drives. Non-finite actions count as zero, so
    that one diverged world cannot poison the batch.
    """
    w = wp.tid()
    record_actions(raw_actions, task, clip, w)
    for i in range(NUM_BASE_COMMANDS):
        task.base_command[w, i] = base_default[i] + base_scale[i] * task.actions[w, i]
    for j in range(NUM_ARM_JOINTS):
        task.arm_command[w, j] = task.arm_default[j] + arm_scale * task.actions[w, NUM_BASE_COMMANDS + j]
    send_commands(robot, task, limits, w, base_target, joint_target_q)


@wp.kernel
def apply_commands(
    raw_actions: wp.array2d(dtype=float),
    base_command: wp.array2d(dtype=float),
    arm_targets: wp.array2d(dtype=float),
    robot: RobotView,
    task: PushTask,
    clip: float,
    limits: CommandLimits,
    base_target: wp.array2d(dtype=float),
    joint_target_q: wp.array(dtype=float),
):
    """Commands given as they are: ``task.base_command = base_command`` (6, as in ``process_actions``) and
    ``task.arm_command = arm_targets`` [rad], sent as ``process_actions`` sends its own; the action history is
    shifted with ``raw_actions`` as in ``process_actions`` (the policy output behind the commands, zeros when the
    caller has none), for the action terms (the ``last_actions`` observation, the action-rate reward and arm-rate
    constraint)."""
    w = wp.tid()
    record_actions(raw_actions, task, clip, w)
    for i in range(NUM_BASE_COMMANDS):
        task.base_command[w, i] = base_command[w, i]
    for j in range(NUM_ARM_JOINTS):
        task.arm_command[w, j] = arm_targets[w, j]
    send_commands(robot, task, limits, w, base_target, joint_target_q)
