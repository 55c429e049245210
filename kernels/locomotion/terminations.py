"""Episode ends of the locomotion task: time-out after ``max_episode_steps``, or a fall (base tilt [rad] beyond
``base_tilt`` or base height [m] below ``base_min_height``, ``LeggedLimits``).
"""

import warp as wp

from .views import LeggedLimits, LeggedView, LocomotionTask

wp.set_module_options({"enable_backward": False})


@wp.kernel
def compute_terminations(
    view: LeggedView,
    task: LocomotionTask,
    limits: LeggedLimits,
    reset: wp.array(dtype=int),
    time_out: wp.array(dtype=int),
):
    """Advances the episode counter; a world resets after ``max_episode_steps`` (time-out) or a fall
    (base tilt beyond ``base_tilt`` or base below ``base_min_height``)."""
    w = wp.tid()
    task.episode_step[w] = task.episode_step[w] + 1
    x_b = view.body_q[view.base_body[w]]
    z_axis = wp.quat_rotate(wp.transform_get_rotation(x_b), wp.vec3(0.0, 0.0, 1.0))
    fallen = z_axis[2] < wp.cos(limits.base_tilt) or wp.transform_get_translation(x_b)[2] < limits.base_min_height
    timed_out = task.episode_step[w] >= limits.max_episode_steps
    reset[w] = wp.where(fallen or timed_out, 1, 0)
    time_out[w] = wp.where(timed_out and not fallen, 1, 0)
