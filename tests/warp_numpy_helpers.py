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


def quat_matrix(q):
    """(..., 3, 3) rotation matrices: the columns are the rotated basis vectors."""
    return np.stack([quat_rotate(q, np.broadcast_to(e, q.shape[:-1] + (3,))) for e in np.eye(3)], axis=-1)


def quat_mul(a, b):
    ua, wa, ub, wb = a[..., :3], a[..., 3:], b[..., :3], b[..., 3:]
    return np.concatenate([wa * ub + wb * ua + np.cross(ua, ub), wa * wb - np.sum(ua * ub, -1, keepdims=True)], -1)


def axis_angle_quat(axis, angle):
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    return np.concatenate([axis * np.sin(angle / 2)[..., None], np.cos(angle / 2)[..., None]], -1)


def as_f32(values):
    """Rounds the float buffers to float32 so that the references see exactly the kernels' inputs."""
    return {k: (v.astype(np.float32).astype(np.float64) if np.asarray(v).dtype.kind == "f" else v) for k, v in values.items()}


def close(actual, expected, rtol=1e-4, atol=1e-5, err_msg=""):
    np.testing.assert_allclose(actual, expected, rtol=rtol, atol=atol, err_msg=err_msg)


def arr(values, dtype=float):
    values = np.asarray(values, dtype=np.int32 if dtype is int else np.float32)
    return wp.array(values, dtype=dtype, device=DEVICE)


def launch(kernel, dim, *inputs):
    wp.launch(kernel, dim=dim, inputs=list(inputs), device=DEVICE)
