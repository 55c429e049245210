"""Keypoints: the 8 vertices of an oriented bounding box (paper III-D, reward r1).

``K_o`` and ``K_g`` in the paper are the 24-d stacks of the object's and the goal's OBB vertices in
the world frame; both boxes share the object's dimensions.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def obb_vertex(p: wp.vec3, q: wp.quat, dims: wp.vec3, k: int):
    """Vertex ``k`` (0..7) of an oriented bounding box, world frame [m].

    ``dims`` are the full side lengths along the body axes; bit 0/1/2 of ``k`` selects the sign of
    the x/y/z half extent (``-`` when the bit is clear).
    """
    sx = float(2 * (k & 1) - 1)
    sy = float(2 * ((k >> 1) & 1) - 1)
    sz = float(2 * ((k >> 2) & 1) - 1)
    local = wp.vec3(0.5 * sx * dims[0], 0.5 * sy * dims[1], 0.5 * sz * dims[2])
    return p + wp.quat_rotate(q, local)


@wp.func
def keypoint_distance(p_o: wp.vec3, q_o: wp.quat, p_g: wp.vec3, q_g: wp.quat, dims: wp.vec3):
    """``||K_g - K_o||``: norm of the 24-d difference of the object and goal OBB keypoints [m]."""
    total = float(0.0)
    for k in range(8):
        d = obb_vertex(p_g, q_g, dims, k) - obb_vertex(p_o, q_o, dims, k)
        total += wp.dot(d, d)
    return wp.sqrt(total)

