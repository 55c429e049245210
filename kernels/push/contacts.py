"""Contact classification: which robot parts touch the object, and robot self-collisions.

Each shape has a role code (``shape_role``): ``ROLE_NONE`` (ground), ``ROLE_OBJECT``, ``ROLE_EE``
(the end-effector, the desired contact), ``ROLE_ROBOT`` (a robot part allowed to touch the
object), or the collision column ``c >= 0`` of a robot part that must not touch the object. Undesired collision columns (paper Table "Rewards and constraints",
18 in all): object vs base, the 8 leg segments and the shoulder, upper arm, elbow and forearm
(13 columns); the remaining 5 columns are self-collisions of an arm link with the base or legs,
stored per shape in ``shape_self_column``.
"""

import warp as wp

from .views import EE_CONTACT, PushTask

wp.set_module_options({"enable_backward": False})

ROLE_NONE = -1
ROLE_OBJECT = -2
ROLE_EE = -3
ROLE_ROBOT = -4  # a robot part whose contact with the object is allowed (wrist)


@wp.kernel
def classify_contacts(
    contact_count: wp.array(dtype=int),
    shape0: wp.array(dtype=int),
    shape1: wp.array(dtype=int),
    point0: wp.array(dtype=wp.vec3),
    point1: wp.array(dtype=wp.vec3),
    normal: wp.array(dtype=wp.vec3),
    margin0: wp.array(dtype=float),
    margin1: wp.array(dtype=float),
    shape_body: wp.array(dtype=int),
    shape_world: wp.array(dtype=int),
    shape_role: wp.array(dtype=int),
    shape_self_column: wp.array(dtype=int),
    body_q: wp.array(dtype=wp.transform),
    contact_distance: float,
    task: PushTask,
):
    """Marks ``task.contacts[w, column] = 1`` for every pair touching in the poses ``body_q`` (accumulates over the
    launches of a step; ``env.constraints.contacts_at_step_end`` decides which states of the step are classified)."""
    i = wp.tid()
    if i >= contact_count[0]:
        return
    a = shape0[i]
    b = shape1[i]
    if a < 0 or b < 0:
        return
    p_a = point0[i]
    p_b = point1[i]
    if shape_body[a] >= 0:
        p_a = wp.transform_point(body_q[shape_body[a]], p_a)
    if shape_body[b] >= 0:
        p_b = wp.transform_point(body_q[shape_body[b]], p_b)
    gap = wp.dot(normal[i], p_b - p_a) - margin0[i] - margin1[i]
    if gap > contact_distance:
        return
    role_a = shape_role[a]
    role_b = shape_role[b]
    w = wp.max(shape_world[a], shape_world[b])
    if w < 0:
        return
    if role_a == ROLE_OBJECT or role_b == ROLE_OBJECT:
        other = role_b
        if role_b == ROLE_OBJECT:
            other = role_a
        if other == ROLE_EE:
            task.contacts[w, EE_CONTACT] = 1
        elif other >= 0:
            task.contacts[w, other] = 1
        return
    # Robot self-collision: an arm link (which carries a self-collision column) against a robot part.
    if role_a != ROLE_NONE and role_b != ROLE_NONE:  # both robot shapes (arm-arm pairs are filtered)
        column = wp.max(shape_self_column[a], shape_self_column[b])
        if column >= 0:
            task.contacts[w, column] = 1
