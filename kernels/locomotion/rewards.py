"""Rewards of the locomotion task (``REWARD_TERMS``, ``compute_rewards``).

``w exp(-e^2 / sigma)`` for the heading-frame velocity, the yaw rate, the attitude and the height, legged_gym's
stepping reward ``w sum_feet (t_air - t_target)`` at touchdowns while the command asks to move, and legged_gym's
penalties on the action rate ``-w sum_j (a_t - a_{t-1})^2``, the base's vertical velocity ``-w v_z^2`` and its
roll and pitch rates ``-w (omega_x,b^2 + omega_y,b^2)``. Frames: ``_b`` base, ``_h`` heading frame (base yaw only).
"""

import warp as wp

from ..frames import heading_roll_pitch, heading_yaw, yaw_quat
from .views import NUM_COMMANDS, NUM_FEET, NUM_LEG_JOINTS, LeggedView, LocomotionTask

wp.set_module_options({"enable_backward": False})

REWARD_TERMS = ("linear_velocity", "yaw_rate", "attitude", "height", "feet_air_time", "action_rate",
                "base_vertical_velocity", "base_roll_pitch_rate")
vec6 = wp.types.vector(length=NUM_COMMANDS, dtype=float)
NUM_REWARD_TERMS = len(REWARD_TERMS)
reward_vec = wp.types.vector(length=NUM_REWARD_TERMS, dtype=float)


@wp.struct
class LocomotionRewardParams:
    """Tracking kernels ``exp(-e^2 / sigma)``, the stepping reward and the weights."""

    sigma_linear_velocity: float  # [m^2/s^2]
    sigma_yaw_rate: float  # [rad^2/s^2]
    sigma_attitude: float  # [rad^2]
    sigma_height: float  # [m^2]
    air_time_target: float  # [s]
    moving_command: float  # the stepping reward counts while |(vx, vy)| + |yaw rate| exceeds this
    weights: wp.array(dtype=float)  # (NUM_REWARD_TERMS,) REWARD_TERMS order


@wp.func
def heading_velocities(q_b: wp.quat, qd_b: wp.spatial_vector):
    """(vx_h, vy_h, yaw rate): base velocity in the heading frame [m/s] and angular velocity about world z [rad/s]."""
    v_h = wp.quat_rotate_inv(yaw_quat(heading_yaw(q_b)), wp.spatial_top(qd_b))
    return wp.vec3(v_h[0], v_h[1], wp.spatial_bottom(qd_b)[2])


@wp.kernel
def compute_rewards(
    view: LeggedView,
    task: LocomotionTask,
    params: LocomotionRewardParams,
    reward: wp.array(dtype=float),
    reward_terms: wp.array2d(dtype=float),
    tracking_error: wp.array2d(dtype=float),
):
    """Tracking rewards of the 6D command: ``w_i exp(-e_i^2 / sigma_i)`` for the heading-frame velocity
    (vx, vy), the yaw rate, the attitude (roll, pitch) and the base height; and the stepping reward of
    legged_gym, ``w_5 sum_feet (t_air - air_time_target)`` over the feet touching down this step, while the
    command asks to move (a standing robot collects none); legged_gym's penalties: action rate
    ``-w_6 sum_j (a_t,j - a_t-1,j)^2`` (raw action units), the base's vertical velocity ``-w_7 v_z^2``
    (world frame, of its centre of mass, m/s) and roll and pitch rates ``-w_8 (omega_x^2 + omega_y^2)``
    (base frame, rad/s). ``tracking_error`` (N, 6): the errors
    ``command - measured`` per component (vx, vy, yaw rate, roll, pitch, height)."""
    w = wp.tid()
    x_b = view.body_q[view.base_body[w]]
    q_b = wp.transform_get_rotation(x_b)
    qd_b = view.body_qd[view.base_body[w]]
    velocity = heading_velocities(q_b, qd_b)
    omega_b = wp.quat_rotate_inv(q_b, wp.spatial_bottom(qd_b))
    vertical_velocity = wp.spatial_top(qd_b)[2]
    roll_pitch = heading_roll_pitch(q_b, yaw_quat(heading_yaw(q_b)))
    e_v = wp.vec2(task.command[w, 0] - velocity[0], task.command[w, 1] - velocity[1])
    e_yaw = task.command[w, 2] - velocity[2]
    e_att = wp.vec2(task.command[w, 3] - roll_pitch[0], task.command[w, 4] - roll_pitch[1])
    e_h = task.command[w, 5] - wp.transform_get_translation(x_b)[2]
    errors = vec6(e_v[0], e_v[1], e_yaw, e_att[0], e_att[1], e_h)
    for i in range(NUM_COMMANDS):
        tracking_error[w, i] = errors[i]
    stepping = float(0.0)
    moving = wp.length(wp.vec2(task.command[w, 0], task.command[w, 1])) + wp.abs(task.command[w, 2]) > params.moving_command
    for f in range(NUM_FEET):
        air = task.touchdown_air_time[w, f]
        if moving and air >= 0.0:
            stepping += air - params.air_time_target
    action_change = float(0.0)
    for j in range(NUM_LEG_JOINTS):
        change = task.actions[w, j] - task.last_actions[w, j]
        action_change += change * change
    terms = reward_vec(
        wp.exp(-wp.dot(e_v, e_v) / params.sigma_linear_velocity),
        wp.exp(-e_yaw * e_yaw / params.sigma_yaw_rate),
        wp.exp(-wp.dot(e_att, e_att) / params.sigma_attitude),
        wp.exp(-e_h * e_h / params.sigma_height),
        stepping,
        -action_change,
        -vertical_velocity * vertical_velocity,
        -(omega_b[0] * omega_b[0] + omega_b[1] * omega_b[1]),
    )
    total = float(0.0)
    for i in range(NUM_REWARD_TERMS):
        reward_terms[w, i] = params.weights[i] * terms[i]
        total += params.weights[i] * terms[i]
    reward[w] = total
