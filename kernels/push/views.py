"""Warp structs that hand the kernels the simulator's arrays and the task's per-world buffers.

Every array indexed by ``w`` has one entry per world (environment). Frames: ``_w`` world,
``_b`` robot base, ``_o`` object. Quaternions are (x, y, z, w).
"""

import warp as wp

# The push policy's sizes are defined once, by the runtime's numpy observation builder and action mapping (the
# runtime checks an ONNX file against them); the kernels import them from here. 5 arm joints act, the 6th DynaArm
# joint is frozen (paper III); 11 actions, (vx, vy, yaw rate, roll, pitch, height) + the 5 arm joints (III-C); 54
# actor observations (Table "Observations").
from dynpush.runtime.actions import NUM_BASE_COMMANDS  # noqa: F401
from dynpush.runtime.observation import NUM_ACTIONS, NUM_ARM_JOINTS  # noqa: F401
from dynpush.runtime.observation import POLICY_OBSERVATION_SIZE as NUM_POLICY_OBS  # noqa: F401

NUM_CRITIC_OBS = 74
NUM_COLLISIONS = 18
CONTACT_COLUMNS = NUM_COLLISIONS + 1  # the undesired collisions, then the EE-object contact state
EE_CONTACT = NUM_COLLISIONS


@wp.struct
class RobotView:
    """Newton state and the indices that locate each world's robot and object in it."""

    body_q: wp.array(dtype=wp.transform)  # body frame poses, world frame
    body_qd: wp.array(dtype=wp.spatial_vector)  # (v_com_w, omega_w)
    body_com: wp.array(dtype=wp.vec3)  # body frame
    body_mass: wp.array(dtype=float)
    joint_q: wp.array(dtype=float)
    joint_qd: wp.array(dtype=float)
    base_body: wp.array(dtype=int)  # per world
    object_body: wp.array(dtype=int)  # per world
    ee_body: wp.array(dtype=int)  # per world: the link that carries the end-effector
    arm_q_start: wp.array(dtype=int)  # per world: joint_q index of the first arm joint
    arm_qd_start: wp.array(dtype=int)  # per world: joint_qd index of the first arm joint
    robot_body_start: wp.array(dtype=int)  # per world: first body of the robot
    robot_body_count: int
    ee_offset: wp.vec3  # end-effector point in the ee_body frame [m]


@wp.struct
class PushTask:
    """Per-world task buffers owned by the environment."""

    goal_pos: wp.array(dtype=wp.vec3)  # world frame, object centroid at the goal
    goal_quat: wp.array(dtype=wp.quat)
    reach_target_o: wp.array(dtype=wp.vec3)  # reach target p_r in the object frame
    object_dims: wp.array(dtype=wp.vec3)  # full side lengths (cylinder: diameter, diameter, height)
    object_shape: wp.array(dtype=int)  # 0 cuboid, 1 cylinder
    object_mass: wp.array(dtype=float)
    object_com_o: wp.array(dtype=wp.vec3)  # CoM in the object frame
    object_inertia: wp.array(dtype=wp.vec3)  # principal moments of inertia [kg m^2]
    object_friction: wp.array(dtype=float)  # the object shape's own coefficient (combined = mean with floor)
    arm_default: wp.array(dtype=float)  # (5,) default arm configuration [rad]
    actions: wp.array2d(dtype=float)  # a_t, clipped raw actions
    last_actions: wp.array2d(dtype=float)  # a_{t-1}
    # absolute u_base^cmd = default + scale * a_base, as the policy asks for it (the base receives it clamped)
    base_command: wp.array2d(dtype=float)
    base_command_filtered: wp.array2d(dtype=float)  # the clamped command after the locomotion bandwidth lag
    base_wrench_b: wp.array(dtype=wp.spatial_vector)  # applied tracking wrench (force, torque), base frame
    arm_command: wp.array2d(dtype=float)  # absolute q_j^cmd, as asked (the drives get it clamped)
    contacts: wp.array2d(dtype=int)  # (num_worlds, CONTACT_COLUMNS) 1 where touching this step
    episode_step: wp.array(dtype=int)
    reach_reward_held: wp.array(dtype=float)  # r2 of the previous step (held on success)
    next_push_step: wp.array(dtype=int)
    rng_counter: wp.array(dtype=int)
    reward_weights: wp.array(dtype=float)  # (4,) w1..w4, an array so training can change w2
