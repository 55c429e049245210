"""Helpers shared by the kernels of both tasks (``wp.func`` only, no launches): a raw policy output clipped
for the action buffers, and the writes into the observation buffers (a 3-vector, the actor's noisy copy of the
critic's entries). Frames and units are the caller's.
"""

import warp as wp


@wp.func
def clipped_action(a: float, clip: float):
    """A raw policy output clipped to ``+-clip``; a non-finite one counts as zero."""
    if not wp.isfinite(a):
        return 0.0
    return wp.clamp(a, -clip, clip)


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
