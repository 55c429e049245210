"""Helpers shared by the kernels of both tasks (``wp.func`` only, no launches): a raw policy output clipped
for the action buffers, the torque of a joint's PD position drive, and the writes into the observation buffers
(a 3-vector, the actor's noisy copy of the critic's entries). Frames and units are the caller's.
"""

import warp as wp


@wp.func
def clipped_action(a: float, clip: float):
    """A raw policy output clipped to ``+-clip``; a non-finite one counts as zero."""
    if not wp.isfinite(a):
        return 0.0
    return wp.clamp(a, -clip, clip)


@wp.func
def pd_drive_torque(stiffness: float, damping: float, target: float, q: float, qd: float, limit: float):
    """Torque [N m] of a joint's PD position drive towards ``target`` [rad] at position ``q`` [rad] and velocity
    ``qd`` [rad/s], saturated at ``+-limit`` [N m] (the actuator's peak)."""
    return wp.clamp(stiffness * (target - q) - damping * qd, -limit, limit)


@wp.func
def write_vec(out: wp.array2d(dtype=float), w: int, k: int, v: wp.vec3):
    out[w, k + 0] = v[0]
    out[w, k + 1] = v[1]
    out[w, k + 2] = v[2]
    return k + 3


@wp.func
def add_noise(critic_obs: wp.array2d(dtype=float), policy_obs: wp.array2d(dtype=float), w: int,
              noise_scale: wp.array(dtype=float), noise_enabled: int, rng: wp.uint32):
    """The actor's observation: the first ``len(noise_scale)`` critic entries plus U(-s, s) noise where enabled."""
    for i in range(noise_scale.shape[0]):
        noise = float(0.0)
        if noise_enabled != 0:
            noise = wp.randf(rng, -1.0, 1.0) * noise_scale[i]
        policy_obs[w, i] = critic_obs[w, i] + noise
