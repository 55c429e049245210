"""Episode ends (paper III-B): time-out after the episode length, or an unrecoverable fall.

The object has toppled when its +z axis tilts beyond ``object_topple``; the robot has fallen when
its base tilts beyond ``base_tilt`` or drops below ``base_min_height`` (thresholds in
``TerminationConfig``). A world whose base or object pose or velocity is not finite (the solver diverged) ends
its episode too, as a failure: its next episode starts from a fresh state, where a NaN left in place would reach
the observations and stop the whole run.
"""

import warp as wp

from ..frames import tilt_angle
from .views import PushTask, RobotView

wp.set_module_options({"enable_backward": False})


@wp.struct
class TerminationParams:
    object_topple: float  # [rad]
    base_tilt: float  # [rad]
    base_min_height: float  # [m]
    max_episode_steps: int


@wp.kernel
def compute_terminations(
    robot: RobotView,
    task: PushTask,
    params: TerminationParams,
    success: wp.array(dtype=int),
    reset: wp.array(dtype=int),
    time_out: wp.array(dtype=int),
    episode_success: wp.array(dtype=int),
    episode_toppled: wp.array(dtype=int),
    episode_diverged: wp.array(dtype=int),
    episode_fallen: wp.array(dtype=int),
):
    """Advances the episode counter and flags worlds to reset; ``episode_*`` describe ended episodes.

    ``episode_success`` is the success flag at an episode's last step (-1 where no episode ended);
    ``episode_toppled``, ``episode_fallen`` and ``episode_diverged`` are 1 where an episode ended with the object
    toppled, with the robot fallen (both may be) or with the solver diverged.
    """
    w = wp.tid()
    task.episode_step[w] = task.episode_step[w] + 1
    x_b = robot.body_q[robot.base_body[w]]
    x_o = robot.body_q[robot.object_body[w]]
    v_b, v_o = robot.body_qd[robot.base_body[w]], robot.body_qd[robot.object_body[w]]
    diverged = not (wp.isfinite(wp.transform_get_translation(x_b)) and wp.isfinite(wp.transform_get_rotation(x_b))
                    and wp.isfinite(wp.transform_get_translation(x_o)) and wp.isfinite(wp.transform_get_rotation(x_o))
                    and wp.isfinite(v_b) and wp.isfinite(v_o))
    # A diverged world is neither toppled nor fallen: its angles are not numbers.
    toppled = not diverged and tilt_angle(wp.transform_get_rotation(x_o)) > params.object_topple
    fallen = not diverged and (tilt_angle(wp.transform_get_rotation(x_b)) > params.base_tilt
                               or wp.transform_get_translation(x_b)[2] < params.base_min_height)
    timed_out = task.episode_step[w] >= params.max_episode_steps
    done = toppled or fallen or timed_out or diverged
    reset[w] = wp.where(done, 1, 0)
    time_out[w] = wp.where(timed_out and not (toppled or fallen or diverged), 1, 0)
    episode_success[w] = wp.where(done, success[w], -1)
    episode_toppled[w] = wp.where(done and toppled, 1, 0)
    episode_diverged[w] = wp.where(diverged, 1, 0)
    episode_fallen[w] = wp.where(done and fallen, 1, 0)
