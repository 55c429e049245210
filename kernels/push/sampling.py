"""Reset sampling and domain randomisation (paper III-B, III-E), plus random base pushes.

Every world flagged in ``reset`` draws a new episode: object shape, dimensions, mass, CoM and
friction; object at the origin with a random yaw; goal uniform (by area) in the annulus (disc)
``goal_radius`` with a random yaw; robot base uniform (by area) in the annulus ``robot_radius`` with a
random yaw at nominal height (polar angles within the ``*_bearing`` ranges); arm
joints uniform around the default; reach target uniform on the object's vertical surfaces. Training
curricula may ask for less of the goal's yaw change or draw a share of the goals near the object's start.
"""

import warp as wp

from ..frames import fork_rng, next_rng, yaw_quat
from .views import NUM_ACTIONS, NUM_ARM_JOINTS, NUM_BASE_COMMANDS, CONTACT_COLUMNS, PushTask, RobotView

wp.set_module_options({"enable_backward": False})

SHAPE_CUBOID = 0
SHAPE_CYLINDER = 1


@wp.struct
class SamplingParams:
    robot_radius: wp.vec2  # [m]
    robot_bearing: wp.vec2  # polar angle of the base position [rad]
    goal_bearing: wp.vec2  # polar angle of the goal position [rad]
    object_yaw: wp.vec2  # [rad]
    goal_yaw: wp.vec2  # [rad]
    base_yaw: wp.vec2  # [rad]
    surface_target: int  # 0: reach target at the centroid (ablation)
    friction: wp.vec2  # combined object-floor coefficient
    ground_friction: float  # the floor's own coefficient (Newton averages the two)
    com_fraction_lo: wp.vec3
    com_fraction_hi: wp.vec3
    size_lo: wp.vec3  # [m]
    size_hi: wp.vec3  # [m]
    cylinder_probability: float
    base_mass_offset: wp.vec2  # [kg]
    push_interval_steps: wp.vec2  # control steps
    push_velocity: float  # [m/s]
    arm_joint_noise: float  # [rad]
    base_height: float  # [m]
    frozen_joint_value: float  # [rad] of the 6th arm joint


@wp.func
def uniform(u: float, r: wp.vec2):
    """``u`` in [0, 1) (a ``wp.randf(rng)`` of the caller) mapped onto ``[r[0], r[1])``."""
    return r[0] + u * (r[1] - r[0])


@wp.func
def polar_pose(rng: wp.uint32, radius: wp.vec2, bearing: wp.vec2, yaw: wp.vec2):
    """(x, y, yaw): position uniform by area in the annulus sector, yaw uniform. ``rng``: a forked stream
    (``frames.fork_rng``)."""
    r = wp.sqrt(wp.randf(rng, radius[0] * radius[0], radius[1] * radius[1]))
    a = uniform(wp.randf(rng), bearing)
    return wp.vec3(r * wp.cos(a), r * wp.sin(a), uniform(wp.randf(rng), yaw))


@wp.func
def cuboid_inertia(m: float, d: wp.vec3):
    return wp.vec3(
        m / 12.0 * (d[1] * d[1] + d[2] * d[2]),
        m / 12.0 * (d[0] * d[0] + d[2] * d[2]),
        m / 12.0 * (d[0] * d[0] + d[1] * d[1]),
    )


@wp.func
def cylinder_inertia(m: float, d: wp.vec3):
    r = 0.5 * d[0]
    side = m / 12.0 * (3.0 * r * r + d[2] * d[2])
    return wp.vec3(side, side, 0.5 * m * r * r)


@wp.func
def surface_point(rng: wp.uint32, shape: int, d: wp.vec3):
    """A point uniform (by area) on the vertical surfaces of the object, object frame [m]. ``rng``: a forked
    stream (``frames.fork_rng``)."""
    z = wp.randf(rng, -0.5 * d[2], 0.5 * d[2])
    if shape == SHAPE_CYLINDER:
        angle = wp.randf(rng, -wp.pi, wp.pi)
        return wp.vec3(0.5 * d[0] * wp.cos(angle), 0.5 * d[0] * wp.sin(angle), z)
    # Pick a face with probability proportional to its area (perimeter share), then a point on it.
    s = wp.randf(rng, 0.0, 2.0 * (d[0] + d[1]))
    if s < d[1]:
        return wp.vec3(0.5 * d[0], s - 0.5 * d[1], z)
    s -= d[1]
    if s < d[1]:
        return wp.vec3(-0.5 * d[0], s - 0.5 * d[1], z)
    s -= d[1]
    if s < d[0]:
        return wp.vec3(s - 0.5 * d[0], 0.5 * d[1], z)
    s -= d[0]
    return wp.vec3(s - 0.5 * d[0], -0.5 * d[1], z)


@wp.struct
class EpisodeSpec:
    """Per-world description of an episode: drawn by ``sample_episodes`` or written by the user
    (evaluation scenarios), and applied by ``start_episodes``."""

    shape: wp.array(dtype=int)  # SHAPE_CUBOID or SHAPE_CYLINDER
    dims: wp.array(dtype=wp.vec3)  # full side lengths [m] (cylinder: diameter, diameter, height)
    mass: wp.array(dtype=float)  # [kg]
    com_o: wp.array(dtype=wp.vec3)  # CoM in the object frame [m]
    friction: wp.array(dtype=float)  # combined object-floor coefficient
    object_yaw: wp.array(dtype=float)  # [rad]; the object stands at the env origin
    reach_target_o: wp.array(dtype=wp.vec3)  # object frame [m]
    goal: wp.array(dtype=wp.vec3)  # (x [m], y [m], yaw [rad])
    base: wp.array(dtype=wp.vec3)  # (x [m], y [m], yaw [rad])
    arm_q: wp.array2d(dtype=float)  # (N, 5) initial arm joints [rad]
    base_mass_offset: wp.array(dtype=float)  # [kg]
    first_push_step: wp.array(dtype=int)  # control steps until the first random push


@wp.kernel
def sample_episodes(
    reset: wp.array(dtype=int),
    seed: int,
    params: SamplingParams,
    goal_difficulty: wp.array(dtype=float),
    object_mass: wp.array(dtype=wp.vec2),
    goal_radius: wp.array(dtype=wp.vec2),
    near_goal: wp.array(dtype=wp.vec3),
    behind_start: wp.array(dtype=wp.vec2),
    task: PushTask,
    spec: EpisodeSpec,
    near_goal_start: wp.array(dtype=int),
    near_goal_ended: wp.array(dtype=int),
):
    """Draws the episode of every world with ``reset[w] != 0`` into ``spec`` (paper III-B, III-E).

    ``goal_difficulty[0]`` in [0, 1] (a training curriculum; 1 is the paper's task) scales the
    reorientation the goal asks for: goal yaw ``yaw_object + d * wrap(yaw_goal - yaw_object)``; the
    goal position is always the drawn one (a position scaled toward the start would make waiting
    next to the object a success). At 1 the goal is exactly the drawn one.

    ``object_mass[0]`` = (low, high) [kg]: the range the object's mass is drawn from, uniform (the configured
    ``randomization.mass`` unless a training curriculum narrows it).

    ``goal_radius[0]`` = (low, high) [m]: the annulus the goal position is drawn from, uniform by area (the configured
    ``sampling.goal_radius`` unless a training curriculum narrows it).

    ``near_goal[0]`` = (share, radius [m], max_yaw [rad]) (a training-only start-state curriculum; share 0 is the
    paper's task): with probability ``share`` a world's goal is instead drawn near the object's start, uniform (by
    area) in the disc ``radius`` around the env origin, with yaw ``yaw_object + U(-max_yaw, max_yaw)``.
    ``near_goal_start[w]`` is 1 for such an episode, 0 otherwise; ``near_goal_ended[w]`` receives the flag of the
    episode this reset ends (the statistics of ended episodes are read after their world was reset).

    ``behind_start[0]`` = (share, spread [rad]) (a training-only start-state curriculum; share 0 is the paper's task):
    with probability ``share`` the robot instead starts behind the object as seen from the goal, at a bearing
    within ``spread`` of the one opposite the goal's, in the same radius range, facing the object within ``spread``:
    a push toward the goal is then one walk forward.
    """
    w = wp.tid()
    if reset[w] == 0:
        return
    rng = next_rng(seed, task.rng_counter, w)
    shape = wp.where(wp.randf(rng) < params.cylinder_probability, SHAPE_CYLINDER, SHAPE_CUBOID)
    d = wp.vec3(
        wp.randf(rng, params.size_lo[0], params.size_hi[0]),
        wp.randf(rng, params.size_lo[1], params.size_hi[1]),
        wp.randf(rng, params.size_lo[2], params.size_hi[2]),
    )
    if shape == SHAPE_CYLINDER:
        d = wp.vec3(d[0], d[0], d[2])
    spec.shape[w] = shape
    spec.dims[w] = d
    spec.mass[w] = uniform(wp.randf(rng), object_mass[0])
    spec.com_o[w] = wp.vec3(
        wp.randf(rng, params.com_fraction_lo[0], params.com_fraction_hi[0]) * d[0],
        wp.randf(rng, params.com_fraction_lo[1], params.com_fraction_hi[1]) * d[1],
        wp.randf(rng, params.com_fraction_lo[2], params.com_fraction_hi[2]) * d[2],
    )
    spec.friction[w] = uniform(wp.randf(rng), params.friction)
    object_yaw = uniform(wp.randf(rng), params.object_yaw)
    spec.object_yaw[w] = object_yaw
    spec.reach_target_o[w] = wp.vec3(0.0)
    if params.surface_target != 0:
        spec.reach_target_o[w] = surface_point(fork_rng(wp.randi(rng)), shape, d)
    # Goal and robot uniform by area in their annuli.
    goal = polar_pose(fork_rng(wp.randi(rng)), goal_radius[0], params.goal_bearing, params.goal_yaw)
    difficulty = goal_difficulty[0]
    yaw_change = wp.atan2(wp.sin(goal[2] - object_yaw), wp.cos(goal[2] - object_yaw))
    goal_yaw = wp.where(difficulty < 1.0, object_yaw + difficulty * yaw_change, goal[2])
    spec.goal[w] = wp.vec3(goal[0], goal[1], goal_yaw)
    spec.base[w] = polar_pose(fork_rng(wp.randi(rng)), params.robot_radius, params.robot_bearing, params.base_yaw)
    for j in range(NUM_ARM_JOINTS):
        spec.arm_q[w, j] = task.arm_default[j] + wp.randf(rng, -params.arm_joint_noise, params.arm_joint_noise)
    spec.base_mass_offset[w] = uniform(wp.randf(rng), params.base_mass_offset)
    spec.first_push_step[w] = int(uniform(wp.randf(rng), params.push_interval_steps))
    # Drawn last, so that every draw above is the paper's whatever the share (share 0: today's episodes exactly).
    near = near_goal[0]
    near_goal_ended[w] = near_goal_start[w]
    near_goal_start[w] = 0
    if wp.randf(rng) < near[0]:
        yaw_range = wp.vec2(object_yaw - near[2], object_yaw + near[2])
        spec.goal[w] = polar_pose(fork_rng(wp.randi(rng)), wp.vec2(0.0, near[1]), wp.vec2(-wp.pi, wp.pi), yaw_range)
        near_goal_start[w] = 1
    # Drawn after the goal, which it depends on (share 0: the episodes above exactly).
    behind = behind_start[0]
    if wp.randf(rng) < behind[0]:
        goal_xy = spec.goal[w]
        opposite_goal = wp.atan2(goal_xy[1], goal_xy[0]) + wp.pi
        base = polar_pose(fork_rng(wp.randi(rng)), params.robot_radius,
                          wp.vec2(opposite_goal - behind[1], opposite_goal + behind[1]), wp.vec2(0.0, 0.0))
        facing_object = wp.atan2(-base[1], -base[0])
        spec.base[w] = wp.vec3(base[0], base[1], facing_object + uniform(wp.randf(rng), wp.vec2(-behind[1], behind[1])))


@wp.func
def write_free_joint(joint_q: wp.array(dtype=float), start: int, p: wp.vec3, q: wp.quat):
    for i in range(3):
        joint_q[start + i] = p[i]
    for i in range(4):
        joint_q[start + 3 + i] = q[i]


@wp.kernel
def start_episodes(
    reset: wp.array(dtype=int),
    spec: EpisodeSpec,
    params: SamplingParams,
    robot: RobotView,
    task: PushTask,
    base_default: wp.array(dtype=float),
    base_mass_nominal: float,
    robot_q_start: wp.array(dtype=int),
    object_q_start: wp.array(dtype=int),
    joint_q: wp.array(dtype=float),
    body_mass: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    variant: wp.array(dtype=int),
):
    """Applies ``spec`` to every world with ``reset[w] != 0``; ``variant[w]`` = -1 elsewhere.

    Writes the task buffers and the generalized coordinates of the robot (free base at nominal
    height + 6 arm joints) and the object (free joint, resting on the floor) into ``joint_q``; the
    environment then selects the object variant and runs forward kinematics.
    """
    w = wp.tid()
    variant[w] = -1
    if reset[w] == 0:
        return
    shape = spec.shape[w]
    d = spec.dims[w]
    m = spec.mass[w]
    task.object_shape[w] = shape
    task.object_dims[w] = d
    task.object_mass[w] = m
    task.object_com_o[w] = spec.com_o[w]
    task.object_inertia[w] = wp.where(shape == SHAPE_CYLINDER, cylinder_inertia(m, d), cuboid_inertia(m, d))
    # Newton combines two coefficients by their mean.
    task.object_friction[w] = 2.0 * spec.friction[w] - params.ground_friction
    task.reach_target_o[w] = spec.reach_target_o[w]
    goal = spec.goal[w]
    task.goal_pos[w] = wp.vec3(goal[0], goal[1], 0.5 * d[2])
    task.goal_quat[w] = yaw_quat(goal[2])
    variant[w] = shape

    write_free_joint(joint_q, object_q_start[w], wp.vec3(0.0, 0.0, 0.5 * d[2]), yaw_quat(spec.object_yaw[w]))
    base = spec.base[w]
    write_free_joint(joint_q, robot_q_start[w], wp.vec3(base[0], base[1], params.base_height), yaw_quat(base[2]))
    a0 = robot.arm_q_start[w]
    for j in range(NUM_ARM_JOINTS):
        joint_q[a0 + j] = spec.arm_q[w, j]
        task.arm_command[w, j] = spec.arm_q[w, j]
    joint_q[a0 + NUM_ARM_JOINTS] = params.frozen_joint_value
    base_mass = base_mass_nominal + spec.base_mass_offset[w]
    body_mass[robot.base_body[w]] = base_mass
    body_inv_mass[robot.base_body[w]] = 1.0 / base_mass

    for i in range(NUM_ACTIONS):
        task.actions[w, i] = 0.0
        task.last_actions[w, i] = 0.0
    for i in range(NUM_BASE_COMMANDS):
        task.base_command[w, i] = base_default[i]
        task.base_command_filtered[w, i] = base_default[i]
    for c in range(CONTACT_COLUMNS):
        task.contacts[w, c] = 0
    task.episode_step[w] = 0
    task.reach_reward_held[w] = 0.0
    task.next_push_step[w] = spec.first_push_step[w]


@wp.kernel
def zero_velocities(reset: wp.array(dtype=int), robot_qd_start: wp.array(dtype=int), robot_qd_count: int,
                    object_qd_start: wp.array(dtype=int), joint_qd: wp.array(dtype=float)):
    """Zeroes the generalized velocities of the robot and the object of reset worlds."""
    w = wp.tid()
    if reset[w] == 0:
        return
    for i in range(robot_qd_count):
        joint_qd[robot_qd_start[w] + i] = 0.0
    for i in range(6):
        joint_qd[object_qd_start[w] + i] = 0.0


@wp.kernel
def apply_object_properties(
    reset: wp.array(dtype=int),
    task: PushTask,
    object_body: wp.array(dtype=int),
    object_shape_index: wp.array(dtype=int),
    shape_scale: wp.array(dtype=wp.vec3),
    shape_collision_radius: wp.array(dtype=float),
    shape_aabb_lower: wp.array(dtype=wp.vec3),
    shape_aabb_upper: wp.array(dtype=wp.vec3),
    shape_mu: wp.array(dtype=float),
    body_mass: wp.array(dtype=float),
    body_inv_mass: wp.array(dtype=float),
    body_com: wp.array(dtype=wp.vec3),
    body_inertia: wp.array(dtype=wp.mat33),
    body_inv_inertia: wp.array(dtype=wp.mat33),
):
    """Writes the sampled geometry, friction and mass properties into the Newton model.

    Runs after ``Model.select_body_variants``, which restores the prototype's properties. Shape
    scale follows Newton's primitives: box half extents (hx, hy, hz); cylinder (radius, half height).
    """
    w = wp.tid()
    if reset[w] == 0:
        return
    s = object_shape_index[w]
    d = task.object_dims[w]
    half = 0.5 * d
    if task.object_shape[w] == SHAPE_CYLINDER:
        shape_scale[s] = wp.vec3(half[0], half[2], 0.0)
        shape_collision_radius[s] = wp.sqrt(half[0] * half[0] + half[2] * half[2])
    else:
        shape_scale[s] = half
        shape_collision_radius[s] = wp.length(half)
    shape_aabb_lower[s] = -half
    shape_aabb_upper[s] = half
    shape_mu[s] = task.object_friction[w]
    b = object_body[w]
    m = task.object_mass[w]
    body_mass[b] = m
    body_inv_mass[b] = 1.0 / m
    body_com[b] = task.object_com_o[w]
    inertia = task.object_inertia[w]
    body_inertia[b] = wp.diag(inertia)
    body_inv_inertia[b] = wp.diag(wp.vec3(1.0 / inertia[0], 1.0 / inertia[1], 1.0 / inertia[2]))


@wp.kernel
def apply_pushes(
    seed: int,
    params: SamplingParams,
    robot: RobotView,
    task: PushTask,
    body_qd: wp.array(dtype=wp.spatial_vector),
):
    """Random base pushes every 7-10 s (paper III-E): a uniform horizontal velocity change."""
    w = wp.tid()
    if task.episode_step[w] < task.next_push_step[w]:
        return
    rng = next_rng(seed, task.rng_counter, w)
    b = robot.base_body[w]
    dv = wp.vec3(
        wp.randf(rng, -params.push_velocity, params.push_velocity),
        wp.randf(rng, -params.push_velocity, params.push_velocity),
        0.0,
    )
    qd = body_qd[b]
    body_qd[b] = wp.spatial_vector(wp.spatial_top(qd) + dv, wp.spatial_bottom(qd))
    task.next_push_step[w] = task.episode_step[w] + int(uniform(wp.randf(rng), params.push_interval_steps))
