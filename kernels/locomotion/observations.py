"""Observations of the locomotion task.

Actor observation (61), the layout of the runtime's locomotion ONNX (``dynpush.runtime.locomotion_layout.LOCOMOTION_TERMS``,
in that order, scale 1): ``base_linear_velocity_b`` (3), ``base_angular_velocity_b`` (3),
``projected_gravity_b`` (3, ``R_b^T (0, 0, -1)``), ``base_command`` (6), ``leg_joint_position`` (12,
``q - q_default``), ``leg_joint_velocity`` (12), ``last_leg_actions`` (12), ``arm_joint_position`` (5,
``q - q_default``), ``arm_joint_velocity`` (5). Critic (67, noiseless): the same, then ``base_height``
(1), ``foot_contact`` (4) and ``base_mass_offset`` (1). Frames: ``_b`` base.
"""

import warp as wp

from dynpush.runtime.locomotion_layout import LOCOMOTION_TERMS

from ..common import add_noise, write_vec
from ..frames import next_rng
from .views import NUM_ARM_JOINTS, NUM_COMMANDS, NUM_FEET, NUM_LEG_JOINTS, LeggedView, LocomotionParams, LocomotionTask

wp.set_module_options({"enable_backward": False})

POLICY_TERMS = tuple(LOCOMOTION_TERMS.items())
PRIVILEGED_TERMS = (("base_height", 1), ("foot_contact", NUM_FEET), ("base_mass_offset", 1))
NUM_POLICY_OBS = sum(size for _, size in POLICY_TERMS)
NUM_CRITIC_OBS = NUM_POLICY_OBS + sum(size for _, size in PRIVILEGED_TERMS)


@wp.kernel
def compute_observations(
    view: LeggedView,
    task: LocomotionTask,
    params: LocomotionParams,
    noise_scale: wp.array(dtype=float),
    noise_enabled: int,
    seed: int,
    policy_obs: wp.array2d(dtype=float),
    critic_obs: wp.array2d(dtype=float),
):
    """Fills ``critic_obs`` (noiseless) then ``policy_obs`` = its first 61 entries + U(-s, s) noise."""
    w = wp.tid()
    x_b = view.body_q[view.base_body[w]]
    q_b = wp.transform_get_rotation(x_b)
    qd_b = view.body_qd[view.base_body[w]]
    k = int(0)
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.spatial_top(qd_b)))
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.spatial_bottom(qd_b)))
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.vec3(0.0, 0.0, -1.0)))
    for i in range(NUM_COMMANDS):
        critic_obs[w, k + i] = task.command[w, i]
    k += NUM_COMMANDS
    for j in range(NUM_LEG_JOINTS):
        critic_obs[w, k + j] = view.joint_q[view.leg_q[w, j]] - params.leg_default[j]
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        critic_obs[w, k + j] = view.joint_qd[view.leg_qd[w, j]]
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        critic_obs[w, k + j] = task.actions[w, j]
    k += NUM_LEG_JOINTS
    for j in range(NUM_ARM_JOINTS):
        critic_obs[w, k + j] = view.joint_q[view.arm_q[w, j]] - params.arm_default[j]
    k += NUM_ARM_JOINTS
    for j in range(NUM_ARM_JOINTS):
        critic_obs[w, k + j] = view.joint_qd[view.arm_qd[w, j]]
    k += NUM_ARM_JOINTS
    # Privileged terms.
    critic_obs[w, k] = wp.transform_get_translation(x_b)[2]
    k += 1
    for f in range(NUM_FEET):
        critic_obs[w, k + f] = float(task.foot_contact[w, f])
    k += NUM_FEET
    critic_obs[w, k] = task.base_mass_offset[w]

    add_noise(critic_obs, policy_obs, w, noise_scale, noise_enabled, next_rng(seed, task.rng_counter, w))
