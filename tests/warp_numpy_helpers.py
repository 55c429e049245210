"""Shared by the kernel tests: numpy quaternion helpers and Warp structs built from numpy arrays."""

import numpy as np
import warp as wp

DEVICE = "cpu"


def quat_rotate(q, v):
    """Rotates ``v`` (..., 3) by unit quaternions ``q`` (..., 4) stored (x, y, z, w)."""
    u, w = q[..., :3], q[..., 3:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_rotate_inv(q, v):
    return quat_rotate(q * np.array([-1.0, -1.0, -1.0, 1.0]), v)


def random_quat(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def make_struct(cls, **values):
    """A Warp struct whose array fields are CPU copies of the given numpy arrays (dtype from the struct)."""
    s = cls()
    for name, value in values.items():
        kind = cls.vars[name].type
        if wp.types.is_array(kind):
            dtype = np.int32 if kind.dtype in (wp.int32, int) else np.float32
            value = wp.array(np.asarray(value, dtype=dtype), dtype=kind.dtype, device=DEVICE)
        elif kind is wp.vec3 or kind is wp.vec2:
            value = kind(*value)
        setattr(s, name, value)
    return s
