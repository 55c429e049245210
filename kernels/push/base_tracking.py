"""Tracked-base locomotion model (docs/task.md, "Deviations from the paper").

The base is a free rigid body. Once per substep a wrench drives it toward the commanded 6D base
state ``(vx, vy, yaw rate, roll, pitch, height)`` (the command the robot receives, clamped to its limits:
``base_target`` of ``actions.py``) after a first-order lag that stands for the
locomotion controller's bandwidth. Horizontal velocities are tracked in the heading (yaw) frame.
The wrench supports the whole robot's weight at its centre of mass and saturates at force and
torque limits, so an object that is too heavy slows the robot down as it would on hardware.
"""

import warp as wp

from ..frames import heading_roll_pitch, heading_yaw, yaw_quat
from .views import PushTask, RobotView

wp.set_module_options({"enable_backward": False})


@wp.struct
class BaseTrackingParams:
    dt: float  # substep [s]
    time_constant: float  # command lag [s]
    velocity_gain: float  # [1/s]
    yaw_rate_gain: float  # [1/s]
    attitude_stiffness: float  # omega_n^2 [1/s^2]
    attitude_damping: float  # 2 zeta omega_n [1/s]
    max_horizontal_force: float  # [N]
    max_vertical_force: float  # [N]
    max_torque: wp.vec3  # [N m] about the heading frame's x, y (roll, pitch) and world z (yaw)
    attitude_inertia: wp.vec3  # [kg m^2] effective stance inertia about the same axes (z scales the yaw-rate torque)
    gravity: float  # [m/s^2], positive


@wp.kernel
def apply_base_wrench(robot: RobotView, task: PushTask, base_target: wp.array2d(dtype=float), params: BaseTrackingParams,
                      body_f: wp.array(dtype=wp.spatial_vector)):
    """Adds the tracking wrench of ``base_target`` (num_worlds, 6) to ``body_f`` of each base (world frame, at the base
    CoM)."""
    w = wp.tid()
    b = robot.base_body[w]
    alpha = params.dt / (params.time_constant + params.dt)
    for i in range(6):
        f = task.base_command_filtered[w, i]
        task.base_command_filtered[w, i] = f + alpha * (base_target[w, i] - f)
    vx_cmd = task.base_command_filtered[w, 0]
    vy_cmd = task.base_command_filtered[w, 1]
    yaw_rate_cmd = task.base_command_filtered[w, 2]
    roll_cmd = task.base_command_filtered[w, 3]
    pitch_cmd = task.base_command_filtered[w, 4]
    height_cmd = task.base_command_filtered[w, 5]

    x_b = robot.body_q[b]
    p_b = wp.transform_get_translation(x_b)
    q_b = wp.transform_get_rotation(x_b)
    v_w = wp.spatial_top(robot.body_qd[b])
    omega_w = wp.spatial_bottom(robot.body_qd[b])

    # Whole-robot mass and centre of mass (the legs carry the arm too).
    mass = float(0.0)
    com = wp.vec3(0.0)
    for k in range(robot.robot_body_count):
        body = robot.robot_body_start[w] + k
        m = robot.body_mass[body]
        mass += m
        com += m * wp.transform_point(robot.body_q[body], robot.body_com[body])
    com = com / mass

    # Horizontal velocity in the heading frame.
    yaw = heading_yaw(q_b)
    q_yaw = yaw_quat(yaw)
    v_target = wp.quat_rotate(q_yaw, wp.vec3(vx_cmd, vy_cmd, 0.0))
    f_xy = mass * params.velocity_gain * (wp.vec3(v_target[0], v_target[1], 0.0) - wp.vec3(v_w[0], v_w[1], 0.0))
    f_xy_norm = wp.length(f_xy)
    if f_xy_norm > params.max_horizontal_force:
        f_xy = f_xy * (params.max_horizontal_force / f_xy_norm)
    f_z = mass * (params.gravity + params.attitude_stiffness * (height_cmd - p_b[2]) - params.attitude_damping * v_w[2])
    f_z = wp.clamp(f_z, 0.0, params.max_vertical_force)
    force_w = wp.vec3(f_xy[0], f_xy[1], f_z)

    # Attitude: roll/pitch about the heading frame, yaw rate about world z.
    omega_h = wp.quat_rotate_inv(q_yaw, omega_w)
    roll_pitch = heading_roll_pitch(q_b, q_yaw)
    roll = roll_pitch[0]
    pitch = roll_pitch[1]
    tau_x = params.attitude_inertia[0] * (params.attitude_stiffness * (roll_cmd - roll) - params.attitude_damping * omega_h[0])
    tau_y = params.attitude_inertia[1] * (params.attitude_stiffness * (pitch_cmd - pitch) - params.attitude_damping * omega_h[1])
    tau_z = params.attitude_inertia[2] * params.yaw_rate_gain * (yaw_rate_cmd - omega_w[2])
    tau_h = wp.vec3(
        wp.clamp(tau_x, -params.max_torque[0], params.max_torque[0]),
        wp.clamp(tau_y, -params.max_torque[1], params.max_torque[1]),
        wp.clamp(tau_z, -params.max_torque[2], params.max_torque[2]),
    )
    # The support force acts at the robot's CoM; body_f is referenced at the base CoM.
    lever = com - wp.transform_point(x_b, robot.body_com[b])
    torque_w = wp.quat_rotate(q_yaw, tau_h) + wp.cross(lever, force_w)

    body_f[b] = body_f[b] + wp.spatial_vector(force_w, torque_w)
    task.base_wrench_b[w] = wp.spatial_vector(wp.quat_rotate_inv(q_b, force_w), wp.quat_rotate_inv(q_b, torque_w))
