"""Action processing of the locomotion task, and what else goes into the simulator before the physics.

The policy outputs 12 leg joint position offsets: ``q_leg^target = q_leg^default + action_scale * a``, clamped to the
joints' ranges as the runtime's safety layer clamps the leg targets it sends (``dynpush.runtime.safety``); the joints'
PD drives (stiffness ``k_p``, damping ``k_d``, effort limit from ``robot_legged.usda``) produce
``tau = clip(k_p (q^target - q) - k_d qd, -effort, effort)``. The random arm motion's targets go to the arm's
drives, and the end-effector force (``sampling.sample_ee_force``, heading frame) to its link as a world-frame
wrench.
"""

import warp as wp

from ..common import clipped_action
from ..frames import heading_yaw, yaw_quat
from .views import NUM_ARM_JOINTS, NUM_LEG_JOINTS, LeggedView, LocomotionParams, LocomotionTask

wp.set_module_options({"enable_backward": False})


@wp.kernel
def process_leg_actions(
    raw_actions: wp.array2d(dtype=float),
    params: LocomotionParams,
    view: LeggedView,
    task: LocomotionTask,
    joint_target_q: wp.array(dtype=float),
):
    """Shifts the action history, clips the actions (non-finite counts as zero) and writes the leg joint
    targets, clamped to the joints' ranges."""
    w = wp.tid()
    for j in range(NUM_LEG_JOINTS):
        task.last_actions[w, j] = task.actions[w, j]
        task.actions[w, j] = clipped_action(raw_actions[w, j], params.clip)
        target = wp.clamp(params.leg_default[j] + params.action_scale * task.actions[w, j], params.leg_lower[j],
                          params.leg_upper[j])
        task.leg_target[w, j] = target
        joint_target_q[view.leg_q[w, j]] = target


@wp.kernel
def write_leg_targets(
    leg_targets: wp.array2d(dtype=float),
    view: LeggedView,
    task: LocomotionTask,
    joint_target_q: wp.array(dtype=float),
):
    """Writes leg joint targets [rad] given from outside (a locomotion controller that runs elsewhere, sim-to-sim) as
    they are; the action history is left alone: that controller keeps its own."""
    w = wp.tid()
    for j in range(NUM_LEG_JOINTS):
        task.leg_target[w, j] = leg_targets[w, j]
        joint_target_q[view.leg_q[w, j]] = leg_targets[w, j]


@wp.kernel
def write_arm_targets(view: LeggedView, task: LocomotionTask, joint_target_q: wp.array(dtype=float)):
    """The random arm motion's targets (all 6 arm joints) into the joint drives."""
    w = wp.tid()
    for j in range(NUM_ARM_JOINTS + 1):
        joint_target_q[view.arm_q[w, j]] = task.arm_target[w, j]


@wp.kernel
def write_ee_force(
    view: LeggedView,
    task: LocomotionTask,
    ee_body: wp.array(dtype=int),
    ee_offset: wp.vec3,
    body_com: wp.array(dtype=wp.vec3),
    body_f_0: wp.array(dtype=wp.spatial_vector),
    body_f_1: wp.array(dtype=wp.spatial_vector),
):
    """The end-effector force as the wrench on its link that Newton's solvers apply: ``body_f = (F_w, (p_ee - c_w)
    x F_w)`` about the link's centre of mass ``c_w`` (world frame, Newton's ``State.body_f`` convention), with
    ``F_w = R_yaw F_h`` and ``p_ee`` the end-effector point; written into both states the substeps alternate."""
    w = wp.tid()
    b = ee_body[w]
    x_e = view.body_q[b]
    force_w = wp.quat_rotate(yaw_quat(heading_yaw(wp.transform_get_rotation(view.body_q[view.base_body[w]]))),
                             wp.vec3(task.ee_force_h[w, 0], task.ee_force_h[w, 1], task.ee_force_h[w, 2]))
    lever = wp.transform_point(x_e, ee_offset) - wp.transform_point(x_e, body_com[b])
    wrench = wp.spatial_vector(force_w, wp.cross(lever, force_w))
    body_f_0[b] = wrench
    body_f_1[b] = wrench
