"""Constraints of the locomotion task (CaT, violated where > 0).

Columns in ``CONSTRAINT_GROUPS`` order: leg joint torque ``|tau| - tau_nominal`` (12), leg joint velocity
``|qd| - qd_max`` (12), leg joint acceleration ``|qd_t - qd_{t-1}| / dt - qdd_max`` (12), leg action rate
``|a_t - a_{t-1}| / dt - rate_max`` (12), collision (5: the base box and each leg's knee and shank within
``collision_margin`` of the ground, the ground being the plane z = 0), foot air time ``t_min - t_air`` at each
touchdown (4), foot contact force ``|F_foot| - F_max`` (4: the ground's contact force on each lower leg, foot
sphere and shank, at the control step's last substep, measured by the solver; ``contacts.gather_foot_forces``).
"""

import warp as wp

from ..common import pd_drive_torque
from .views import NUM_FEET, NUM_LEG_JOINTS, LeggedLimits, LeggedView, LocomotionTask

wp.set_module_options({"enable_backward": False})

CONSTRAINT_GROUPS = (
    ("leg_joint_torque", NUM_LEG_JOINTS),
    ("leg_joint_velocity", NUM_LEG_JOINTS),
    ("leg_joint_acceleration", NUM_LEG_JOINTS),
    ("leg_action_rate", NUM_LEG_JOINTS),
    ("collision", 1 + NUM_FEET),
    ("foot_air_time", NUM_FEET),
    ("foot_contact_force", NUM_FEET),
)
NUM_CONSTRAINTS = sum(size for _, size in CONSTRAINT_GROUPS)


@wp.func
def leg_torque(view: LeggedView, task: LocomotionTask, limits: LeggedLimits, w: int, j: int):
    """Torque [N m] of leg joint ``j`` under its PD drive towards ``task.leg_target``."""
    return pd_drive_torque(limits.stiffness[j], limits.damping[j], task.leg_target[w, j],
                           view.joint_q[view.leg_q[w, j]], view.joint_qd[view.leg_qd[w, j]], limits.effort_limit[j])


@wp.func
def leg_torque_excess(view: LeggedView, task: LocomotionTask, limits: LeggedLimits, w: int, j: int):
    """Leg-torque constraint value ``|tau_j| - tau_nominal_j`` [N m] (violated where > 0)."""
    return wp.abs(leg_torque(view, task, limits, w, j)) - limits.nominal_torque[j]


@wp.kernel
def write_leg_torque_constraints(view: LeggedView, task: LocomotionTask, limits: LeggedLimits,
                                 constraints: wp.array2d(dtype=float), first_column: int):
    """The 12 leg-torque constraint values into ``constraints[:, first_column:first_column + 12]`` (the legged
    push task's leg-torque columns)."""
    w = wp.tid()
    for j in range(NUM_LEG_JOINTS):
        constraints[w, first_column + j] = leg_torque_excess(view, task, limits, w, j)


@wp.func
def clearance(x: wp.transform, point: wp.vec3, radius: float):
    """Height [m] above the ground plane of a sphere of ``radius`` centred at body-frame ``point``."""
    return wp.transform_point(x, point)[2] - radius


@wp.kernel
def compute_constraints(
    view: LeggedView,
    task: LocomotionTask,
    limits: LeggedLimits,
    foot_force: wp.array2d(dtype=float),
    constraints: wp.array2d(dtype=float),
):
    """Constraint values (see the module docstring); then stores this step's leg velocities for the next."""
    w = wp.tid()
    k = int(0)
    for j in range(NUM_LEG_JOINTS):
        constraints[w, k + j] = leg_torque_excess(view, task, limits, w, j)
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        constraints[w, k + j] = wp.abs(view.joint_qd[view.leg_qd[w, j]]) - limits.velocity_limit[j]
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        qd = view.joint_qd[view.leg_qd[w, j]]
        constraints[w, k + j] = wp.abs(qd - task.leg_velocity_last[w, j]) / limits.control_dt - limits.acceleration_limit
        task.leg_velocity_last[w, j] = qd
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        rate = wp.abs(task.actions[w, j] - task.last_actions[w, j]) / limits.control_dt
        constraints[w, k + j] = rate - limits.action_rate_limit
    k += NUM_LEG_JOINTS
    # Base box: its lowest corner is |R_20| a + |R_21| b + |R_22| c below the base origin.
    x_b = view.body_q[view.base_body[w]]
    R = wp.quat_to_matrix(wp.transform_get_rotation(x_b))
    e = limits.base_half_extents
    lowest = wp.transform_get_translation(x_b)[2] - (wp.abs(R[2, 0]) * e[0] + wp.abs(R[2, 1]) * e[1] + wp.abs(R[2, 2]) * e[2])
    constraints[w, k] = limits.collision_margin - lowest
    for f in range(NUM_FEET):
        x_s = view.body_q[view.shank_body[w, f]]
        knee = clearance(x_s, wp.vec3(0.0), limits.knee_radius)
        shank = clearance(x_s, limits.shank_end, limits.shank_radius)
        constraints[w, k + 1 + f] = limits.collision_margin - wp.min(knee, shank)
    k += 1 + NUM_FEET
    for f in range(NUM_FEET):
        air = task.touchdown_air_time[w, f]
        constraints[w, k + f] = wp.where(air >= 0.0, limits.air_time_min - air, 0.0)
    k += NUM_FEET
    for f in range(NUM_FEET):
        constraints[w, k + f] = foot_force[w, f] - limits.foot_force_limit
