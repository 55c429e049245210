"""Kernels of the locomotion task (issue 8): a legged robot tracks the 6D base command of the push policy.

The command ``(vx, vy, yaw rate, roll, pitch, height)`` is the push policy's action space (paper III-C):
vx, vy [m/s] in the heading frame, yaw rate [rad/s] about world z, roll and pitch [rad] of the base
relative to its heading frame, height [m] of the base origin above the ground. The policy outputs 12
leg joint position offsets: ``q_leg^target = q_leg^default + action_scale * a``; the joints' PD drives
(stiffness ``k_p``, damping ``k_d``, effort limit from ``robot_legged.usda``) produce
``tau = clip(k_p (q^target - q) - k_d qd, -effort, effort)``.

Actor observation (61), the layout of the runtime's locomotion ONNX (``dynpush.runtime.locomotion_layout.LOCOMOTION_TERMS``,
in that order, scale 1): ``base_linear_velocity_b`` (3), ``base_angular_velocity_b`` (3),
``projected_gravity_b`` (3, ``R_b^T (0, 0, -1)``), ``base_command`` (6), ``leg_joint_position`` (12,
``q - q_default``), ``leg_joint_velocity`` (12), ``last_leg_actions`` (12), ``arm_joint_position`` (5,
``q - q_default``), ``arm_joint_velocity`` (5). Critic (67, noiseless): the same, then ``base_height``
(1), ``foot_contact`` (4) and ``base_mass_offset`` (1).

Rewards (``REWARD_TERMS``): ``w exp(-e^2 / sigma)`` for the heading-frame velocity, the yaw rate, the attitude
and the height, legged_gym's stepping reward ``w sum_feet (t_air - t_target)`` at touchdowns while the
command asks to move, and legged_gym's penalties on the action rate ``-w sum_j (a_t - a_{t-1})^2``, the base's
vertical velocity ``-w v_z^2`` and its roll and pitch rates ``-w (omega_x,b^2 + omega_y,b^2)``
(``compute_rewards``).

Constraints (CaT, violated where > 0), columns in ``CONSTRAINT_GROUPS`` order: leg joint torque
``|tau| - tau_nominal`` (12), leg joint velocity ``|qd| - qd_max`` (12), leg joint acceleration
``|qd_t - qd_{t-1}| / dt - qdd_max`` (12), leg action rate ``|a_t - a_{t-1}| / dt - rate_max`` (12),
collision (5: the base box and each leg's knee and shank within ``collision_margin`` of the ground,
the ground being the plane z = 0), foot air time ``t_min - t_air`` at each touchdown (4), foot contact
force ``|F_foot| - F_max`` (4: the ground's contact force on each lower leg, foot sphere and shank, at the
control step's last substep, measured by the solver; ``gather_foot_forces``).

Disturbances (``apply_events``, scaled by the training curriculum's ``disturbance_scale``): random arm targets,
base pushes, and a horizontal force on the end-effector point, the push-back of a pushed object
(``sample_ee_force``, applied as a wrench by ``write_ee_force``).

Frames: ``_w`` world, ``_b`` base, ``_h`` heading frame (base yaw only). Legs LF, RF, LH, RH; joints HAA,
HFE, KFE per leg (``dynpush.assets_usd.LEG_JOINT_NAMES``).
"""

import warp as wp

from dynpush.runtime.locomotion_layout import LOCOMOTION_TERMS, NUM_LEG_JOINTS
from dynpush.runtime.observation import NUM_ARM_JOINTS

from .actions import clipped_action
from .frames import fork_rng, heading_roll_pitch, heading_yaw, next_rng, yaw_quat
from .observations import add_noise, write_vec

wp.set_module_options({"enable_backward": False})

NUM_FEET = 4
NUM_COMMANDS = 6
POLICY_TERMS = tuple(LOCOMOTION_TERMS.items())
PRIVILEGED_TERMS = (("base_height", 1), ("foot_contact", NUM_FEET), ("base_mass_offset", 1))
NUM_POLICY_OBS = sum(size for _, size in POLICY_TERMS)
NUM_CRITIC_OBS = NUM_POLICY_OBS + sum(size for _, size in PRIVILEGED_TERMS)
CONSTRAINT_GROUPS = (
    ("leg_joint_torque", NUM_LEG_JOINTS),
    ("leg_joint_velocity", NUM_LEG_JOINTS),
    ("leg_joint_acceleration", NUM_LEG_JOINTS),
    ("leg_action_rate", NUM_LEG_JOINTS),
    ("collision", 1 + NUM_FEET),
    ("foot_air_time", NUM_FEET),
    ("foot_contact_force", NUM_FEET),
)
NUM_CONSTRAINTS = sum(size for _, size in CONSTRAINT_GROUPS)
REWARD_TERMS = ("linear_velocity", "yaw_rate", "attitude", "height", "feet_air_time", "action_rate",
                "base_vertical_velocity", "base_roll_pitch_rate")
vec12 = wp.types.vector(length=NUM_LEG_JOINTS, dtype=float)
vec6 = wp.types.vector(length=NUM_COMMANDS, dtype=float)
NUM_REWARD_TERMS = len(REWARD_TERMS)
reward_vec = wp.types.vector(length=NUM_REWARD_TERMS, dtype=float)


@wp.struct
class LeggedView:
    """Newton state of the legged robots and the indices that locate each world's robot in it."""

    body_q: wp.array(dtype=wp.transform)  # world frame
    body_qd: wp.array(dtype=wp.spatial_vector)  # (v_com_w, omega_w)
    joint_q: wp.array(dtype=float)
    joint_qd: wp.array(dtype=float)
    base_body: wp.array(dtype=int)  # (N,)
    base_q_start: wp.array(dtype=int)  # (N,) joint_q index of the free joint (p, quat xyzw)
    base_qd_start: wp.array(dtype=int)  # (N,) joint_qd index of the free joint
    robot_qd_count: int  # generalized velocities of one robot
    leg_q: wp.array2d(dtype=int)  # (N, 12) joint_q index of each leg joint, LEG_JOINT_NAMES order
    leg_qd: wp.array2d(dtype=int)  # (N, 12)
    arm_q: wp.array2d(dtype=int)  # (N, 6) joint_q index of each arm joint (the last one is frozen)
    arm_qd: wp.array2d(dtype=int)  # (N, 6)
    shank_body: wp.array2d(dtype=int)  # (N, 4) the shank of each leg (carries knee, shank and foot)


@wp.struct
class LocomotionTask:
    """Per-world buffers of the locomotion task."""

    command: wp.array2d(dtype=float)  # (N, 6) absolute 6D base command
    actions: wp.array2d(dtype=float)  # (N, 12) a_t, clipped
    last_actions: wp.array2d(dtype=float)  # (N, 12) a_{t-1}
    leg_target: wp.array2d(dtype=float)  # (N, 12) [rad]
    leg_velocity_last: wp.array2d(dtype=float)  # (N, 12) qd of the previous control step [rad/s]
    arm_target: wp.array2d(dtype=float)  # (N, 6) [rad], random arm motions
    foot_contact: wp.array2d(dtype=int)  # (N, 4) 1 where the foot touches the ground this step
    foot_air_time: wp.array2d(dtype=float)  # (N, 4) [s] since the foot left the ground
    touchdown_air_time: wp.array2d(dtype=float)  # (N, 4) [s] air time ended by a touchdown this step, else -1
    base_mass_offset: wp.array(dtype=float)  # (N,) [kg] drawn once per world when the environment is built
    ee_force_h: wp.array2d(dtype=float)  # (N, 3) [N] external force on the end-effector point, heading frame
    episode_step: wp.array(dtype=int)
    next_command_step: wp.array(dtype=int)
    next_arm_step: wp.array(dtype=int)
    next_push_step: wp.array(dtype=int)
    next_ee_force_step: wp.array(dtype=int)
    rng_counter: wp.array(dtype=int)


@wp.struct
class LocomotionParams:
    """Actions, command sampling and randomization (``LocomotionEnvConfig``)."""

    leg_default: wp.array(dtype=float)  # (12,) [rad]
    arm_default: wp.array(dtype=float)  # (6,) [rad]
    arm_lower: wp.array(dtype=float)  # (6,) [rad]
    arm_upper: wp.array(dtype=float)  # (6,) [rad]
    action_scale: float  # [rad] per unit action
    clip: float
    command_lower: wp.array(dtype=float)  # (6,)
    command_upper: wp.array(dtype=float)  # (6,)
    standing_probability: float  # share of commands with zero vx, vy and yaw rate
    command_interval: wp.vec2  # [steps] between command changes
    arm_amplitude: wp.array(dtype=float)  # (5,) [rad] arm targets uniform within default +- amplitude (clipped to the limits)
    arm_interval: wp.vec2  # [steps] between arm target changes
    push_interval: wp.vec2  # [steps] between base pushes
    push_velocity: float  # [m/s] max horizontal velocity change of a push
    ee_force_interval: wp.vec2  # [steps] between end-effector force changes
    ee_force_probability: float  # share of the end-effector force draws that are not zero
    ee_force_max: float  # [N] magnitude uniform in [0, ee_force_max]
    ee_force_spread: float  # [rad] direction uniform within +- spread of the heading frame's -x, horizontal
    disturbance_scale: wp.array(dtype=float)  # (1,) in [0, 1]: multiplies arm_amplitude, push_velocity and ee_force_max
    start_height: float  # [m] base height at reset
    leg_position_noise: float  # [rad] leg joints uniform within default +- noise at reset


@wp.struct
class LeggedLimits:
    """Drive law, contact geometry and constraint limits."""

    stiffness: wp.array(dtype=float)  # (12,) [N m/rad]
    damping: wp.array(dtype=float)  # (12,) [N m s/rad]
    effort_limit: wp.array(dtype=float)  # (12,) [N m] the drives' peak torque
    nominal_torque: wp.array(dtype=float)  # (12,) [N m] constraint limit
    velocity_limit: wp.array(dtype=float)  # (12,) [rad/s] constraint limit
    acceleration_limit: float  # [rad/s^2]
    action_rate_limit: float  # [1/s] of raw action units
    air_time_min: float  # [s]
    foot_force_limit: float  # [N]
    control_dt: float  # [s]
    foot_offset: wp.vec3  # foot sphere centre in the shank frame [m]
    foot_radius: float  # [m]
    contact_margin: float  # [m] a foot within this of the ground counts as touching
    knee_radius: float  # [m] thigh capsule radius about the knee (the shank frame origin)
    shank_end: wp.vec3  # lower cap centre of the shank capsule in the shank frame [m]
    shank_radius: float  # [m]
    base_half_extents: wp.vec3  # [m] of the base box collider, centred on the base frame
    collision_margin: float  # [m] clearance below which a part counts as touching the ground
    base_tilt: float  # [rad] termination
    base_min_height: float  # [m] termination
    max_episode_steps: int


@wp.struct
class LocomotionRewardParams:
    """Tracking kernels ``exp(-e^2 / sigma)``, the stepping reward and the weights."""

    sigma_linear_velocity: float  # [m^2/s^2]
    sigma_yaw_rate: float  # [rad^2/s^2]
    sigma_attitude: float  # [rad^2]
    sigma_height: float  # [m^2]
    air_time_target: float  # [s]
    moving_command: float  # the stepping reward counts while |(vx, vy)| + |yaw rate| exceeds this
    weights: wp.array(dtype=float)  # (NUM_REWARD_TERMS,) REWARD_TERMS order


@wp.func
def leg_torque(view: LeggedView, task: LocomotionTask, limits: LeggedLimits, w: int, j: int):
    """Torque [N m] of leg joint ``j`` under its PD drive towards ``task.leg_target``."""
    q = view.joint_q[view.leg_q[w, j]]
    qd = view.joint_qd[view.leg_qd[w, j]]
    tau = limits.stiffness[j] * (task.leg_target[w, j] - q) - limits.damping[j] * qd
    return wp.clamp(tau, -limits.effort_limit[j], limits.effort_limit[j])


@wp.func
def leg_torque_excess(view: LeggedView, task: LocomotionTask, limits: LeggedLimits, w: int, j: int):
    """Leg-torque constraint value ``|tau_j| - tau_nominal_j`` [N m] (violated where > 0)."""
    return wp.abs(leg_torque(view, task, limits, w, j)) - limits.nominal_torque[j]


@wp.kernel
def write_leg_torque_constraints(view: LeggedView, task: LocomotionTask, limits: LeggedLimits,
                                 constraints: wp.array2d(dtype=float), first_column: int):
    """The 12 leg-torque constraint values into ``constraints[:, first_column:first_column + 12]`` (the legged
    push task's leg-torque columns)."""
    w = wp.tid()
    for j in range(NUM_LEG_JOINTS):
        constraints[w, first_column + j] = leg_torque_excess(view, task, limits, w, j)


@wp.func
def heading_velocities(q_b: wp.quat, qd_b: wp.spatial_vector):
    """(vx_h, vy_h, yaw rate): base velocity in the heading frame [m/s] and angular velocity about world z [rad/s]."""
    v_h = wp.quat_rotate_inv(yaw_quat(heading_yaw(q_b)), wp.spatial_top(qd_b))
    return wp.vec3(v_h[0], v_h[1], wp.spatial_bottom(qd_b)[2])


@wp.func
def sample_command(rng: wp.uint32, params: LocomotionParams, task: LocomotionTask, w: int):
    """A new command for world ``w``; ``rng``: a forked stream (``frames.fork_rng``)."""
    standing = wp.randf(rng) < params.standing_probability
    for i in range(NUM_COMMANDS):
        value = wp.randf(rng, params.command_lower[i], params.command_upper[i])
        if standing and i < 3:
            value = 0.0
        task.command[w, i] = value


@wp.func
def sample_arm_target(rng: wp.uint32, params: LocomotionParams, task: LocomotionTask, w: int):
    """A new arm target for world ``w``; ``rng``: a forked stream (``frames.fork_rng``)."""
    for j in range(NUM_ARM_JOINTS):
        amplitude = params.arm_amplitude[j] * params.disturbance_scale[0]
        target = params.arm_default[j] + wp.randf(rng, -amplitude, amplitude)
        task.arm_target[w, j] = wp.clamp(target, params.arm_lower[j], params.arm_upper[j])
    task.arm_target[w, NUM_ARM_JOINTS] = params.arm_default[NUM_ARM_JOINTS]


@wp.func
def sample_ee_force(rng: wp.uint32, params: LocomotionParams, task: LocomotionTask, w: int):
    """A new end-effector force for world ``w`` (heading frame); ``rng``: a forked stream (``frames.fork_rng``)."""
    force = wp.vec3(0.0, 0.0, 0.0)
    if wp.randf(rng) < params.ee_force_probability:
        magnitude = wp.randf(rng, 0.0, params.ee_force_max * params.disturbance_scale[0])
        angle = wp.pi + wp.randf(rng, -params.ee_force_spread, params.ee_force_spread)
        force = wp.vec3(magnitude * wp.cos(angle), magnitude * wp.sin(angle), 0.0)
    for i in range(3):
        task.ee_force_h[w, i] = force[i]


@wp.func
def steps_in(u: float, interval: wp.vec2):
    """``u`` in [0, 1) (a ``wp.randf(rng)`` of the caller) mapped onto a whole number of steps in ``interval``."""
    return int(interval[0] + u * (interval[1] - interval[0]))


@wp.func
def reset_legs(params: LocomotionParams, view: LeggedView, task: LocomotionTask, w: int, noise: vec12):
    """Legs of world ``w`` at their default plus ``noise`` [rad], targets there, no action history, feet down."""
    for j in range(NUM_LEG_JOINTS):
        q = params.leg_default[j] + noise[j]
        view.joint_q[view.leg_q[w, j]] = q
        task.leg_target[w, j] = q
        task.leg_velocity_last[w, j] = 0.0
        task.actions[w, j] = 0.0
        task.last_actions[w, j] = 0.0
    for f in range(NUM_FEET):
        task.foot_contact[w, f] = 1
        task.foot_air_time[w, f] = 0.0
        task.touchdown_air_time[w, f] = -1.0


@wp.kernel
def start_episodes(
    reset: wp.array(dtype=int),
    seed: int,
    params: LocomotionParams,
    view: LeggedView,
    task: LocomotionTask,
):
    """Starts a new episode in every world with ``reset[w] != 0``.

    Base at the origin, ``start_height`` above the ground, uniform yaw; legs at their default plus
    uniform noise, the arm at its default; all velocities zero; no end-effector force; a new command,
    arm target and event schedule. The environment runs forward kinematics afterwards.
    """
    w = wp.tid()
    if reset[w] == 0:
        return
    rng = next_rng(seed, task.rng_counter, w)
    q0 = view.base_q_start[w]
    pose = wp.transform(wp.vec3(0.0, 0.0, params.start_height), yaw_quat(wp.randf(rng, -wp.pi, wp.pi)))
    for i in range(7):
        view.joint_q[q0 + i] = pose[i]
    for i in range(view.robot_qd_count):
        view.joint_qd[view.base_qd_start[w] + i] = 0.0
    noise = vec12()
    for j in range(NUM_LEG_JOINTS):
        noise[j] = wp.randf(rng, -params.leg_position_noise, params.leg_position_noise)
    reset_legs(params, view, task, w, noise)
    for j in range(NUM_ARM_JOINTS + 1):
        view.joint_q[view.arm_q[w, j]] = params.arm_default[j]
        task.arm_target[w, j] = params.arm_default[j]
    for i in range(3):
        task.ee_force_h[w, i] = 0.0
    sample_command(fork_rng(wp.randi(rng)), params, task, w)
    task.episode_step[w] = 0
    task.next_command_step[w] = steps_in(wp.randf(rng), params.command_interval)
    task.next_arm_step[w] = steps_in(wp.randf(rng), params.arm_interval)
    task.next_push_step[w] = steps_in(wp.randf(rng), params.push_interval)
    task.next_ee_force_step[w] = steps_in(wp.randf(rng), params.ee_force_interval)


@wp.kernel
def start_legs(reset: wp.array(dtype=int), params: LocomotionParams, view: LeggedView, task: LocomotionTask):
    """Legs of every world with ``reset[w] != 0`` at their default (the legged push task's episode start)."""
    w = wp.tid()
    if reset[w] != 0:
        reset_legs(params, view, task, w, vec12())


@wp.kernel
def apply_events(seed: int, params: LocomotionParams, view: LeggedView, task: LocomotionTask):
    """Scheduled events of a running episode: a new command, a new arm target, a base push (a uniform
    horizontal velocity change of the free joint), a new end-effector force."""
    w = wp.tid()
    step = task.episode_step[w]
    if step >= task.next_command_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        sample_command(fork_rng(wp.randi(rng)), params, task, w)
        task.next_command_step[w] = step + steps_in(wp.randf(rng), params.command_interval)
    if step >= task.next_arm_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        sample_arm_target(fork_rng(wp.randi(rng)), params, task, w)
        task.next_arm_step[w] = step + steps_in(wp.randf(rng), params.arm_interval)
    if step >= task.next_push_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        d0 = view.base_qd_start[w]
        push = params.push_velocity * params.disturbance_scale[0]
        view.joint_qd[d0 + 0] = view.joint_qd[d0 + 0] + wp.randf(rng, -push, push)
        view.joint_qd[d0 + 1] = view.joint_qd[d0 + 1] + wp.randf(rng, -push, push)
        task.next_push_step[w] = step + steps_in(wp.randf(rng), params.push_interval)
    if step >= task.next_ee_force_step[w]:
        rng = next_rng(seed, task.rng_counter, w)
        sample_ee_force(fork_rng(wp.randi(rng)), params, task, w)
        task.next_ee_force_step[w] = step + steps_in(wp.randf(rng), params.ee_force_interval)


@wp.kernel
def write_ee_force(
    view: LeggedView,
    task: LocomotionTask,
    ee_body: wp.array(dtype=int),
    ee_offset: wp.vec3,
    body_com: wp.array(dtype=wp.vec3),
    body_f_0: wp.array(dtype=wp.spatial_vector),
    body_f_1: wp.array(dtype=wp.spatial_vector),
):
    """The end-effector force as the wrench on its link that Newton's solvers apply: ``body_f = (F_w, (p_ee - c_w)
    x F_w)`` about the link's centre of mass ``c_w`` (world frame, Newton's ``State.body_f`` convention), with
    ``F_w = R_yaw F_h`` and ``p_ee`` the end-effector point; written into both states the substeps alternate."""
    w = wp.tid()
    b = ee_body[w]
    x_e = view.body_q[b]
    force_w = wp.quat_rotate(yaw_quat(heading_yaw(wp.transform_get_rotation(view.body_q[view.base_body[w]]))),
                             wp.vec3(task.ee_force_h[w, 0], task.ee_force_h[w, 1], task.ee_force_h[w, 2]))
    lever = wp.transform_point(x_e, ee_offset) - wp.transform_point(x_e, body_com[b])
    wrench = wp.spatial_vector(force_w, wp.cross(lever, force_w))
    body_f_0[b] = wrench
    body_f_1[b] = wrench


@wp.kernel
def process_leg_actions(
    raw_actions: wp.array2d(dtype=float),
    params: LocomotionParams,
    view: LeggedView,
    task: LocomotionTask,
    joint_target_q: wp.array(dtype=float),
):
    """Shifts the action history, clips the actions (non-finite counts as zero) and writes the leg joint
    targets."""
    w = wp.tid()
    for j in range(NUM_LEG_JOINTS):
        task.last_actions[w, j] = task.actions[w, j]
        task.actions[w, j] = clipped_action(raw_actions[w, j], params.clip)
        target = params.leg_default[j] + params.action_scale * task.actions[w, j]
        task.leg_target[w, j] = target
        joint_target_q[view.leg_q[w, j]] = target


@wp.kernel
def write_arm_targets(view: LeggedView, task: LocomotionTask, joint_target_q: wp.array(dtype=float)):
    """The random arm motion's targets (all 6 arm joints) into the joint drives."""
    w = wp.tid()
    for j in range(NUM_ARM_JOINTS + 1):
        joint_target_q[view.arm_q[w, j]] = task.arm_target[w, j]


@wp.kernel
def update_feet(view: LeggedView, limits: LeggedLimits, task: LocomotionTask):
    """Foot contact (the foot sphere within ``contact_margin`` of the ground) and air time after the physics."""
    w = wp.tid()
    for f in range(NUM_FEET):
        foot = wp.transform_point(view.body_q[view.shank_body[w, f]], limits.foot_offset)
        contact = foot[2] - limits.foot_radius < limits.contact_margin
        task.touchdown_air_time[w, f] = -1.0
        if contact:
            if task.foot_contact[w, f] == 0:
                task.touchdown_air_time[w, f] = task.foot_air_time[w, f] + limits.control_dt
            task.foot_air_time[w, f] = 0.0
        else:
            task.foot_air_time[w, f] = task.foot_air_time[w, f] + limits.control_dt
        task.foot_contact[w, f] = wp.where(contact, 1, 0)


@wp.kernel
def compute_rewards(
    view: LeggedView,
    task: LocomotionTask,
    params: LocomotionRewardParams,
    reward: wp.array(dtype=float),
    reward_terms: wp.array2d(dtype=float),
    tracking_error: wp.array2d(dtype=float),
):
    """Tracking rewards of the 6D command: ``w_i exp(-e_i^2 / sigma_i)`` for the heading-frame velocity
    (vx, vy), the yaw rate, the attitude (roll, pitch) and the base height; and the stepping reward of
    legged_gym, ``w_5 sum_feet (t_air - air_time_target)`` over the feet touching down this step, while the
    command asks to move (a standing robot collects none); legged_gym's penalties: action rate
    ``-w_6 sum_j (a_t,j - a_t-1,j)^2`` (raw action units), the base's vertical velocity ``-w_7 v_z^2``
    (world frame, of its centre of mass, m/s) and roll and pitch rates ``-w_8 (omega_x^2 + omega_y^2)``
    (base frame, rad/s). ``tracking_error`` (N, 6): the errors
    ``command - measured`` per component (vx, vy, yaw rate, roll, pitch, height)."""
    w = wp.tid()
    x_b = view.body_q[view.base_body[w]]
    q_b = wp.transform_get_rotation(x_b)
    qd_b = view.body_qd[view.base_body[w]]
    velocity = heading_velocities(q_b, qd_b)
    omega_b = wp.quat_rotate_inv(q_b, wp.spatial_bottom(qd_b))
    vertical_velocity = wp.spatial_top(qd_b)[2]
    roll_pitch = heading_roll_pitch(q_b, yaw_quat(heading_yaw(q_b)))
    e_v = wp.vec2(task.command[w, 0] - velocity[0], task.command[w, 1] - velocity[1])
    e_yaw = task.command[w, 2] - velocity[2]
    e_att = wp.vec2(task.command[w, 3] - roll_pitch[0], task.command[w, 4] - roll_pitch[1])
    e_h = task.command[w, 5] - wp.transform_get_translation(x_b)[2]
    errors = vec6(e_v[0], e_v[1], e_yaw, e_att[0], e_att[1], e_h)
    for i in range(NUM_COMMANDS):
        tracking_error[w, i] = errors[i]
    stepping = float(0.0)
    moving = wp.length(wp.vec2(task.command[w, 0], task.command[w, 1])) + wp.abs(task.command[w, 2]) > params.moving_command
    for f in range(NUM_FEET):
        air = task.touchdown_air_time[w, f]
        if moving and air >= 0.0:
            stepping += air - params.air_time_target
    action_change = float(0.0)
    for j in range(NUM_LEG_JOINTS):
        change = task.actions[w, j] - task.last_actions[w, j]
        action_change += change * change
    terms = reward_vec(
        wp.exp(-wp.dot(e_v, e_v) / params.sigma_linear_velocity),
        wp.exp(-e_yaw * e_yaw / params.sigma_yaw_rate),
        wp.exp(-wp.dot(e_att, e_att) / params.sigma_attitude),
        wp.exp(-e_h * e_h / params.sigma_height),
        stepping,
        -action_change,
        -vertical_velocity * vertical_velocity,
        -(omega_b[0] * omega_b[0] + omega_b[1] * omega_b[1]),
    )
    total = float(0.0)
    for i in range(NUM_REWARD_TERMS):
        reward_terms[w, i] = params.weights[i] * terms[i]
        total += params.weights[i] * terms[i]
    reward[w] = total


@wp.func
def clearance(x: wp.transform, point: wp.vec3, radius: float):
    """Height [m] above the ground plane of a sphere of ``radius`` centred at body-frame ``point``."""
    return wp.transform_point(x, point)[2] - radius


@wp.kernel
def gather_foot_forces(total_force: wp.array(dtype=wp.vec3), foot_force: wp.array2d(dtype=float)):
    """``foot_force[w, f]`` = |F| [N] of contact sensor row ``NUM_FEET w + f`` (the lower leg ``f`` of world ``w``)."""
    w = wp.tid()
    for f in range(NUM_FEET):
        foot_force[w, f] = wp.length(total_force[w * NUM_FEET + f])


@wp.kernel
def compute_constraints(
    view: LeggedView,
    task: LocomotionTask,
    limits: LeggedLimits,
    foot_force: wp.array2d(dtype=float),
    constraints: wp.array2d(dtype=float),
):
    """Constraint values (see the module docstring); then stores this step's leg velocities for the next."""
    w = wp.tid()
    k = int(0)
    for j in range(NUM_LEG_JOINTS):
        constraints[w, k + j] = leg_torque_excess(view, task, limits, w, j)
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        constraints[w, k + j] = wp.abs(view.joint_qd[view.leg_qd[w, j]]) - limits.velocity_limit[j]
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        qd = view.joint_qd[view.leg_qd[w, j]]
        constraints[w, k + j] = wp.abs(qd - task.leg_velocity_last[w, j]) / limits.control_dt - limits.acceleration_limit
        task.leg_velocity_last[w, j] = qd
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        rate = wp.abs(task.actions[w, j] - task.last_actions[w, j]) / limits.control_dt
        constraints[w, k + j] = rate - limits.action_rate_limit
    k += NUM_LEG_JOINTS
    # Base box: its lowest corner is |R_20| a + |R_21| b + |R_22| c below the base origin.
    x_b = view.body_q[view.base_body[w]]
    R = wp.quat_to_matrix(wp.transform_get_rotation(x_b))
    e = limits.base_half_extents
    lowest = wp.transform_get_translation(x_b)[2] - (wp.abs(R[2, 0]) * e[0] + wp.abs(R[2, 1]) * e[1] + wp.abs(R[2, 2]) * e[2])
    constraints[w, k] = limits.collision_margin - lowest
    for f in range(NUM_FEET):
        x_s = view.body_q[view.shank_body[w, f]]
        knee = clearance(x_s, wp.vec3(0.0), limits.knee_radius)
        shank = clearance(x_s, limits.shank_end, limits.shank_radius)
        constraints[w, k + 1 + f] = limits.collision_margin - wp.min(knee, shank)
    k += 1 + NUM_FEET
    for f in range(NUM_FEET):
        air = task.touchdown_air_time[w, f]
        constraints[w, k + f] = wp.where(air >= 0.0, limits.air_time_min - air, 0.0)
    k += NUM_FEET
    for f in range(NUM_FEET):
        constraints[w, k + f] = foot_force[w, f] - limits.foot_force_limit


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


@wp.kernel
def compute_observations(
    view: LeggedView,
    task: LocomotionTask,
    params: LocomotionParams,
    noise_scale: wp.array(dtype=float),
    noise_enabled: int,
    seed: int,
    policy_obs: wp.array2d(dtype=float),
    critic_obs: wp.array2d(dtype=float),
):
    """Fills ``critic_obs`` (noiseless) then ``policy_obs`` = its first 61 entries + U(-s, s) noise."""
    w = wp.tid()
    x_b = view.body_q[view.base_body[w]]
    q_b = wp.transform_get_rotation(x_b)
    qd_b = view.body_qd[view.base_body[w]]
    k = int(0)
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.spatial_top(qd_b)))
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.spatial_bottom(qd_b)))
    k = write_vec(critic_obs, w, k, wp.quat_rotate_inv(q_b, wp.vec3(0.0, 0.0, -1.0)))
    for i in range(NUM_COMMANDS):
        critic_obs[w, k + i] = task.command[w, i]
    k += NUM_COMMANDS
    for j in range(NUM_LEG_JOINTS):
        critic_obs[w, k + j] = view.joint_q[view.leg_q[w, j]] - params.leg_default[j]
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        critic_obs[w, k + j] = view.joint_qd[view.leg_qd[w, j]]
    k += NUM_LEG_JOINTS
    for j in range(NUM_LEG_JOINTS):
        critic_obs[w, k + j] = task.actions[w, j]
    k += NUM_LEG_JOINTS
    for j in range(NUM_ARM_JOINTS):
        critic_obs[w, k + j] = view.joint_q[view.arm_q[w, j]] - params.arm_default[j]
    k += NUM_ARM_JOINTS
    for j in range(NUM_ARM_JOINTS):
        critic_obs[w, k + j] = view.joint_qd[view.arm_qd[w, j]]
    k += NUM_ARM_JOINTS
    # Privileged terms.
    critic_obs[w, k] = wp.transform_get_translation(x_b)[2]
    k += 1
    for f in range(NUM_FEET):
        critic_obs[w, k + f] = float(task.foot_contact[w, f])
    k += NUM_FEET
    critic_obs[w, k] = task.base_mass_offset[w]

    add_noise(critic_obs, policy_obs, w, noise_scale, noise_enabled, next_rng(seed, task.rng_counter, w))
