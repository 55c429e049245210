"""Frame helpers shared by the kernels (``wp.func`` only, no launches).

Conventions (the whole project's): world Z-up, SI units, quaternions stored (x, y, z, w) as in Warp/Newton,
rotation matrices act on column vectors (``p_world = R_wb @ p_b``).
"""

import warp as wp


@wp.func
def yaw_quat(yaw: float):
    """Rotation about world +z by ``yaw`` [rad], as a (x, y, z, w) quaternion."""
    return wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), yaw)


@wp.func
def tilt_angle(q: wp.quat):
    """Angle [rad] between the body's +z axis and the world +z axis."""
    z_axis = wp.quat_rotate(q, wp.vec3(0.0, 0.0, 1.0))
    return wp.acos(wp.clamp(z_axis[2], -1.0, 1.0))


@wp.func
def rotation_angle(q_a: wp.quat, q_b: wp.quat):
    """Angle [rad] of the relative rotation between two orientations, in [0, pi]."""
    d = wp.abs(wp.dot(q_a, q_b))
    return 2.0 * wp.acos(wp.clamp(d, 0.0, 1.0))


@wp.func
def fork_rng(draw: int):
    """A random stream for a ``wp.func`` that draws, from ``draw = wp.randi(rng)`` taken by the caller.

    Warp passes the uint32 state to a ``wp.func`` by value: draws inside the function do not advance the
    caller's state, so the caller's next draw would repeat the function's first one. Builtins (``wp.randf``,
    ``wp.randi``) called in the caller's own scope do advance it. The offset matters: ``wp.rand_init(draw)``
    alone is the caller's own next state (Warp's PCG), i.e. the caller's stream shifted by one draw.
    """
    return wp.rand_init(draw, 1)


@wp.func
def next_rng(seed: int, rng_counter: wp.array(dtype=int), w: int):
    """A fresh random stream for world ``w``: counter-based, so runs are reproducible per seed."""
    n = rng_counter.shape[0]
    state = wp.rand_init(seed, w + n * rng_counter[w])
    rng_counter[w] = rng_counter[w] + 1
    return state


@wp.func
def heading_yaw(q: wp.quat):
    """Yaw [rad] of the body's x axis projected on the ground plane."""
    x_axis = wp.quat_rotate(q, wp.vec3(1.0, 0.0, 0.0))
    return wp.atan2(x_axis[1], x_axis[0])


@wp.func
def heading_roll_pitch(q: wp.quat, q_yaw: wp.quat):
    """(roll, pitch) [rad] of orientation ``q`` relative to its heading frame ``q_yaw`` (:func:`heading_yaw`):
    the tilt of the body's +z axis about the heading frame's x and y axes."""
    z_h = wp.quat_rotate(wp.quat_inverse(q_yaw) * q, wp.vec3(0.0, 0.0, 1.0))
    return wp.vec2(wp.atan2(-z_h[1], z_h[2]), wp.atan2(z_h[0], z_h[2]))
