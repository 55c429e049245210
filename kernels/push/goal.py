"""The success rule (paper III-B): the object is at its goal when its position is within ``d_success`` of the goal's
and the rotation between the two orientations is within ``theta_success``. The rewards (``r1 = 2`` on success) and
the critic's ``object_at_goal`` input both apply it.
"""

import warp as wp

from ..frames import rotation_angle

wp.set_module_options({"enable_backward": False})


@wp.func
def object_at_goal(p_o: wp.vec3, q_o: wp.quat, p_g: wp.vec3, q_g: wp.quat, success_distance: float,
                   success_angle: float):
    """Whether the object (position ``p_o`` [m], orientation ``q_o``) is at its goal (``p_g``, ``q_g``):
    ``||p_g - p_o|| <= success_distance`` [m] and ``rotation_angle(q_o, q_g) <= success_angle`` [rad]."""
    return wp.length(p_g - p_o) <= success_distance and rotation_angle(q_o, q_g) <= success_angle
