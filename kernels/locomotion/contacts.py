"""Foot contacts of the locomotion task: contact and air time of each foot from its height above the ground
plane z = 0 [m], and the contact force [N] of each lower leg from the solver's contact sensor.
"""

import warp as wp

from .views import NUM_FEET, LeggedLimits, LeggedView, LocomotionTask

wp.set_module_options({"enable_backward": False})


@wp.kernel
def update_feet(view: LeggedView, limits: LeggedLimits, task: LocomotionTask):
    """Foot contact (the foot sphere within ``contact_margin`` of the ground) and air time after the physics."""
    w = wp.tid()
    for f in range(NUM_FEET):
        foot = wp.transform_point(view.body_q[view.shank_body[w, f]], limits.foot_offset)
        contact = foot[2] - limits.foot_radius < limits.contact_margin
        task.touchdown_air_time[w, f] = -1.0
        if contact:
            if task.foot_contact[w, f] == 0:
                task.touchdown_air_time[w, f] = task.foot_air_time[w, f] + limits.control_dt
            task.foot_air_time[w, f] = 0.0
        else:
            task.foot_air_time[w, f] = task.foot_air_time[w, f] + limits.control_dt
        task.foot_contact[w, f] = wp.where(contact, 1, 0)


@wp.kernel
def gather_foot_forces(total_force: wp.array(dtype=wp.vec3), foot_force: wp.array2d(dtype=float)):
    """``foot_force[w, f]`` = |F| [N] of contact sensor row ``NUM_FEET w + f`` (the lower leg ``f`` of world ``w``)."""
    w = wp.tid()
    for f in range(NUM_FEET):
        foot_force[w, f] = wp.length(total_force[w * NUM_FEET + f])
