"""Constraints of the paper's Table "Rewards and constraints" (violated where the value is > 0).

Columns, in order (62): base command limits (6), arm command limits (5), arm action rate (5),
arm joint position (5), arm joint velocity (5), arm joint torque (5), leg joint torque (12),
undesired collisions (18), object balance (1).

Tracked-base deviation (docs/task.md, "Deviations from the paper"): the leg joint torques are not simulated; they are the quasi-static
torques ``tau_leg = M @ wrench_b`` that the four legs of the nominal stance need to produce the
applied base-tracking wrench (``M`` from ``dynpush.sim.leg_statics``).
"""

import warp as wp

from dynpush.runtime.locomotion_layout import NUM_LEG_JOINTS

from ..common import pd_drive_torque
from ..frames import tilt_angle
from .views import NUM_ARM_JOINTS, NUM_BASE_COMMANDS, NUM_COLLISIONS, PushTask, RobotView

wp.set_module_options({"enable_backward": False})

CONSTRAINT_GROUPS = (
    ("base_command", 6),
    ("arm_command", 5),
    ("arm_action_rate", 5),
    ("arm_joint_position", 5),
    ("arm_joint_velocity", 5),
    ("arm_joint_torque", 5),
    ("leg_joint_torque", 12),
    ("collision", NUM_COLLISIONS),
    ("object_balance", 1),
)
NUM_CONSTRAINTS = sum(size for _, size in CONSTRAINT_GROUPS)


@wp.struct
class ArmLimits:
    """Per arm joint (5): limits from the USD robot and the nominal torques of the config."""

    lower: wp.array(dtype=float)  # [rad]
    upper: wp.array(dtype=float)  # [rad]
    velocity: wp.array(dtype=float)  # [rad/s]
    stiffness: wp.array(dtype=float)  # drive [N m/rad]
    damping: wp.array(dtype=float)  # drive [N m s/rad]
    peak_torque: wp.array(dtype=float)  # drive saturation [N m]
    nominal_torque: wp.array(dtype=float)  # constraint limit [N m]


@wp.struct
class ConstraintParams:
    base_lower: wp.array(dtype=float)  # (6,)
    base_upper: wp.array(dtype=float)  # (6,)
    leg_torque_map: wp.array2d(dtype=float)  # (12, 6): base-frame wrench (force, torque) -> leg torques
    leg_nominal_torque: wp.array(dtype=float)  # (12,)
    object_tilt_limit: float  # [rad]
    base_moving_speed: float  # [m/s]
    arm_scale: float
    control_dt: float  # [s]


@wp.kernel
def compute_constraints(
    robot: RobotView,
    task: PushTask,
    limits: ArmLimits,
    params: ConstraintParams,
    joint_target_q: wp.array(dtype=float),
    constraints: wp.array2d(dtype=float),
):
    """Every world's constraint row. The command limits judge the commands as the policy asked for them
    (``task.base_command``, ``task.arm_command``); the arm's drive torque is that of the target its drive received
    (``joint_target_q``: the command clamped to the joint range, ``actions.py``)."""
    w = wp.tid()
    k = int(0)
    for i in range(NUM_BASE_COMMANDS):
        u = task.base_command[w, i]
        constraints[w, k + i] = wp.max(u - params.base_upper[i], params.base_lower[i] - u)
    k += NUM_BASE_COMMANDS
    for j in range(NUM_ARM_JOINTS):
        q_cmd = task.arm_command[w, j]
        constraints[w, k + j] = wp.max(q_cmd - limits.upper[j], limits.lower[j] - q_cmd)
    k += NUM_ARM_JOINTS
    for j in range(NUM_ARM_JOINTS):
        a = NUM_BASE_COMMANDS + j
        rate = params.arm_scale * wp.abs(task.actions[w, a] - task.last_actions[w, a]) / params.control_dt
        constraints[w, k + j] = rate - limits.velocity[j]
    k += NUM_ARM_JOINTS
    q0 = robot.arm_q_start[w]
    qd0 = robot.arm_qd_start[w]
    for j in range(NUM_ARM_JOINTS):
        q = robot.joint_q[q0 + j]
        constraints[w, k + j] = wp.max(q - limits.upper[j], limits.lower[j] - q)
    k += NUM_ARM_JOINTS
    for j in range(NUM_ARM_JOINTS):
        constraints[w, k + j] = wp.abs(robot.joint_qd[qd0 + j]) - limits.velocity[j]
    k += NUM_ARM_JOINTS
    for j in range(NUM_ARM_JOINTS):
        tau = pd_drive_torque(limits.stiffness[j], limits.damping[j], joint_target_q[q0 + j], robot.joint_q[q0 + j],
                              robot.joint_qd[qd0 + j], limits.peak_torque[j])
        constraints[w, k + j] = wp.abs(tau) - limits.nominal_torque[j]
    k += NUM_ARM_JOINTS
    wrench = task.base_wrench_b[w]
    for i in range(NUM_LEG_JOINTS):
        tau = float(0.0)
        for c in range(6):
            tau += params.leg_torque_map[i, c] * wrench[c]
        constraints[w, k + i] = wp.abs(tau) - params.leg_nominal_torque[i]
    k += NUM_LEG_JOINTS
    for c in range(NUM_COLLISIONS):
        constraints[w, k + c] = float(task.contacts[w, c])
    k += NUM_COLLISIONS
    balance = float(0.0)
    v_b = wp.spatial_top(robot.body_qd[robot.base_body[w]])
    if wp.length(v_b) > params.base_moving_speed:
        balance = wp.abs(tilt_angle(wp.transform_get_rotation(robot.body_q[robot.object_body[w]]))) - params.object_tilt_limit
    constraints[w, k] = balance
