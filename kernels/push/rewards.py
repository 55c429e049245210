"""Rewards r1..r4 and the success rule (paper Table "Rewards and constraints", III-B, III-D).

``r1 = exp(-||K_g - K_o|| / sigma_3^2)`` (2 on success), ``r2 = exp(-||p_e - p_r|| / sigma_1^2)`` (held
at its previous value on success), ``r3 = exp(v_o_hat . p_og_hat / sigma_2^2 - 1)`` (0 on success),
``r4 = exp(-||du_t - du_{t-1}|| / sigma_4b^2) + exp(-||dq_t - dq_{t-1}|| / sigma_4a^2)``.
Total ``sum_i w_i r_i``. Success: the rule of :mod:`.goal` (``||p_o - p_g|| <= d_success`` and the rotation
between object and goal ``<= theta_success``).
"""

import warp as wp

from .goal import object_at_goal
from .keypoints import keypoint_distance
from .observations import object_origin_velocity
from .views import NUM_ARM_JOINTS, NUM_BASE_COMMANDS, PushTask, RobotView

wp.set_module_options({"enable_backward": False})


@wp.struct
class RewardParams:
    sigma_reach: float
    sigma_velocity: float
    sigma_task: float
    sigma_base_rate: float
    sigma_arm_rate: float
    success_task_reward: float
    success_distance: float  # [m]
    arm_scale: float


@wp.func
def safe_normalize(v: wp.vec3):
    """Unit vector, or zero for a (near) zero vector."""
    n = wp.length(v)
    if n < 1.0e-6:
        return wp.vec3(0.0)
    return v / n


@wp.kernel
def compute_rewards(
    robot: RobotView,
    task: PushTask,
    params: RewardParams,
    success_angle: wp.array(dtype=float),
    base_scale: wp.array(dtype=float),
    reward: wp.array(dtype=float),
    reward_terms: wp.array2d(dtype=float),
    success: wp.array(dtype=int),
):
    """Writes the weighted total, the four unweighted terms and the success flag of each world.

    ``success_angle[0]`` [rad]: the largest rotation from the goal that counts as success (the configured
    ``success_angle_deg`` unless a training curriculum widens it)."""
    w = wp.tid()
    x_o = robot.body_q[robot.object_body[w]]
    p_o = wp.transform_get_translation(x_o)
    q_o = wp.transform_get_rotation(x_o)
    p_g = task.goal_pos[w]
    q_g = task.goal_quat[w]

    is_success = object_at_goal(p_o, q_o, p_g, q_g, params.success_distance, success_angle[0])

    r1 = wp.exp(-keypoint_distance(p_o, q_o, p_g, q_g, task.object_dims[w]) / (params.sigma_task * params.sigma_task))
    p_e = wp.transform_point(robot.body_q[robot.ee_body[w]], robot.ee_offset)
    p_r = wp.transform_point(x_o, task.reach_target_o[w])
    r2 = wp.exp(-wp.length(p_e - p_r) / (params.sigma_reach * params.sigma_reach))
    v_o = object_origin_velocity(x_o, robot.body_qd[robot.object_body[w]], task.object_com_o[w])
    alignment = wp.dot(safe_normalize(v_o), safe_normalize(p_g - p_o))
    r3 = wp.exp(alignment / (params.sigma_velocity * params.sigma_velocity) - 1.0)

    base_rate = float(0.0)
    for i in range(NUM_BASE_COMMANDS):
        d = base_scale[i] * (task.actions[w, i] - task.last_actions[w, i])
        base_rate += d * d
    arm_rate = float(0.0)
    for j in range(NUM_ARM_JOINTS):
        d = params.arm_scale * (task.actions[w, NUM_BASE_COMMANDS + j] - task.last_actions[w, NUM_BASE_COMMANDS + j])
        arm_rate += d * d
    r4 = wp.exp(-wp.sqrt(base_rate) / (params.sigma_base_rate * params.sigma_base_rate)) + wp.exp(
        -wp.sqrt(arm_rate) / (params.sigma_arm_rate * params.sigma_arm_rate)
    )

    if is_success:
        r1 = params.success_task_reward
        r2 = task.reach_reward_held[w]
        r3 = 0.0
    task.reach_reward_held[w] = r2
    success[w] = wp.where(is_success, 1, 0)
    reward_terms[w, 0] = r1
    reward_terms[w, 1] = r2
    reward_terms[w, 2] = r3
    reward_terms[w, 3] = r4
    weights = task.reward_weights
    reward[w] = weights[0] * r1 + weights[1] * r2 + weights[2] * r3 + weights[3] * r4
