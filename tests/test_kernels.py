"""Every Warp kernel of ``dynpush.kernels`` against an independent numpy reference on random states.

The references are written from the paper (Dadiotis et al., ICRA 2025, III-B..III-E, Tables
"Observations" and "Rewards and constraints") and the kernels' docstrings, not from the kernel code.
All launches run on the CPU device; the observation kernel is tested in test_observation_builder.py.

Layout of the random scenes: each world holds ``STRIDE`` bodies, the object first, then the robot's
``ROBOT_BODIES`` bodies (base first, end-effector link last); ``Q``/``QD`` joint coordinates/DOFs per
world with the robot's free joint, the 6 arm joints and the object's free joint.
"""

import math

import numpy as np
import pytest
import warp as wp

from dynpush.kernels.push import actions, base_tracking, constraints, contacts, keypoints, rewards, sampling, terminations
from dynpush.kernels.push.views import CONTACT_COLUMNS, EE_CONTACT, NUM_COLLISIONS, PushTask, RobotView
from warp_numpy_helpers import (DEVICE, arr, as_f32, axis_angle_quat, close, launch, make_struct, quat_matrix, quat_mul,
                                quat_rotate, quat_rotate_inv, random_quat)

wp.config.enable_backward = False
wp.config.quiet = True

ROBOT_BODIES = 4
STRIDE = ROBOT_BODIES + 1
Q, QD = 20, 18  # per world: robot free joint (7/6), arm (6/6), object free joint (7/6)
ARM_Q, ARM_QD = 7, 6  # offsets of the first arm joint
OBJECT_Q, OBJECT_QD = 13, 12


def yaw_quat(yaw):
    return axis_angle_quat(np.broadcast_to([0.0, 0.0, 1.0], np.shape(yaw) + (3,)), np.asarray(yaw))


def transform_point(x, p):
    """Applies transforms ``x`` (..., 7) = (position, quaternion) to points ``p`` (..., 3)."""
    return x[..., :3] + quat_rotate(x[..., 3:], p)


def tilt(q):
    """Angle between a body's +z axis and the world +z axis [rad]."""
    return np.arccos(np.clip(quat_rotate(q, np.array([0.0, 0.0, 1.0]))[..., 2], -1.0, 1.0))


def unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n < 1e-6, 0.0, v / np.maximum(n, 1e-12))


def obb_vertices(p, q, dims):
    """(n, 8, 3) OBB vertices; vertex k takes the +half extent along axis i where bit i of k is set."""
    signs = np.array([[1 if k >> i & 1 else -1 for i in range(3)] for k in range(8)], dtype=np.float64)
    return p[:, None] + quat_rotate(q[:, None], 0.5 * signs * dims[:, None])


def assert_uniform(u, name):
    """Kolmogorov-Smirnov distance of samples ``u`` from U(0, 1) below the 0.1 % critical value."""
    u = np.sort(np.asarray(u, dtype=np.float64))
    n = len(u)
    i = np.arange(1, n + 1)
    d = max(np.max(i / n - u), np.max(u - (i - 1) / n))
    assert d < 1.95 / math.sqrt(n), f"{name}: KS distance {d:.4f} for {n} samples"


def random_state(rng, n):
    """Random robot (RobotView fields) and task (PushTask fields) buffers of ``n`` worlds, float32-exact."""
    w = np.arange(n)
    nb = n * STRIDE
    pos = np.column_stack([rng.uniform(-2.0, 2.0, (nb, 2)), rng.uniform(0.2, 1.2, nb)])
    robot = dict(
        body_q=np.column_stack([pos, random_quat(rng, nb)]),
        body_qd=rng.normal(size=(nb, 6)),
        body_com=rng.uniform(-0.1, 0.1, (nb, 3)),
        body_mass=rng.uniform(0.5, 20.0, nb),
        joint_q=rng.normal(size=n * Q),
        joint_qd=2.0 * rng.normal(size=n * QD),
        base_body=w * STRIDE + 1,
        object_body=w * STRIDE,
        ee_body=w * STRIDE + ROBOT_BODIES,
        arm_q_start=w * Q + ARM_Q,
        arm_qd_start=w * QD + ARM_QD,
        robot_body_start=w * STRIDE + 1,
        robot_body_count=ROBOT_BODIES,
        ee_offset=rng.uniform(-0.1, 0.1, 3),
    )
    task = dict(
        goal_pos=rng.uniform(-2.0, 2.0, (n, 3)),
        goal_quat=random_quat(rng, n),
        reach_target_o=rng.uniform(-0.4, 0.4, (n, 3)),
        object_dims=rng.uniform(0.25, 1.0, (n, 3)),
        object_shape=rng.integers(0, 2, n),
        object_mass=rng.uniform(1.0, 10.0, n),
        object_com_o=rng.uniform(-0.1, 0.1, (n, 3)),
        object_inertia=rng.uniform(0.05, 1.0, (n, 3)),
        object_friction=rng.uniform(0.4, 2.0, n),
        arm_default=rng.uniform(-1.0, 1.0, 5),
        actions=rng.normal(size=(n, 11)),
        last_actions=rng.normal(size=(n, 11)),
        base_command=rng.normal(size=(n, 6)),
        base_command_filtered=rng.normal(size=(n, 6)),
        base_wrench_b=50.0 * rng.normal(size=(n, 6)),
        arm_command=rng.normal(size=(n, 5)),
        contacts=rng.integers(0, 2, (n, CONTACT_COLUMNS)),
        episode_step=rng.integers(0, 1000, n),
        reach_reward_held=rng.uniform(0.0, 1.0, n),
        next_push_step=rng.integers(0, 1000, n),
        rng_counter=rng.integers(0, 5, n),
        reward_weights=rng.uniform(0.1, 3.0, 4),
    )
    return as_f32(robot), as_f32(task)


def structs(robot, task):
    return make_struct(RobotView, **robot), make_struct(PushTask, **task)


# --------------------------------------------------------------------------- actions (III-C)
def test_process_actions():
    rng = np.random.default_rng(1)
    n, clip, arm_scale = 64, 2.5, 0.5
    robot_np, task_np = random_state(rng, n)
    raw = (3.0 * rng.normal(size=(n, 11))).astype(np.float32)
    raw[0, 0], raw[1, 3], raw[2, 7], raw[3, 10] = np.nan, np.inf, -np.inf, np.nan
    base_default = rng.uniform(-0.5, 0.5, 6)
    base_scale = rng.uniform(0.1, 1.0, 6)
    target = rng.normal(size=n * Q).astype(np.float32)
    limits, (base_lo, base_hi, arm_lo, arm_hi) = random_command_limits(rng)
    robot, task = structs(robot_np, task_np)
    joint_target_q, base_target = arr(target), arr(np.zeros((n, 6)))
    launch(actions.process_actions, n, arr(raw), robot, task, arr(base_default), arr(base_scale), arm_scale, clip,
           limits, base_target, joint_target_q)

    a = np.clip(np.where(np.isfinite(raw), raw, 0.0), -clip, clip)
    assert np.abs(raw[np.isfinite(raw)]).max() > clip and np.isfinite(task.actions.numpy()).all()
    close(task.last_actions.numpy(), task_np["actions"], atol=0)
    close(task.actions.numpy(), a, atol=0)
    base = base_default + base_scale * a[:, :6]
    close(task.base_command.numpy(), base, err_msg="the command as asked")
    arm = task_np["arm_default"] + arm_scale * a[:, 6:]
    close(task.arm_command.numpy(), arm, err_msg="the command as asked")
    assert ((base < base_lo) | (base > base_hi)).any() and ((arm < arm_lo) | (arm > arm_hi)).any()
    close(base_target.numpy(), np.clip(base, base_lo, base_hi), err_msg="the base receives the clamped command")
    idx = robot_np["arm_q_start"][:, None] + np.arange(5)
    target[idx] = np.clip(arm, arm_lo, arm_hi)
    close(joint_target_q.numpy(), target, err_msg="clamped arm targets at the arm's joint_q entries, the rest untouched")


def test_apply_commands():
    """Commands mapped outside (sim-to-sim) land where process_actions writes its own; the action history shifts."""
    rng = np.random.default_rng(12)
    n, clip = 64, 2.5
    robot_np, task_np = random_state(rng, n)
    raw = (3.0 * rng.normal(size=(n, 11))).astype(np.float32)
    raw[0, 0], raw[1, 5] = np.nan, np.inf
    base_command = rng.normal(size=(n, 6)).astype(np.float32)
    arm_targets = rng.uniform(-2.0, 2.0, (n, 5)).astype(np.float32)
    target = rng.normal(size=n * Q).astype(np.float32)
    limits, (base_lo, base_hi, arm_lo, arm_hi) = random_command_limits(rng)
    robot, task = structs(robot_np, task_np)
    joint_target_q, base_target = arr(target), arr(np.zeros((n, 6)))
    launch(actions.apply_commands, n, arr(raw), arr(base_command), arr(arm_targets), robot, task, clip, limits,
           base_target, joint_target_q)

    close(task.last_actions.numpy(), task_np["actions"], atol=0)
    close(task.actions.numpy(), np.clip(np.where(np.isfinite(raw), raw, 0.0), -clip, clip), atol=0)
    close(task.base_command.numpy(), base_command, atol=0)
    close(task.arm_command.numpy(), arm_targets, atol=0)
    close(base_target.numpy(), np.clip(base_command, base_lo, base_hi), atol=0)
    target[robot_np["arm_q_start"][:, None] + np.arange(5)] = np.clip(arm_targets, arm_lo, arm_hi)
    close(joint_target_q.numpy(), target, atol=0, err_msg="arm targets at the arm's joint_q entries, the rest untouched")


def random_command_limits(rng):
    """A ``CommandLimits`` struct of random float32 bounds, and the bounds (base lower, upper, arm lower, upper)."""
    bounds = [np.float32(b) for b in (rng.uniform(-1.0, -0.2, 6), rng.uniform(0.2, 1.0, 6),
                                     rng.uniform(-1.5, -0.5, 5), rng.uniform(0.5, 1.5, 5))]
    names = ("base_lower", "base_upper", "arm_lower", "arm_upper")
    return make_struct(actions.CommandLimits, **dict(zip(names, bounds))), bounds


# --------------------------------------------------------------------------- tracked base (DESIGN decision 2)
def test_apply_base_wrench():
    rng = np.random.default_rng(2)
    n = 256
    robot_np, task_np = random_state(rng, n)
    base = robot_np["base_body"]
    # Moderate base attitudes (yaw anywhere, tilt < 0.5 rad) so roll/pitch are well defined.
    axis = np.column_stack([rng.normal(size=(n, 2)), np.zeros(n)])
    q_b = quat_mul(yaw_quat(rng.uniform(-np.pi, np.pi, n)), axis_angle_quat(axis, rng.uniform(0.0, 0.5, n)))
    robot_np["body_q"][base, 3:] = q_b.astype(np.float32)
    robot_np["body_q"][base, 2] = rng.uniform(0.3, 0.7, n)
    robot_np["body_qd"][base] *= 0.7
    task_np["base_command"][:, 5] = rng.uniform(0.35, 0.65, n)
    task_np["base_command_filtered"][:, 5] = rng.uniform(0.35, 0.65, n)
    task_np["base_command"][:, 3:5] *= 0.2
    task_np["base_command_filtered"][:, 3:5] *= 0.2
    robot_np, task_np = as_f32(robot_np), as_f32(task_np)

    p = base_tracking.BaseTrackingParams()
    p.dt, p.time_constant, p.velocity_gain, p.yaw_rate_gain = 0.005, 0.15, 8.0, 6.0
    p.attitude_stiffness, p.attitude_damping = 64.0, 16.0
    p.max_horizontal_force, p.max_vertical_force, p.gravity = 300.0, 1200.0, 9.81
    max_torque, inertia = np.array([150.0, 250.0, 80.0]), np.array([10.0, 12.0, 5.0])
    p.max_torque, p.attitude_inertia = wp.vec3(*max_torque), wp.vec3(*inertia)
    body_f0 = rng.normal(size=(n * STRIDE, 6)).astype(np.float32)
    robot, task = structs(robot_np, task_np)
    body_f = wp.array(body_f0, dtype=wp.spatial_vector, device=DEVICE)
    base_target = task_np["base_command"] + 0.1 * rng.normal(size=(n, 6)).astype(np.float32)  # not the asked command
    launch(base_tracking.apply_base_wrench, n, robot, task, arr(base_target), p, body_f)

    # Reference. First-order lag of the command the base receives, then the PD wrench of the docstring.
    alpha = p.dt / (p.time_constant + p.dt)
    u = task_np["base_command_filtered"] + alpha * (base_target - task_np["base_command_filtered"])
    x_b, qd_b = robot_np["body_q"][base], robot_np["body_qd"][base]
    v, omega = qd_b[:, :3], qd_b[:, 3:]
    bodies = robot_np["robot_body_start"][:, None] + np.arange(ROBOT_BODIES)
    m = robot_np["body_mass"][bodies]
    com = np.einsum("nk,nki->ni", m, transform_point(robot_np["body_q"][bodies], robot_np["body_com"][bodies]))
    mass = m.sum(1)
    com /= mass[:, None]
    R_b = quat_matrix(x_b[:, 3:])
    yaw = np.arctan2(R_b[:, 1, 0], R_b[:, 0, 0])
    R_yaw = quat_matrix(yaw_quat(yaw))
    v_target = np.einsum("nij,nj->ni", R_yaw, np.column_stack([u[:, 0], u[:, 1], np.zeros(n)]))
    f_xy = (mass * p.velocity_gain)[:, None] * (v_target[:, :2] - v[:, :2])
    norm_xy = np.linalg.norm(f_xy, axis=1)
    f_xy *= np.minimum(1.0, p.max_horizontal_force / norm_xy)[:, None]
    f_z_raw = mass * (p.gravity + p.attitude_stiffness * (u[:, 5] - x_b[:, 2]) - p.attitude_damping * v[:, 2])
    force = np.column_stack([f_xy, np.clip(f_z_raw, 0.0, p.max_vertical_force)])
    R_h = np.einsum("nji,njk->nik", R_yaw, R_b)  # base attitude in its heading frame
    z_h = R_h[:, :, 2]
    roll, pitch = np.arctan2(-z_h[:, 1], z_h[:, 2]), np.arctan2(z_h[:, 0], z_h[:, 2])
    omega_h = np.einsum("nji,nj->ni", R_yaw, omega)
    tau_raw = np.column_stack([
        inertia[0] * (p.attitude_stiffness * (u[:, 3] - roll) - p.attitude_damping * omega_h[:, 0]),
        inertia[1] * (p.attitude_stiffness * (u[:, 4] - pitch) - p.attitude_damping * omega_h[:, 1]),
        inertia[2] * p.yaw_rate_gain * (u[:, 2] - omega[:, 2]),
    ])
    tau_h = np.clip(tau_raw, -max_torque, max_torque)
    lever = com - transform_point(x_b, robot_np["body_com"][base])  # robot CoM relative to the base CoM
    torque = np.einsum("nij,nj->ni", R_yaw, tau_h) + np.cross(lever, force)

    # The random states exercise every saturation and both sides of each clamp.
    assert (norm_xy > p.max_horizontal_force).any() and (norm_xy < p.max_horizontal_force).any()
    assert (f_z_raw < 0).any() and (f_z_raw > p.max_vertical_force).any() and (np.abs(f_z_raw - 600) < 500).any()
    assert (np.abs(tau_raw) > max_torque).any(axis=0).all() and (np.abs(tau_raw) < max_torque).any(axis=0).all()
    assert np.linalg.norm(lever, axis=1).min() > 1e-3

    close(task.base_command_filtered.numpy(), u)
    expected_f = body_f0.astype(np.float64).copy()
    expected_f[base] += np.column_stack([force, torque])
    close(body_f.numpy(), expected_f, rtol=2e-4, atol=2e-3, err_msg="body_f = previous + (force_w, torque_w at base CoM)")
    wrench_b = np.column_stack([quat_rotate_inv(x_b[:, 3:], force), quat_rotate_inv(x_b[:, 3:], torque)])
    close(task.base_wrench_b.numpy(), wrench_b, rtol=2e-4, atol=2e-3)


# --------------------------------------------------------------------------- keypoints (III-D)
@wp.kernel
def _keypoints(robot: RobotView, task: PushTask, object_keypoints_w: wp.array2d(dtype=wp.vec3),
               goal_keypoints_w: wp.array2d(dtype=wp.vec3)):
    """``K_o`` and ``K_g`` [m], world frame, (num_worlds, 8): the vertices the reward's keypoint distance sums over."""
    w = wp.tid()
    x_o = robot.body_q[robot.object_body[w]]
    for k in range(8):
        object_keypoints_w[w, k] = keypoints.obb_vertex(wp.transform_get_translation(x_o), wp.transform_get_rotation(x_o),
                                                        task.object_dims[w], k)
        goal_keypoints_w[w, k] = keypoints.obb_vertex(task.goal_pos[w], task.goal_quat[w], task.object_dims[w], k)


@wp.kernel
def _keypoint_distance(robot: RobotView, task: PushTask, out: wp.array(dtype=float)):
    w = wp.tid()
    x_o = robot.body_q[robot.object_body[w]]
    out[w] = keypoints.keypoint_distance(wp.transform_get_translation(x_o), wp.transform_get_rotation(x_o),
                                         task.goal_pos[w], task.goal_quat[w], task.object_dims[w])


def test_keypoints_and_distance():
    rng = np.random.default_rng(3)
    n = 64
    robot_np, task_np = random_state(rng, n)
    obj = robot_np["object_body"]
    # World 0: goal = object pose (distance 0); world 1: pure translation t (distance sqrt(8) |t|).
    task_np["goal_pos"][0], task_np["goal_quat"][0] = robot_np["body_q"][obj[0], :3], robot_np["body_q"][obj[0], 3:]
    task_np["goal_pos"][1] = robot_np["body_q"][obj[1], :3] + np.array([0.3, -0.4, 0.0])
    task_np["goal_quat"][1] = robot_np["body_q"][obj[1], 3:]
    task_np = as_f32(task_np)
    robot, task = structs(robot_np, task_np)
    k_o, k_g = (wp.zeros((n, 8), dtype=wp.vec3, device=DEVICE) for _ in range(2))
    dist = wp.zeros(n, dtype=float, device=DEVICE)
    launch(_keypoints, n, robot, task, k_o, k_g)
    launch(_keypoint_distance, n, robot, task, dist)

    dims = task_np["object_dims"]
    ref_o = obb_vertices(robot_np["body_q"][obj, :3], robot_np["body_q"][obj, 3:], dims)
    ref_g = obb_vertices(task_np["goal_pos"], task_np["goal_quat"], dims)
    close(k_o.numpy(), ref_o, atol=1e-5)
    close(k_g.numpy(), ref_g, atol=1e-5)
    # Vertex k is the +half extent along axis i where bit i of k is set (body frame of the object).
    local = quat_rotate_inv(robot_np["body_q"][obj, None, 3:], k_o.numpy() - robot_np["body_q"][obj, None, :3])
    close(local[:, 6], 0.5 * dims * np.array([-1, 1, 1]), atol=1e-5)
    ref_dist = np.linalg.norm((ref_g - ref_o).reshape(n, 24), axis=1)
    close(dist.numpy(), ref_dist, atol=1e-5)
    assert abs(dist.numpy()[0]) < 1e-5 and dist.numpy()[1] == pytest.approx(math.sqrt(8) * 0.5, abs=1e-5)


# --------------------------------------------------------------------------- rewards (Table "Rewards and constraints")
def test_compute_rewards():
    rng = np.random.default_rng(4)
    n = 256
    robot_np, task_np = random_state(rng, n)
    obj, w = robot_np["object_body"], np.arange(n)
    p_o, q_o = robot_np["body_q"][obj, :3], robot_np["body_q"][obj, 3:]
    # Goals near the object: case 0 success, 1 too rotated, 2 too far; 3 is an arbitrary goal.
    case = w % 4
    near = case < 3
    dist = np.where(case == 2, rng.uniform(0.12, 0.3, n), rng.uniform(0.0, 0.08, n))
    angle = np.radians(np.where(case == 1, rng.uniform(12.0, 40.0, n), rng.uniform(0.0, 8.0, n)))
    offset = unit(rng.normal(size=(n, 3))) * dist[:, None]
    task_np["goal_pos"][near] = (p_o + offset)[near]
    task_np["goal_quat"][near] = quat_mul(q_o, axis_angle_quat(rng.normal(size=(n, 3)), angle))[near]
    robot_np["body_qd"][obj[w % 8 == 7]] = 0.0  # resting object: r3 uses a zero direction
    robot_np, task_np = as_f32(robot_np), as_f32(task_np)

    prm = rewards.RewardParams()
    sig = dict(sigma_reach=0.8, sigma_velocity=1.3, sigma_task=0.7, sigma_base_rate=1.1, sigma_arm_rate=0.9)
    for k, v in sig.items():
        setattr(prm, k, v)
    prm.success_task_reward, prm.success_distance, prm.arm_scale = 2.0, 0.1, 0.5
    base_scale = rng.uniform(0.2, 1.0, 6).astype(np.float32)
    p_g, q_g = task_np["goal_pos"], task_np["goal_quat"]
    rel = 2.0 * np.arccos(np.clip(np.abs(np.sum(q_o * q_g, axis=1)), 0.0, 1.0))
    for success_angle_deg, expected in ((10.0, near & (case == 0)), (45.0, near & (case < 2))):  # 45: a curriculum's
        robot, task = structs(robot_np, task_np)
        reward, terms = wp.zeros(n, dtype=float, device=DEVICE), wp.zeros((n, 4), dtype=float, device=DEVICE)
        success = wp.zeros(n, dtype=int, device=DEVICE)
        launch(rewards.compute_rewards, n, robot, task, prm, arr([math.radians(success_angle_deg)]), arr(base_scale),
               reward, terms, success)

        is_success = (np.linalg.norm(p_g - p_o, axis=1) <= 0.1) & (rel <= math.radians(success_angle_deg))
        dims = task_np["object_dims"]
        keypoint_gap = (obb_vertices(p_g, q_g, dims) - obb_vertices(p_o, q_o, dims)).reshape(n, 24)
        r1 = np.exp(-np.linalg.norm(keypoint_gap, axis=1) / sig["sigma_task"] ** 2)
        p_e = transform_point(robot_np["body_q"][robot_np["ee_body"]], robot_np["ee_offset"])
        p_r = transform_point(robot_np["body_q"][obj], task_np["reach_target_o"])
        r2 = np.exp(-np.linalg.norm(p_e - p_r, axis=1) / sig["sigma_reach"] ** 2)
        qd_o = robot_np["body_qd"][obj]
        c_w = transform_point(robot_np["body_q"][obj], task_np["object_com_o"])
        v_o = qd_o[:, :3] + np.cross(qd_o[:, 3:], p_o - c_w)  # velocity of the object frame origin
        r3 = np.exp(np.sum(unit(v_o) * unit(p_g - p_o), axis=1) / sig["sigma_velocity"] ** 2 - 1.0)
        da = task_np["actions"] - task_np["last_actions"]
        r4 = (np.exp(-np.linalg.norm(base_scale * da[:, :6], axis=1) / sig["sigma_base_rate"] ** 2)
              + np.exp(-np.linalg.norm(0.5 * da[:, 6:], axis=1) / sig["sigma_arm_rate"] ** 2))
        r1 = np.where(is_success, 2.0, r1)  # III-D: r1 = 2, r2 held, r3 = 0 on success
        r2 = np.where(is_success, task_np["reach_reward_held"], r2)
        r3 = np.where(is_success, 0.0, r3)
        ref_terms = np.column_stack([r1, r2, r3, r4])

        np.testing.assert_array_equal(is_success, expected)
        np.testing.assert_array_equal(success.numpy(), is_success.astype(int))
        close(terms.numpy(), ref_terms, atol=1e-5)
        close(reward.numpy(), ref_terms @ task_np["reward_weights"], atol=1e-5)
        close(task.reach_reward_held.numpy(), r2, atol=1e-5, err_msg="held r2 = this step's r2")
        assert np.allclose(terms.numpy()[w % 8 == 7, 2][~is_success[w % 8 == 7]], math.exp(-1.0), atol=1e-6)


# --------------------------------------------------------------------------- constraints (Table "Rewards and constraints")
def test_compute_constraints():
    rng = np.random.default_rng(5)
    n = 256
    robot_np, task_np = random_state(rng, n)
    lower, upper = rng.uniform(-1.5, -0.5, 5), rng.uniform(0.5, 1.5, 5)
    vel, kp, kd = rng.uniform(1.0, 3.0, 5), rng.uniform(50.0, 150.0, 5), rng.uniform(1.0, 5.0, 5)
    peak, nominal = rng.uniform(60.0, 120.0, 5), rng.uniform(20.0, 50.0, 5)
    base_lo, base_hi = rng.uniform(-1.0, -0.3, 6), rng.uniform(0.3, 1.0, 6)
    leg_map, leg_nominal = rng.normal(size=(12, 6)), rng.uniform(20.0, 60.0, 12)
    arm_scale, dt, tilt_limit, moving = 0.5, 0.02, math.radians(10.0), 1.5
    limits = make_struct(constraints.ArmLimits, lower=lower, upper=upper, velocity=vel, stiffness=kp, damping=kd,
                         peak_torque=peak, nominal_torque=nominal)
    params = make_struct(constraints.ConstraintParams, base_lower=base_lo, base_upper=base_hi, leg_torque_map=leg_map,
                         leg_nominal_torque=leg_nominal)
    params.object_tilt_limit, params.base_moving_speed, params.arm_scale, params.control_dt = tilt_limit, moving, arm_scale, dt
    robot, task = structs(robot_np, task_np)
    out = wp.zeros((n, constraints.NUM_CONSTRAINTS), dtype=float, device=DEVICE)
    # The arm drives' targets: the asked command clamped to the joint range (actions.py), away from it in some worlds.
    arm_q_index = robot_np["arm_q_start"][:, None] + np.arange(5)
    joint_target_q = np.zeros(robot_np["joint_q"].size, dtype=np.float32)
    joint_target_q[arm_q_index] = np.clip(task_np["arm_command"], lower, upper)
    launch(constraints.compute_constraints, n, robot, task, limits, params, arr(joint_target_q), out)

    f32 = lambda x: np.asarray(x, dtype=np.float32).astype(np.float64)  # noqa: E731
    lower, upper, vel, kp, kd, peak, nominal = map(f32, (lower, upper, vel, kp, kd, peak, nominal))
    u, q_cmd = task_np["base_command"], task_np["arm_command"]
    q = robot_np["joint_q"][robot_np["arm_q_start"][:, None] + np.arange(5)]
    qd = robot_np["joint_qd"][robot_np["arm_qd_start"][:, None] + np.arange(5)]
    da = task_np["actions"][:, 6:] - task_np["last_actions"][:, 6:]
    q_target = joint_target_q[arm_q_index].astype(np.float64)
    assert (q_target != q_cmd).any()
    tau = np.clip(kp * (q_target - q) - kd * qd, -peak, peak)  # PD drive of the received target, saturated at the peak
    tau_leg = task_np["base_wrench_b"] @ f32(leg_map).T
    speed = np.linalg.norm(robot_np["body_qd"][robot_np["base_body"], :3], axis=1)
    theta = tilt(robot_np["body_q"][robot_np["object_body"], 3:])
    groups = {
        "base_command": np.maximum(u - f32(base_hi), f32(base_lo) - u),
        "arm_command": np.maximum(q_cmd - upper, lower - q_cmd),
        "arm_action_rate": arm_scale * np.abs(da) / dt - vel,
        "arm_joint_position": np.maximum(q - upper, lower - q),
        "arm_joint_velocity": np.abs(qd) - vel,
        "arm_joint_torque": np.abs(tau) - nominal,
        "leg_joint_torque": np.abs(tau_leg) - f32(leg_nominal),
        "collision": task_np["contacts"][:, :NUM_COLLISIONS].astype(np.float64),
        "object_balance": np.where(speed > moving, np.abs(theta) - tilt_limit, 0.0)[:, None],
    }
    assert [(name, ref.shape[1]) for name, ref in groups.items()] == list(constraints.CONSTRAINT_GROUPS)
    assert (np.abs(kp * (q_target - q) - kd * qd) > peak).any() and (speed > moving).any() and (speed < moving).any()
    actual, start = out.numpy(), 0
    for name, ref in groups.items():
        assert (ref > 0).any() and (ref <= 0).any(), f"random states should both violate and satisfy {name}"
        close(actual[:, start : start + ref.shape[1]], ref, atol=2e-4, err_msg=name)
        start += ref.shape[1]
    assert start == constraints.NUM_CONSTRAINTS == 62


# --------------------------------------------------------------------------- terminations (III-B)
def test_compute_terminations():
    rng = np.random.default_rng(6)
    n, max_steps = 512, 1000
    robot_np, task_np = random_state(rng, n)
    base, obj = robot_np["base_body"], robot_np["object_body"]
    robot_np["body_q"][base, 2] = rng.uniform(0.1, 0.7, n)
    task_np["episode_step"] = rng.integers(max_steps - 3, max_steps, n)
    success0 = rng.integers(0, 2, n)
    # Diverged worlds (a non-finite base or object pose or velocity): every eighth, one field each.
    diverged = np.arange(n) % 8 == 5
    for k, w in enumerate(np.flatnonzero(diverged)):
        body, field, column = [(base[w], "body_q", 0), (obj[w], "body_q", 4), (base[w], "body_qd", 3),
                               (obj[w], "body_qd", 1)][k % 4]
        robot_np[field][body, column] = [np.nan, np.inf][k % 2]
        success0[w] = 0  # a diverged world's success flag is 0 (its distances are NaN)
    params = terminations.TerminationParams()
    params.object_topple, params.base_tilt, params.base_min_height, params.max_episode_steps = 1.0, 1.2, 0.25, max_steps
    robot, task = structs(robot_np, task_np)
    flags = [wp.zeros(n, dtype=int, device=DEVICE) for _ in range(6)]
    launch(terminations.compute_terminations, n, robot, task, params, arr(success0, int), *flags)
    reset, time_out, episode_success, toppled_out, diverged_out, fallen_out = (f.numpy() for f in flags)

    step = task_np["episode_step"] + 1
    toppled = ~diverged & (tilt(robot_np["body_q"][obj, 3:]) > 1.0)
    fallen = ~diverged & ((tilt(robot_np["body_q"][base, 3:]) > 1.2) | (robot_np["body_q"][base, 2] < 0.25))
    timed_out = step >= max_steps
    done = toppled | fallen | timed_out | diverged
    for label, mask in (("time-out only", timed_out & ~toppled & ~fallen & ~diverged),
                        ("toppled at time-out", timed_out & toppled), ("fallen, not toppled", fallen & ~toppled),
                        ("fallen and toppled", fallen & toppled),
                        ("diverged before the time-out", diverged & ~timed_out), ("running", ~done)):
        assert mask.any(), f"no world in case {label}"
    np.testing.assert_array_equal(task.episode_step.numpy(), step)
    np.testing.assert_array_equal(reset, done)
    np.testing.assert_array_equal(time_out, timed_out & ~(toppled | fallen | diverged),
                                  err_msg="time-out only without a fall or divergence")
    np.testing.assert_array_equal(episode_success, np.where(done, success0, -1))
    np.testing.assert_array_equal(toppled_out, done & toppled)
    np.testing.assert_array_equal(diverged_out, diverged)
    np.testing.assert_array_equal(fallen_out, done & fallen)


# --------------------------------------------------------------------------- reset sampling (III-B, III-E)
def sampling_params(**overrides):
    p = sampling.SamplingParams()
    full = (-math.pi, math.pi)
    values = dict(robot_radius=(1.2, 2.5), robot_bearing=full, goal_bearing=full,
                  object_yaw=full, goal_yaw=full, base_yaw=full, surface_target=1,
                  friction=(0.4, 1.25), ground_friction=0.4, com_fraction_lo=(-0.25, -0.25, -0.6),
                  com_fraction_hi=(0.25, 0.25, 0.25), size_lo=(0.25, 0.25, 0.4), size_hi=(0.75, 0.75, 1.0),
                  cylinder_probability=0.3, base_mass_offset=(-5.0, 5.0), push_interval_steps=(350.0, 500.0),
                  push_velocity=0.5, arm_joint_noise=0.2, base_height=0.5, frozen_joint_value=0.3)
    values.update(overrides)
    for name, value in values.items():
        kind = sampling.SamplingParams.vars[name].type
        setattr(p, name, kind(*value) if isinstance(value, tuple) else value)
    return p


def random_spec(rng, n):
    """A valid random ``EpisodeSpec`` (numpy, float32-exact) of ``n`` worlds."""
    dims = rng.uniform(0.25, 1.0, (n, 3))
    shape = rng.integers(0, 2, n)
    dims[:, 1] = np.where(shape == 1, dims[:, 0], dims[:, 1])
    yaw = lambda: rng.uniform(-np.pi, np.pi, n)  # noqa: E731
    return as_f32(dict(
        shape=shape, dims=dims, mass=rng.uniform(1.0, 10.0, n), com_o=rng.uniform(-0.1, 0.1, (n, 3)),
        friction=rng.uniform(0.4, 1.25, n), object_yaw=yaw(), reach_target_o=rng.uniform(-0.4, 0.4, (n, 3)),
        goal=np.column_stack([rng.uniform(-2, 2, (n, 2)), yaw()]),
        base=np.column_stack([rng.uniform(-2.5, 2.5, (n, 2)), yaw()]),
        arm_q=rng.normal(size=(n, 5)), base_mass_offset=rng.uniform(-5.0, 5.0, n), first_push_step=rng.integers(0, 600, n),
    ))


def sample_episodes(reset, seed, params, task, spec, difficulty=1.0, object_mass=(1.0, 10.0), goal_radius=(0.0, 2.0),
                    near_goal=(0.0, 0.0, 0.0), behind=(0.0, 0.0), start_flags=None):
    """Launches ``sampling.sample_episodes``; ``object_mass`` = (low, high) [kg], ``goal_radius`` = (low, high) [m],
    ``near_goal`` = (share, radius [m], max_yaw [rad]), ``behind`` = (share, spread [rad]), ``start_flags`` the worlds'
    near-goal flags before (default 0). Returns the near-goal flags (start, ended) after."""
    n = len(reset)
    start = arr(np.zeros(n) if start_flags is None else start_flags, int)
    ended = arr(np.full(n, -1), int)
    launch(sampling.sample_episodes, n, arr(reset, int), seed, params, arr([difficulty]),
           wp.array([object_mass], dtype=wp.vec2, device=DEVICE), wp.array([goal_radius], dtype=wp.vec2, device=DEVICE),
           wp.array([near_goal], dtype=wp.vec3, device=DEVICE),
           wp.array([behind], dtype=wp.vec2, device=DEVICE), task, spec, start, ended)
    return start.numpy(), ended.numpy()


def test_sample_episodes_narrow_ranges():
    """Reduced tasks and curricula: bearings, yaws and the goal annulus follow their ranges."""
    n = 4000
    _, task_np = random_state(np.random.default_rng(3), n)
    task, spec = make_struct(PushTask, **task_np), make_struct(sampling.EpisodeSpec, **random_spec(np.random.default_rng(4), n))
    params = sampling_params(robot_bearing=(2.0, 2.5), goal_bearing=(-0.3, 0.1), object_yaw=(0.2, 0.2),
                             goal_yaw=(-1.0, -0.5), base_yaw=(3.0, 3.1))
    sample_episodes(np.ones(n), 5, params, task, spec, goal_radius=(0.5, 0.8))
    out = read_struct(sampling.EpisodeSpec, spec)
    goal, base = out["goal"], out["base"]
    bearing = lambda xy: np.arctan2(xy[:, 1], xy[:, 0])  # noqa: E731
    assert (bearing(base) >= 2.0 - 1e-5).all() and (bearing(base) <= 2.5 + 1e-5).all()
    assert (bearing(goal) >= -0.3 - 1e-5).all() and (bearing(goal) <= 0.1 + 1e-5).all()
    radius = np.linalg.norm(goal[:, :2], axis=1)
    assert radius.min() >= 0.5 - 1e-5 and radius.max() <= 0.8 + 1e-5
    assert_uniform((radius**2 - 0.25) / (0.64 - 0.25), "goal r^2 in the annulus")
    np.testing.assert_allclose(out["object_yaw"], 0.2, atol=1e-6)
    assert (goal[:, 2] >= -1.0).all() and (goal[:, 2] <= -0.5).all()
    assert (base[:, 2] >= 3.0).all() and (base[:, 2] <= 3.1).all()


def read_struct(cls, s):
    """The array fields of struct ``s`` (of Warp struct type ``cls``) as numpy arrays."""
    return {name: getattr(s, name).numpy() for name, var in cls.vars.items() if wp.types.is_array(var.type)}


def curriculum_draws(n, **levels):
    """The episodes ``sample_episodes`` draws for ``n`` worlds from the same random streams whatever the training
    curriculum ``levels`` (its keyword arguments: difficulty, object_mass, goal_radius, behind)."""
    _, task_np = random_state(np.random.default_rng(3), n)
    task, spec = make_struct(PushTask, **task_np), make_struct(sampling.EpisodeSpec, **random_spec(np.random.default_rng(4), n))
    sample_episodes(np.ones(n), 9, sampling_params(), task, spec, **levels)
    return read_struct(sampling.EpisodeSpec, spec)


def test_goal_difficulty_scales_the_goal_yaw_change():
    """Curriculum: at difficulty d the goal asks for d of the drawn yaw change; its position is unchanged."""
    n = 2000
    goals = {}
    for d in (1.0, 0.4, 0.0):
        out = curriculum_draws(n, difficulty=d)
        goals[d] = out["goal"]
        object_yaw = out["object_yaw"]
    wrap = lambda a: np.arctan2(np.sin(a), np.cos(a))  # noqa: E731
    close(goals[0.4][:, :2], goals[1.0][:, :2], atol=0)
    close(wrap(goals[0.4][:, 2] - object_yaw), 0.4 * wrap(goals[1.0][:, 2] - object_yaw), atol=1e-4)
    close(goals[0.0][:, :2], goals[1.0][:, :2], atol=0)
    close(wrap(goals[0.0][:, 2] - object_yaw), 0.0, atol=1e-6)


def test_object_mass_range_bounds_the_mass_and_nothing_else():
    """Mass curriculum: a narrower (low, high) draws the mass uniform in it; every other draw is unchanged."""
    n = 4000
    out = {}
    for mass in ((1.0, 10.0), (1.0, 2.5)):
        out[mass] = curriculum_draws(n, object_mass=mass)
    light, full = out[(1.0, 2.5)], out[(1.0, 10.0)]
    assert light["mass"].min() >= 1.0 and light["mass"].max() <= 2.5
    assert_uniform((light["mass"] - 1.0) / 1.5, "mass in the narrowed range")
    close((light["mass"] - 1.0) / 1.5, (full["mass"] - 1.0) / 9.0, atol=1e-5)  # the same draw, rescaled
    for name in full:
        if name != "mass":
            close(light[name], full[name], atol=0, err_msg=name)


def test_goal_radius_range_moves_the_goal_along_its_bearing_and_nothing_else():
    """Distance curriculum: a narrower (low, high) draws the goal uniform by area in that annulus, from the same draw
    (same bearing and yaw); every other draw is unchanged."""
    n = 4000
    out = {}
    for radius in ((0.0, 2.0), (0.4, 0.6)):
        out[radius] = curriculum_draws(n, goal_radius=radius)
    near, full = out[(0.4, 0.6)]["goal"], out[(0.0, 2.0)]["goal"]
    r_near, r_full = np.linalg.norm(near[:, :2], axis=1), np.linalg.norm(full[:, :2], axis=1)
    assert r_near.min() >= 0.4 - 1e-5 and r_near.max() <= 0.6 + 1e-5
    assert_uniform((r_near**2 - 0.16) / 0.2, "goal r^2 in the narrowed annulus")
    close((r_near**2 - 0.16) / 0.2, r_full**2 / 4.0, atol=1e-4)  # the same draw, rescaled
    close(np.arctan2(near[:, 1], near[:, 0]), np.arctan2(full[:, 1], full[:, 0]), atol=1e-4)
    close(near[:, 2], full[:, 2], atol=0)
    for name in out[(0.0, 2.0)]:
        if name != "goal":
            close(out[(0.4, 0.6)][name], out[(0.0, 2.0)][name], atol=0, err_msg=name)


def test_behind_starts_put_the_robot_opposite_the_goal_facing_the_object():
    """Start-state curriculum: at share 1 the base stands in the robot annulus at a bearing within ``spread`` of the
    one opposite the goal, heading toward the object within ``spread``; the object and goal are the paper's draws;
    at a share of 0.5 about half the worlds do."""
    n, spread = 4000, 0.3
    out = {}
    for share in (0.0, 1.0, 0.5):
        out[share] = curriculum_draws(n, behind=(share, spread))
    wrap = lambda a: np.arctan2(np.sin(a), np.cos(a))  # noqa: E731
    paper, behind = out[0.0], out[1.0]
    for name in paper:
        if name != "base":
            close(behind[name], paper[name], atol=0, err_msg=name)
    base, goal = behind["base"].astype(np.float64), behind["goal"].astype(np.float64)
    bearing_off = wrap(np.arctan2(base[:, 1], base[:, 0]) - np.arctan2(goal[:, 1], goal[:, 0]) - np.pi)
    assert np.abs(bearing_off).max() <= spread + 1e-4 and np.abs(bearing_off).mean() > 0.5 * spread * 0.8
    radius = np.linalg.norm(base[:, :2], axis=1)
    assert radius.min() >= 1.2 - 1e-4 and radius.max() <= 2.5 + 1e-4
    heading_off = wrap(base[:, 2] - np.arctan2(-base[:, 1], -base[:, 0]))
    assert np.abs(heading_off).max() <= spread + 1e-4
    assert_uniform((heading_off + spread) / (2 * spread), "heading about the one facing the object")
    moved = (out[0.5]["base"] != paper["base"]).any(axis=1).mean()
    assert abs(moved - 0.5) < 4 * math.sqrt(0.25 / n), f"share of behind starts {moved}"


def test_sample_episodes_draws_are_independent():
    """Every random quantity of an episode is its own draw: no two are correlated (|r| < 0.06 at n = 8000, where
    independent draws give |r| ~ 0.011). A wp.func receives the rng state by value, so draws inside one that
    did not fork a stream used to repeat the caller's next draw: robot bearing = goal bearing, friction = object
    yaw, ..."""
    n = 8000
    _, task_np = random_state(np.random.default_rng(5), n)
    task, spec = make_struct(PushTask, **task_np), make_struct(sampling.EpisodeSpec, **random_spec(np.random.default_rng(6), n))
    sample_episodes(np.ones(n), 13, sampling_params(cylinder_probability=0.0), task, spec)
    out = read_struct(sampling.EpisodeSpec, spec)
    goal, base, d = out["goal"], out["base"], out["dims"]
    draws = {
        "size_x": d[:, 0], "size_z": d[:, 2], "mass": out["mass"], "com_x": out["com_o"][:, 0] / d[:, 0],
        "friction": out["friction"], "object_yaw": out["object_yaw"], "reach_target_z": out["reach_target_o"][:, 2] / d[:, 2],
        "goal_r2": (goal[:, :2] ** 2).sum(1), "goal_bearing": np.arctan2(goal[:, 1], goal[:, 0]), "goal_yaw": goal[:, 2],
        "base_r2": (base[:, :2] ** 2).sum(1), "base_bearing": np.arctan2(base[:, 1], base[:, 0]), "base_yaw": base[:, 2],
        "arm_q0": out["arm_q"][:, 0], "base_mass_offset": out["base_mass_offset"], "first_push_step": out["first_push_step"],
    }
    names = list(draws)
    r = np.corrcoef(np.array([draws[k] for k in names], dtype=np.float64))
    np.fill_diagonal(r, 0.0)
    i, j = np.unravel_index(np.abs(r).argmax(), r.shape)
    assert abs(r[i, j]) < 0.06, f"{names[i]} and {names[j]} are correlated (r = {r[i, j]:.3f})"


def test_sample_episodes():
    rng = np.random.default_rng(7)
    n = 20000
    reset = (rng.uniform(size=n) < 0.9).astype(np.int32)
    r = reset == 1
    _, task_np = random_state(rng, n)
    before = random_spec(rng, n)
    task, spec = make_struct(PushTask, **task_np), make_struct(sampling.EpisodeSpec, **before)
    sample_episodes(reset, 11, sampling_params(), task, spec)
    out = read_struct(sampling.EpisodeSpec, spec)

    # Worlds that do not reset keep their episode; every reset world draws from a fresh stream.
    for name, value in before.items():
        close(out[name][~r], value[~r], atol=0, err_msg=f"{name} of a world that did not reset")
    np.testing.assert_array_equal(task.rng_counter.numpy(), task_np["rng_counter"] + reset)

    # Object (III-E): shape, dimensions (cylinder: x == y), mass, CoM, combined friction, yaw.
    shape, d, m = out["shape"][r], out["dims"][r], out["mass"][r]
    cyl = shape == 1
    assert set(np.unique(shape)) == {0, 1}
    assert abs(cyl.mean() - 0.3) < 4 * math.sqrt(0.3 * 0.7 / r.sum()), f"cylinder share {cyl.mean()}"
    for i, (lo, hi) in enumerate(((0.25, 0.75), (0.25, 0.75), (0.4, 1.0))):
        assert_uniform((d[~cyl, i] - lo) / (hi - lo), f"cuboid size {i}")
    assert_uniform((d[cyl, 0] - 0.25) / 0.5, "cylinder diameter")
    np.testing.assert_array_equal(d[cyl, 0], d[cyl, 1])
    assert np.abs(d[~cyl, 0] - d[~cyl, 1]).mean() > 0.1, "cuboid sides are independent"
    assert_uniform((m - 1.0) / 9.0, "mass")
    com_frac = out["com_o"][r] / d
    for i, (lo, hi) in enumerate(((-0.25, 0.25), (-0.25, 0.25), (-0.6, 0.25))):
        assert_uniform((com_frac[:, i] - lo) / (hi - lo), f"CoM fraction {i}")
    assert_uniform((out["friction"][r] - 0.4) / 0.85, "combined friction")
    for label, yaw in (("object", out["object_yaw"][r]), ("goal", out["goal"][r, 2]), ("base", out["base"][r, 2])):
        assert_uniform((yaw + np.pi) / (2 * np.pi), f"{label} yaw")

    # Goal uniform (by area) in the disc r <= 2 m; robot uniform (by area) in the annulus [1.2, 2.5] m (III-B).
    goal, base = out["goal"][r, :2], out["base"][r, :2]
    assert_uniform(np.sum(goal**2, axis=1) / 2.0**2, "goal r^2")
    assert_uniform((np.arctan2(goal[:, 1], goal[:, 0]) + np.pi) / (2 * np.pi), "goal angle")
    assert_uniform((np.sum(base**2, axis=1) - 1.2**2) / (2.5**2 - 1.2**2), "robot r^2")
    assert_uniform((np.arctan2(base[:, 1], base[:, 0]) + np.pi) / (2 * np.pi), "robot angle")

    # Arm joints around the default; base mass offset; first push after 7-10 s.
    arm_dev = out["arm_q"][r] - task_np["arm_default"]
    for j in range(5):
        assert_uniform((arm_dev[:, j] + 0.2) / 0.4, f"arm joint {j} noise")
    assert_uniform((out["base_mass_offset"][r] + 5.0) / 10.0, "base mass offset")
    push = out["first_push_step"][r]
    assert push.min() >= 350 and push.max() <= 499 and push.max() - push.min() > 140

    # Reach target uniform (by area) on the vertical surfaces (III-B, Fig. 2B).
    p_r, half = out["reach_target_o"][r], d / 2
    assert_uniform(p_r[:, 2] / d[:, 2] + 0.5, "reach target height")
    close(np.linalg.norm(p_r[cyl, :2], axis=1), half[cyl, 0], atol=1e-5, err_msg="on the cylinder's lateral surface")
    assert_uniform((np.arctan2(p_r[cyl, 1], p_r[cyl, 0]) + np.pi) / (2 * np.pi), "cylinder target angle")
    pc, hc, dc = p_r[~cyl], half[~cyl], d[~cyl]
    on_x = np.isclose(np.abs(pc[:, 0]), hc[:, 0], atol=1e-6) & (np.abs(pc[:, 1]) <= hc[:, 1] + 1e-6)
    on_y = np.isclose(np.abs(pc[:, 1]), hc[:, 1], atol=1e-6) & (np.abs(pc[:, 0]) <= hc[:, 0] + 1e-6)
    assert (on_x | on_y).all(), "cuboid targets lie on a vertical face"
    p_x = dc[:, 1] / (dc[:, 0] + dc[:, 1])  # share of the two x faces in the lateral area
    assert abs(on_x.sum() - p_x.sum()) < 4 * math.sqrt(np.sum(p_x * (1 - p_x))), "faces drawn by area"
    assert abs((pc[on_x, 0] > 0).mean() - 0.5) < 4 * math.sqrt(0.25 / on_x.sum())
    assert abs((pc[on_y & ~on_x, 1] > 0).mean() - 0.5) < 4 * math.sqrt(0.25 / (on_y & ~on_x).sum())
    assert_uniform(pc[on_x, 1] / dc[on_x, 1] + 0.5, "position along an x face")
    assert_uniform(pc[on_y, 0] / dc[on_y, 0] + 0.5, "position along a y face")

    # Ablation (Table I): the reach target at the centroid.
    spec = make_struct(sampling.EpisodeSpec, **random_spec(rng, 64))
    sample_episodes(np.ones(64), 3, sampling_params(surface_target=0), task, spec)
    np.testing.assert_array_equal(spec.reach_target_o.numpy(), 0.0)


def near_goal_episodes(n, seed, share, radius=0.1, max_yaw=0.6, reset=None):
    """``n`` worlds' episodes drawn from the same random state (seeds 31, 32) with near-goal starts (``share``,
    ``radius`` [m], ``max_yaw`` [rad]), every world flagged near before: (spec fields, start flags, ended flags)."""
    _, task_np = random_state(np.random.default_rng(31), n)
    task, spec = make_struct(PushTask, **task_np), make_struct(sampling.EpisodeSpec, **random_spec(np.random.default_rng(32), n))
    start, ended = sample_episodes(np.ones(n) if reset is None else reset, seed, sampling_params(), task, spec,
                                   near_goal=(share, radius, max_yaw), start_flags=np.ones(n))
    return read_struct(sampling.EpisodeSpec, spec), start, ended


def test_near_goal_share_zero_draws_todays_episodes():
    """Near-goal starts off: the episodes are the ones the sampler drew before the feature (values recorded from that
    kernel at this seed and state), and no world is flagged near."""
    out, start, ended = near_goal_episodes(6, 17, share=0.0, radius=0.1, max_yaw=0.6)
    close(out["goal"], [[-0.10308, -1.741165, 2.334892], [0.830037, -1.325282, -2.354484], [0.535396, 0.827074, -0.450989],
                        [-0.950761, 0.050223, 2.836998], [0.27713, -0.409834, -0.320092], [0.140153, -0.136377, 0.263292]],
          rtol=0, atol=2e-6)
    close(out["base"][:, 2], [1.590024, 1.800324, 0.111826, -2.544515, -1.575447, -2.496414], rtol=0, atol=2e-6)
    close(out["object_yaw"], [-3.131667, -1.368702, -0.795697, -1.838049, -2.489117, 2.933154], rtol=0, atol=2e-6)
    close(out["mass"], [7.33513, 7.045708, 9.254725, 2.371342, 3.787742, 2.267406], rtol=0, atol=2e-6)
    np.testing.assert_array_equal(out["first_push_step"], [383, 357, 401, 381, 428, 425])
    np.testing.assert_array_equal(start, 0)
    np.testing.assert_array_equal(ended, 1, err_msg="the ended episodes' flags are handed on")


def test_near_goal_share_one_puts_every_goal_near():
    """Share 1: every goal uniform (by area) in the disc ``radius`` around the object's start, its yaw the object's
    plus U(-max_yaw, max_yaw) (numpy reference of the distribution); every other draw is the plain sampler's."""
    n, radius, max_yaw = 8000, 0.1, 0.6
    plain, _, _ = near_goal_episodes(n, 23, share=0.0)
    out, start, _ = near_goal_episodes(n, 23, share=1.0, radius=radius, max_yaw=max_yaw)
    np.testing.assert_array_equal(start, 1)
    goal = out["goal"]
    r2 = np.sum(goal[:, :2] ** 2, axis=1)
    assert r2.max() <= radius**2 * (1 + 1e-5)
    assert_uniform(r2 / radius**2, "near goal r^2")
    assert_uniform((np.arctan2(goal[:, 1], goal[:, 0]) + np.pi) / (2 * np.pi), "near goal bearing")
    offset = goal[:, 2] - out["object_yaw"]
    assert np.abs(offset).max() <= max_yaw + 1e-5
    assert_uniform((offset + max_yaw) / (2 * max_yaw), "near goal yaw offset")
    for name, value in plain.items():
        if name != "goal":
            np.testing.assert_array_equal(out[name], value, err_msg=f"{name} differs from the plain sampler's")


def test_near_goal_share_half_and_worlds_that_do_not_reset():
    """Share 0.5: about half the reset worlds start near (4 sigma); a world that does not reset keeps its flags."""
    n = 8000
    reset = (np.random.default_rng(33).uniform(size=n) < 0.8).astype(np.int32)
    r = reset == 1
    out, start, ended = near_goal_episodes(n, 29, share=0.5, reset=reset)
    near = start[r] == 1
    assert abs(near.mean() - 0.5) < 4 * math.sqrt(0.25 / r.sum()), f"near-goal share {near.mean()}"
    assert (np.sum(out["goal"][r][near, :2] ** 2, axis=1) <= 0.1**2 * (1 + 1e-5)).all()
    assert np.sum(out["goal"][r][~near, :2] ** 2, axis=1).max() > 1.0, "the others keep the paper's 2 m disc"
    np.testing.assert_array_equal(start[~r], 1)
    np.testing.assert_array_equal(ended, np.where(r, 1, -1))


def test_start_episodes():
    rng = np.random.default_rng(12)
    n, nominal = 128, 40.0
    robot_np, task_np = random_state(rng, n)
    spec_np = random_spec(rng, n)
    reset = rng.integers(0, 2, n)
    r = reset == 1
    base_default = rng.uniform(-0.5, 0.5, 6).astype(np.float32)
    w = np.arange(n)
    robot, task = structs(robot_np, task_np)
    joint_q, body_mass = arr(robot_np["joint_q"]), arr(robot_np["body_mass"])
    inv_mass, variant = arr(1.0 / robot_np["body_mass"]), wp.full(n, 7, dtype=int, device=DEVICE)
    launch(sampling.start_episodes, n, arr(reset, int), make_struct(sampling.EpisodeSpec, **spec_np), sampling_params(),
           robot, task, arr(base_default), nominal, arr(w * Q, int), arr(w * Q + OBJECT_Q, int), joint_q, body_mass,
           inv_mass, variant)

    s = {k: v[r] for k, v in spec_np.items()}
    d, m, k = s["dims"], s["mass"], r.sum()
    # Principal moments: solid cylinder (radius d_x / 2, height d_z) about its axis z; solid cuboid.
    radius, sq = d[:, 0] / 2, d**2
    cylinder = np.column_stack([m * (3 * radius**2 + sq[:, 2]) / 12] * 2 + [m * radius**2 / 2])
    cuboid = np.column_stack([sq[:, 1] + sq[:, 2], sq[:, 0] + sq[:, 2], sq[:, 0] + sq[:, 1]]) * m[:, None] / 12
    inertia = np.where(s["shape"][:, None] == 1, cylinder, cuboid)
    expected_task = {name: value.copy() for name, value in task_np.items()}
    fresh = dict(
        object_shape=s["shape"], object_dims=d, object_mass=m, object_com_o=s["com_o"], object_inertia=inertia,
        object_friction=2.0 * s["friction"] - 0.4,  # Newton averages the object's and the floor's (0.4) coefficients
        reach_target_o=s["reach_target_o"], goal_pos=np.column_stack([s["goal"][:, :2], d[:, 2] / 2]),
        goal_quat=yaw_quat(s["goal"][:, 2]), arm_command=s["arm_q"], actions=np.zeros((k, 11)), last_actions=np.zeros((k, 11)),
        base_command=np.tile(base_default, (k, 1)), base_command_filtered=np.tile(base_default, (k, 1)),
        contacts=np.zeros((k, CONTACT_COLUMNS)), episode_step=np.zeros(k), reach_reward_held=np.zeros(k),
        next_push_step=s["first_push_step"],
    )
    for name, value in fresh.items():
        expected_task[name][r] = value
    for name, value in read_struct(PushTask, task).items():
        close(value, expected_task[name], rtol=1e-5, atol=1e-6, err_msg=name)

    q = robot_np["joint_q"].reshape(n, Q).copy()
    q[r, 0:7] = np.column_stack([s["base"][:, :2], np.full(k, 0.5), yaw_quat(s["base"][:, 2])])  # nominal height
    q[r, ARM_Q:ARM_Q + 6] = np.column_stack([s["arm_q"], np.full(k, 0.3)])  # frozen 6th joint
    q[r, OBJECT_Q:OBJECT_Q + 7] = np.column_stack([np.zeros((k, 2)), d[:, 2] / 2, yaw_quat(s["object_yaw"])])
    close(joint_q.numpy().reshape(n, Q), q, atol=1e-6)
    mass = robot_np["body_mass"].copy()
    mass[robot_np["base_body"][r]] = nominal + s["base_mass_offset"]
    close(body_mass.numpy(), mass, rtol=1e-6)
    close(inv_mass.numpy()[robot_np["base_body"][r]], 1.0 / mass[robot_np["base_body"][r]], rtol=1e-6)
    np.testing.assert_array_equal(variant.numpy(), np.where(r, spec_np["shape"], -1))


def test_zero_velocities():
    rng = np.random.default_rng(8)
    n = 32
    reset = rng.integers(0, 2, n)
    qd0 = rng.normal(size=n * QD).astype(np.float32)
    qd = arr(qd0)
    w = np.arange(n)
    launch(sampling.zero_velocities, n, arr(reset, int), arr(w * QD, int), ARM_QD + 6, arr(w * QD + OBJECT_QD, int), qd)
    expected = qd0.reshape(n, QD).copy()
    expected[reset == 1] = 0.0  # robot (free base + arm) and object DOFs
    close(qd.numpy().reshape(n, QD), expected, atol=0)


def test_apply_object_properties():
    rng = np.random.default_rng(9)
    n, shapes_per_world = 64, 3
    _, task_np = random_state(rng, n)
    dims = task_np["object_dims"]
    dims[:, 1] = np.where(task_np["object_shape"] == 1, dims[:, 0], dims[:, 1])
    reset = rng.integers(0, 2, n)
    r = reset == 1
    w = np.arange(n)
    object_body, object_shape = w * STRIDE, w * shapes_per_world + 1
    ns, nb = n * shapes_per_world, n * STRIDE
    before = dict(scale=rng.normal(size=(ns, 3)), radius=rng.uniform(size=ns), lower=rng.normal(size=(ns, 3)),
                  upper=rng.normal(size=(ns, 3)), mu=rng.uniform(size=ns), mass=rng.uniform(1, 2, nb),
                  inv_mass=rng.uniform(1, 2, nb), com=rng.normal(size=(nb, 3)), inertia=rng.normal(size=(nb, 3, 3)),
                  inv_inertia=rng.normal(size=(nb, 3, 3)))
    dtypes = dict(scale=wp.vec3, lower=wp.vec3, upper=wp.vec3, com=wp.vec3, inertia=wp.mat33, inv_inertia=wp.mat33)
    buffers = {k: arr(v, dtypes.get(k, float)) for k, v in before.items()}
    task = make_struct(PushTask, **task_np)
    launch(sampling.apply_object_properties, n, arr(reset, int), task, arr(object_body, int), arr(object_shape, int),
           *(buffers[k] for k in ("scale", "radius", "lower", "upper", "mu", "mass", "inv_mass", "com", "inertia", "inv_inertia")))

    expected = {k: np.asarray(v, np.float32).astype(np.float64).copy() for k, v in before.items()}
    s, b = object_shape[r], object_body[r]
    half = task_np["object_dims"][r] / 2
    cyl = task_np["object_shape"][r] == 1
    # Newton primitives: box (hx, hy, hz); cylinder (radius, half height) about its z axis.
    expected["scale"][s] = np.where(cyl[:, None], np.column_stack([half[:, 0], half[:, 2], np.zeros(r.sum())]), half)
    expected["radius"][s] = np.where(cyl, np.hypot(half[:, 0], half[:, 2]), np.linalg.norm(half, axis=1))
    expected["lower"][s], expected["upper"][s] = -half, half
    expected["mu"][s] = task_np["object_friction"][r]
    expected["mass"][b] = task_np["object_mass"][r]
    expected["inv_mass"][b] = 1.0 / task_np["object_mass"][r]
    expected["com"][b] = task_np["object_com_o"][r]
    inertia = task_np["object_inertia"][r]
    expected["inertia"][b] = inertia[:, :, None] * np.eye(3)
    expected["inv_inertia"][b] = (1.0 / inertia)[:, :, None] * np.eye(3)
    assert cyl.any() and (~cyl).any()
    for k, buf in buffers.items():
        close(buf.numpy(), expected[k], rtol=1e-6, atol=1e-7, err_msg=k)


def test_apply_pushes():
    rng = np.random.default_rng(10)
    n = 4000
    robot_np, task_np = random_state(rng, n)
    task_np["next_push_step"] = task_np["episode_step"] + rng.integers(-3, 3, n)
    pushed = task_np["episode_step"] >= task_np["next_push_step"]
    robot, task = structs(robot_np, task_np)
    body_qd = arr(robot_np["body_qd"], wp.spatial_vector)
    launch(sampling.apply_pushes, n, 12, sampling_params(), robot, task, body_qd)

    base = robot_np["base_body"]
    expected = robot_np["body_qd"].copy()
    after = body_qd.numpy()
    dv = after[base] - robot_np["body_qd"][base]
    expected[base[pushed]] = after[base[pushed]]
    close(after, expected, atol=0, err_msg="only the linear xy velocity of pushed bases changes")
    close(dv[:, 2:], 0.0, atol=1e-6)
    assert (np.abs(dv[pushed, :2]) <= 0.5 + 1e-5).all() and (np.linalg.norm(dv[pushed, :2], axis=1) > 1e-6).all()
    assert_uniform((dv[pushed, 0] + 0.5) / 1.0, "push vx")
    step = task_np["episode_step"]
    nxt = task.next_push_step.numpy()
    np.testing.assert_array_equal(nxt[~pushed], task_np["next_push_step"][~pushed])
    assert (nxt[pushed] - step[pushed] >= 350).all() and (nxt[pushed] - step[pushed] <= 500).all()
    np.testing.assert_array_equal(task.rng_counter.numpy(), task_np["rng_counter"] + pushed)


# --------------------------------------------------------------------------- contacts (Table "Rewards and constraints")
def test_classify_contacts():
    """Hand-built contact lists of 2 worlds; shapes per world: object, EE, leg (column 3), base
    (column 0), forearm (column 12, self-collision column 15), wrist (allowed, self column 17); one
    ground shape (world -1, no body)."""
    roles = [contacts.ROLE_OBJECT, contacts.ROLE_EE, 3, 0, 12, contacts.ROLE_ROBOT]
    self_cols = [-1, -1, -1, -1, 15, 17]
    OBJ, EE, LEG, BASE, FOREARM, WRIST = range(6)
    n, per = 2, len(roles)
    ground = n * per
    shape = lambda w, s: w * per + s  # noqa: E731
    shape_role = np.array(roles * n + [contacts.ROLE_NONE])
    shape_self = np.array(self_cols * n + [-1])
    shape_world = np.array([w for w in range(n) for _ in range(per)] + [-1])
    shape_body = np.array(list(range(n * per)) + [-1])  # one body per shape, the ground has none
    rng = np.random.default_rng(11)
    body_q = np.column_stack([rng.uniform(-1, 1, (n * per, 3)), random_quat(rng, n * per)])
    dist = 0.005

    # (shape0, shape1, gap [m]); the first `count` entries are live.
    pairs = [
        (shape(0, LEG), shape(0, OBJ), 0.002),  # object vs leg -> column 3
        (shape(1, OBJ), shape(1, EE), -0.01),  # EE contact -> EE column
        (shape(1, FOREARM), shape(1, BASE), 0.0),  # self-collision -> column 15 (not 0, not 12)
        (shape(0, OBJ), ground, -0.02),  # ground contacts are ignored
        (ground, shape(0, LEG), 0.0),
        (shape(0, BASE), shape(0, OBJ), 0.02),  # gap beyond contact_distance: ignored
        (shape(1, WRIST), shape(1, OBJ), 0.0),  # allowed robot-object contact
        (-1, shape(1, OBJ), 0.0),  # invalid shape
        (shape(0, FOREARM), shape(0, OBJ), 0.0),  # beyond contact_count: ignored
    ]
    count = len(pairs) - 1
    normal = unit(rng.normal(size=(len(pairs), 3)))
    margin0, margin1 = rng.uniform(0, 0.01, len(pairs)), rng.uniform(0, 0.01, len(pairs))
    p0_w = rng.uniform(-1, 1, (len(pairs), 3))
    gaps = np.array([g for _, _, g in pairs])
    p1_w = p0_w + normal * (gaps + margin0 + margin1)[:, None]

    def to_body(s, p):  # world point -> the shape's body frame (the ground's points stay in world)
        if s < 0 or shape_body[s] < 0:
            return p
        x = body_q[shape_body[s]]
        return quat_rotate_inv(x[3:], p - x[:3])

    a, b = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    point0 = np.array([to_body(s, p) for s, p in zip(a, p0_w)])
    point1 = np.array([to_body(s, p) for s, p in zip(b, p1_w)])
    initial = np.zeros((n, CONTACT_COLUMNS), np.int32)
    initial[0, 7] = 1  # set by an earlier substep: contacts accumulate
    task = make_struct(PushTask, contacts=initial)
    launch(contacts.classify_contacts, len(pairs), arr([count], int), arr(a, int), arr(b, int), arr(point0, wp.vec3),
           arr(point1, wp.vec3), arr(normal, wp.vec3), arr(margin0), arr(margin1), arr(shape_body, int),
           arr(shape_world, int), arr(shape_role, int), arr(shape_self, int), arr(body_q, wp.transform), dist, task)

    expected = initial.copy()
    expected[0, 3] = expected[1, EE_CONTACT] = expected[1, 15] = 1
    np.testing.assert_array_equal(task.contacts.numpy(), expected)
