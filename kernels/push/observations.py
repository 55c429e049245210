"""Observations (paper Table "Observations").

Actor ``o_t`` (54, with additive uniform noise), in this order:
``ee_to_object_b`` (3, ^b p_oe = R_b^T (p_e - p_o)), ``object_rotation_b`` (9, ^b R_o row-major),
``arm_joint_position`` (5, q_j - q_default), ``base_linear_velocity_b`` (3), ``base_angular_velocity_b``
(3), ``arm_joint_velocity`` (5), ``projected_gravity_b`` (3, R_b^T (0, 0, -1)), ``object_to_goal_b``
(3, ^b p_og = R_b^T (p_g - p_o)), ``goal_rotation_o`` (9, ^o R_g row-major), ``last_actions`` (11).

Critic (74, noiseless): the 54 above without noise, then ``ee_object_contact`` (1),
``object_com_b`` (3, R_b^T (c_o - p_b)), ``object_mass`` (1), ``object_dims`` (3),
``object_inertia`` (3, principal), ``object_linear_velocity_b`` (3), ``object_angular_velocity_b``
(3), ``object_shape_one_hot`` (2: cuboid, cylinder), ``object_at_goal`` (1: the success rule of :mod:`.goal` on
this state, at the success angle in force). Velocities of the object are those of its frame origin (the centroid),
expressed in the base frame.

The critic's input (``critic_input_terms``: 63, or 62 without ``object_at_goal``) is that buffer without
``last_actions`` (ours; the paper's critic sees all of ``o_t``, without ``object_at_goal``).

``object_at_goal`` (ours): the task reward steps up where the object reaches its goal (``r1`` = 2 against at most 1
just outside, ``r3`` = 0), so the values of the states inside the success region stand above those of their
neighbours. A critic that has to find that small region from the goal offset and rotation smooths the step: it
over-values the states just outside and under-values those inside, and through GAE's bootstrapping that error
credits an action that brings the object in with less than it earned (docs/ppo_fine_tuning.md). With the flag as an
input the critic can represent the step; it also follows a success angle that a training curriculum changes.

``last_actions`` (not read by the critic) is the sampled previous action, exploration noise included: a critic that
reads it learns to use it as a stand-in for the state (on the policy's own data the action mean is a function of the
state), gives the noise the same weight, and so credits every action with the value it would predict for a state in
which that action were the mean. The advantage then pushes the actor along the critic's weights instead of along the
return, whatever the reward; without that input the same fine-tune keeps its success (docs/ppo_fine_tuning.md).
"""

import warp as wp

from dynpush.runtime.observation import POLICY_OBSERVATION_LAYOUT

from ..common import add_noise, write_vec
from ..frames import next_rng
from .goal import object_at_goal
from .views import EE_CONTACT, NUM_ACTIONS, NUM_ARM_JOINTS, PushTask, RobotView

wp.set_module_options({"enable_backward": False})

# The actor layout is defined once, by the runtime's numpy builder (no heavy imports there).
POLICY_TERMS = POLICY_OBSERVATION_LAYOUT
PRIVILEGED_TERMS = (
    ("ee_object_contact", 1),
    ("object_com_b", 3),
    ("object_mass", 1),
    ("object_dims", 3),
    ("object_inertia", 3),
    ("object_linear_velocity_b", 3),
    ("object_angular_velocity_b", 3),
    ("object_shape_one_hot", 2),
    ("object_at_goal", 1),
)


def critic_input_terms(reads_object_at_goal: bool = True) -> tuple[tuple[str, int], ...]:
    """The terms the critic reads, in buffer order: all but ``last_actions``, and ``object_at_goal`` only if
    ``reads_object_at_goal`` (runs started before the critic read it keep their input)."""
    left_out = {"last_actions"} if reads_object_at_goal else {"last_actions", "object_at_goal"}
    return tuple(term for term in POLICY_TERMS + PRIVILEGED_TERMS if term[0] not in left_out)


def critic_input_columns(reads_object_at_goal: bool = True) -> list[int]:
    """Columns of the critic observation buffer (policy terms, then privileged terms) that the critic reads."""
    terms = critic_input_terms(reads_object_at_goal)
    columns, start = [], 0
    for name, size in POLICY_TERMS + PRIVILEGED_TERMS:
        if (name, size) in terms:
            columns.extend(range(start, start + size))
        start += size
    return columns


@wp.func
def object_origin_velocity(x_o: wp.transform, qd_o: wp.spatial_vector, com_o: wp.vec3):
    """World-frame velocity [m/s] of the object frame origin from Newton's CoM twist."""
    p_o = wp.transform_get_translation(x_o)
    c_w = wp.transform_point(x_o, com_o)
    return wp.spatial_top(qd_o) + wp.cross(wp.spatial_bottom(qd_o), p_o - c_w)


@wp.func
def write_mat(out: wp.array2d(dtype=float), w: int, k: int, m: wp.mat33):
    for r in range(3):
        for c in range(3):
            out[w, k + 3 * r + c] = m[r, c]
    return k + 9


@wp.kernel
def compute_observations(
    robot: RobotView,
    task: PushTask,
    noise_scale: wp.array(dtype=float),
    noise_enabled: int,
    seed: int,
    success_distance: float,
    success_angle: wp.array(dtype=float),
    policy_obs: wp.array2d(dtype=float),
    critic_obs: wp.array2d(dtype=float),
):
    """Fills ``critic_obs`` (noiseless) then ``policy_obs`` = its first 54 entries + U(-s, s) noise.

    ``noise_scale`` holds one half-width per actor entry (54, zero for ``last_actions``); ``success_distance`` [m]
    and ``success_angle[0]`` [rad] are the success rule's, as the rewards use them.
    """
    w = wp.tid()
    x_b = robot.body_q[robot.base_body[w]]
    x_o = robot.body_q[robot.object_body[w]]
    x_e = robot.body_q[robot.ee_body[w]]
    q_b = wp.transform_get_rotation(x_b)
    q_o = wp.transform_get_rotation(x_o)
    p_b = wp.transform_get_translation(x_b)
    p_o = wp.transform_get_translation(x_o)
    p_e = wp.transform_point(x_e, robot.ee_offset)
    R_b = wp.quat_to_matrix(q_b)
    R_o = wp.quat_to_matrix(q_o)
    R_g = wp.quat_to_matrix(task.goal_quat[w])
    qd_b = robot.body_qd[robot.base_body[w]]

    k = int(0)
    k = write_vec(critic_obs, w, k, wp.transpose(R_b) @ (p_e - p_o))
    k = write_mat(critic_obs, w, k, wp.transpose(R_b) @ R_o)
    for j in range(NUM_ARM_JOINTS):
        critic_obs[w, k + j] = robot.joint_q[robot.arm_q_start[w] + j] - task.arm_default[j]
    k += NUM_ARM_JOINTS
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.spatial_top(qd_b)))
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.spatial_bottom(qd_b)))
    for j in range(NUM_ARM_JOINTS):
        critic_obs[w, k + j] = robot.joint_qd[robot.arm_qd_start[w] + j]
    k += NUM_ARM_JOINTS
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.vec3(0.0, 0.0, -1.0)))
    k = write_vec(critic_obs, w, k, wp.transpose(R_b) @ (task.goal_pos[w] - p_o))
    k = write_mat(critic_obs, w, k, wp.transpose(R_o) @ R_g)
    for i in range(NUM_ACTIONS):
        critic_obs[w, k + i] = task.actions[w, i]
    k += NUM_ACTIONS

    # Privileged terms.
    critic_obs[w, k] = float(task.contacts[w, EE_CONTACT])
    k += 1
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.transform_point(x_o, task.object_com_o[w]) - p_b))
    critic_obs[w, k] = task.object_mass[w]
    k += 1
    k = write_vec(critic_obs, w, k, task.object_dims[w])
    k = write_vec(critic_obs, w, k, task.object_inertia[w])
    qd_o = robot.body_qd[robot.object_body[w]]
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, object_origin_velocity(x_o, qd_o, task.object_com_o[w])))
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.spatial_bottom(qd_o)))
    shape = task.object_shape[w]
    critic_obs[w, k] = wp.where(shape == 0, 1.0, 0.0)
    critic_obs[w, k + 1] = wp.where(shape == 1, 1.0, 0.0)
    k += 2
    at_goal = object_at_goal(p_o, q_o, task.goal_pos[w], task.goal_quat[w], success_distance, success_angle[0])
    critic_obs[w, k] = wp.where(at_goal, 1.0, 0.0)

    add_noise(critic_obs, policy_obs, w, noise_scale, noise_enabled, next_rng(seed, task.rng_counter, w))
