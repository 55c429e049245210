"""Warp structs of the locomotion task: the legged robots' simulator state and the task's per-world buffers,
parameters and limits (``LocomotionEnvConfig``), with the task's sizes.

The 6D base command ``(vx, vy, yaw rate, roll, pitch, height)``: vx, vy [m/s] in the heading frame, yaw rate
[rad/s] about world z, roll and pitch [rad] of the base relative to its heading frame, height [m] of the base
origin above the ground. Every array indexed by ``w`` has one entry per world. Frames: ``_w`` world, ``_b`` base,
``_h`` heading frame (base yaw only). Legs LF, RF, LH, RH; joints HAA, HFE, KFE per leg
(``dynpush.assets_usd.LEG_JOINT_NAMES``).
"""

import warp as wp

# The sizes of the locomotion policy are defined once, by the runtime's layouts; the kernels import them from here.
from dynpush.runtime.locomotion_layout import NUM_LEG_JOINTS  # noqa: F401
from dynpush.runtime.observation import NUM_ARM_JOINTS  # noqa: F401

NUM_FEET = 4
NUM_COMMANDS = 6
vec12 = wp.types.vector(length=NUM_LEG_JOINTS, dtype=float)


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
    leg_lower: wp.array(dtype=float)  # (12,) [rad] joint range (the targets are clamped to it, as the runtime's)
    leg_upper: wp.array(dtype=float)  # (12,) [rad]
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
