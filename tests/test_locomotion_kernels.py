"""Every Warp kernel of ``dynpush.kernels.locomotion`` against an independent numpy reference on random states.

The references follow the formulas, frames and layouts of the module docstring, not the kernel code. Fake
model: per world ``NB`` bodies (base + 4 shanks, shuffled), ``NQ`` joint coordinates (free joint p, quat
xyzw, then 18 leg/arm coordinates in shuffled order) and ``NQD`` DOFs (free joint, then 18 shuffled), so
that the kernels must go through the index arrays. All launches run on the CPU device.
"""

import math

import numpy as np
import pytest
import warp as wp

from dynpush.kernels.locomotion import (
    actions as actions_k,
    constraints as constraints_k,
    contacts as contacts_k,
    observations as observations_k,
    rewards as rewards_k,
    sampling as sampling_k,
    terminations as terminations_k,
    views as views_k,
)
from warp_numpy_helpers import (DEVICE, arr, as_f32, axis_angle_quat, close, launch, make_struct, quat_matrix, quat_mul,
                                quat_rotate, quat_rotate_inv, random_quat)

wp.config.enable_backward = False
wp.config.quiet = True

NB, NQ, NQD = 5, 25, 24
DT = 0.02
EZ = np.array([0.0, 0.0, 1.0])


# --------------------------------------------------------------------------- numpy helpers
def f32(x):
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def tilted_quat(rng, n, max_tilt):
    """Uniform yaw, then a tilt in [0, max_tilt] about a random horizontal axis."""
    axis = np.column_stack([rng.normal(size=(n, 2)), np.zeros(n)])
    yaw = axis_angle_quat(np.tile(EZ, (n, 1)), rng.uniform(-np.pi, np.pi, n))
    return quat_mul(yaw, axis_angle_quat(axis, rng.uniform(0.0, max_tilt, n)))


def heading(q, v):
    """(R_yaw^T v, roll, pitch) with the yaw of the base x axis projected on the ground."""
    R_b = quat_matrix(q)
    yaw = np.arctan2(R_b[:, 1, 0], R_b[:, 0, 0])
    c, s, z = np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)
    R_yaw = np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.tile(EZ, (len(yaw), 1))], 1)
    v_h = np.einsum("nji,nj->ni", R_yaw, v)
    z_h = np.einsum("nji,nj->ni", R_yaw, R_b[:, :, 2])
    return v_h, np.arctan2(-z_h[:, 1], z_h[:, 2]), np.arctan2(z_h[:, 0], z_h[:, 2])


# --------------------------------------------------------------------------- scenes and structs


def random_scene(rng, n):
    """Random ``LeggedView`` and ``LocomotionTask`` fields (numpy, float32-exact) of ``n`` worlds."""
    w = np.arange(n)[:, None]
    bodies = np.array([rng.permutation(NB) for _ in range(n)]) + NB * w
    q_idx = np.array([rng.permutation(18) for _ in range(n)]) + 7 + NQ * w
    qd_idx = np.array([rng.permutation(18) for _ in range(n)]) + 6 + NQD * w
    body_q = np.column_stack([rng.uniform(-2, 2, (n * NB, 2)), rng.uniform(0.0, 0.5, n * NB), random_quat(rng, n * NB)])
    body_q[bodies[:, 0], 3:] = tilted_quat(rng, n, 0.6)
    view = dict(
        body_q=body_q, body_qd=rng.normal(size=(n * NB, 6)), joint_q=rng.normal(size=n * NQ),
        joint_qd=3.0 * rng.normal(size=n * NQD), base_body=bodies[:, 0], shank_body=bodies[:, 1:],
        base_q_start=NQ * w[:, 0], base_qd_start=NQD * w[:, 0], robot_qd_count=NQD,
        leg_q=q_idx[:, :12], arm_q=q_idx[:, 12:], leg_qd=qd_idx[:, :12], arm_qd=qd_idx[:, 12:],
    )
    contact = rng.integers(0, 2, (n, 4))
    task = dict(
        command=np.column_stack([rng.uniform(-1, 1, (n, 3)), rng.uniform(-0.4, 0.4, (n, 2)), rng.uniform(0.2, 0.6, n)]),
        actions=rng.normal(size=(n, 12)), last_actions=rng.normal(size=(n, 12)),
        leg_target=rng.normal(size=(n, 12)), leg_velocity_last=3.0 * rng.normal(size=(n, 12)),
        arm_target=rng.normal(size=(n, 6)), foot_contact=contact,
        foot_air_time=np.where(contact == 1, 0.0, rng.uniform(0.0, 0.6, (n, 4))),
        touchdown_air_time=np.where(rng.uniform(size=(n, 4)) < 0.5, -1.0, rng.uniform(0.0, 0.5, (n, 4))),
        base_mass_offset=rng.uniform(-3, 3, n), episode_step=rng.integers(0, 1000, n),
        next_command_step=rng.integers(0, 1000, n), next_arm_step=rng.integers(0, 1000, n),
        next_push_step=rng.integers(0, 1000, n), next_ee_force_step=rng.integers(0, 1000, n),
        ee_force_h=rng.normal(scale=50.0, size=(n, 3)), rng_counter=rng.integers(0, 5, n),
    )
    return as_f32(view), as_f32(task)


def structs(view, task):
    return make_struct(views_k.LeggedView, **view), make_struct(views_k.LocomotionTask, **task)


def read(cls, s):
    return {name: getattr(s, name).numpy() for name, var in cls.vars.items() if wp.types.is_array(var.type)}


def loco_params(rng, **overrides):
    """A ``LocomotionParams`` and its numpy values."""
    values = dict(  # arm joints 1-4 are clipped by one of their limits at +- arm_amplitude
        leg_default=rng.uniform(-1, 1, 12), leg_lower=rng.uniform(-2.5, -1.5, 12), leg_upper=rng.uniform(1.5, 2.5, 12),
        arm_default=[0.1, -0.2, 0.3, 0.0, 0.2, 0.1],
        arm_lower=[-2.0, -0.6, -1.5, -0.7, -2.0, -0.3], arm_upper=[2.0, 1.5, 0.6, 2.0, 0.7, 0.3],
        action_scale=0.4, clip=2.5, command_lower=[-1.0, -0.5, -0.8, -0.3, -0.2, 0.3],
        command_upper=[1.5, 0.5, 0.8, 0.3, 0.25, 0.6], standing_probability=0.25, command_interval=(100.0, 200.0),
        arm_amplitude=[0.8, 0.8, 0.8, 0.8, 0.6], arm_interval=(50.0, 150.0), push_interval=(300.0, 400.0), push_velocity=0.5,
        start_height=0.55, leg_position_noise=0.1, disturbance_scale=[1.0], ee_force_interval=(60.0, 120.0),
        ee_force_probability=0.6, ee_force_max=80.0, ee_force_spread=0.7,
    )
    values.update(overrides)
    return make_struct(views_k.LocomotionParams, **values), as_f32({n: np.asarray(v) for n, v in values.items()})


def limits_struct(**values):
    base = dict(contact_margin=0.02, control_dt=DT, foot_radius=0.03, foot_offset=(0.02, -0.01, -0.3))
    base.update(values)
    return make_struct(views_k.LeggedLimits, **base)


def test_layout_constants():
    assert (observations_k.NUM_POLICY_OBS, observations_k.NUM_CRITIC_OBS, constraints_k.NUM_CONSTRAINTS) == (61, 67, 61)


# --------------------------------------------------------------------------- actions
def test_process_leg_actions_and_arm_targets():
    rng = np.random.default_rng(1)
    n = 64
    view_np, task_np = random_scene(rng, n)
    params, p = loco_params(rng)
    raw = (3.0 * rng.normal(size=(n, 12))).astype(np.float32)
    raw[0, 0], raw[1, 5], raw[2, 11], raw[3, 7] = np.nan, np.inf, -np.inf, np.nan
    target0 = rng.normal(size=n * NQ).astype(np.float32)
    view, task = structs(view_np, task_np)
    joint_target_q = arr(target0)
    launch(actions_k.process_leg_actions, n, arr(raw), params, view, task, joint_target_q)
    legs_only = target0.astype(np.float64)
    asked = p["leg_default"] + f32(0.4) * np.clip(np.where(np.isfinite(raw), raw, 0.0), -2.5, 2.5)
    assert ((asked < p["leg_lower"]) | (asked > p["leg_upper"])).any()
    legs_only[view_np["leg_q"]] = np.clip(asked, p["leg_lower"], p["leg_upper"])
    close(joint_target_q.numpy(), legs_only, rtol=1e-6, atol=1e-6, err_msg="process_leg_actions writes leg targets only")
    launch(actions_k.write_arm_targets, n, view, task, joint_target_q)

    a = np.clip(np.where(np.isfinite(raw), raw, 0.0), -2.5, 2.5)
    assert (np.abs(raw[np.isfinite(raw)]) > 2.5).any() and (np.abs(raw) < 2.5).any()
    close(task.last_actions.numpy(), task_np["actions"], atol=0, err_msg="history shifted")
    close(task.actions.numpy(), a, atol=0, err_msg="clipped, non-finite -> 0")
    leg = np.clip(p["leg_default"] + f32(0.4) * a, p["leg_lower"], p["leg_upper"])  # clamped to the joint ranges
    close(task.leg_target.numpy(), leg, rtol=1e-6, atol=1e-6)
    expected = target0.astype(np.float64)
    expected[view_np["leg_q"]] = leg
    expected[view_np["arm_q"]] = task_np["arm_target"]
    close(joint_target_q.numpy(), expected, rtol=1e-6, atol=1e-6, err_msg="leg/arm targets at their joint_q, rest untouched")


def test_write_leg_targets_passes_them_as_given():
    rng = np.random.default_rng(2)
    n = 64
    view_np, task_np = random_scene(rng, n)
    targets = (5.0 * rng.normal(size=(n, 12))).astype(np.float32)  # beyond any action's reach: nothing is clipped
    target0 = rng.normal(size=n * NQ).astype(np.float32)
    view, task = structs(view_np, task_np)
    joint_target_q = arr(target0)
    launch(actions_k.write_leg_targets, n, arr(targets), view, task, joint_target_q)
    expected = target0.copy()
    expected[view_np["leg_q"]] = targets
    close(joint_target_q.numpy(), expected, atol=0, err_msg="leg targets at their joint_q exactly, the rest untouched")
    close(task.leg_target.numpy(), targets, atol=0)
    close(task.actions.numpy(), task_np["actions"], atol=0, err_msg="the action history is not this kernel's")
    close(task.last_actions.numpy(), task_np["last_actions"], atol=0)


# --------------------------------------------------------------------------- feet
def test_write_ee_force():
    """The heading-frame end-effector force turned by the base's yaw, as a wrench about the ee link's centre of mass
    with the force at the end-effector point, in the ee link's rows of both ``body_f`` arrays and nowhere else."""
    rng = np.random.default_rng(12)
    n = 500
    view_np, task_np = random_scene(rng, n)
    ee_body = view_np["shank_body"][:, 2]  # any link of the world but the base
    body_com = f32(rng.uniform(-0.1, 0.1, (n * NB, 3)))
    ee_offset = f32([0.08, -0.02, 0.03])
    body_f = [f32(rng.normal(size=(n * NB, 6))) for _ in range(2)]
    view, task = structs(view_np, task_np)
    out = [arr(f, wp.spatial_vector) for f in body_f]
    launch(actions_k.write_ee_force, n, view, task, arr(ee_body, int), wp.vec3(*ee_offset), arr(body_com, wp.vec3),
           *out)

    q = view_np["body_q"]
    x_base = quat_matrix(q[view_np["base_body"], 3:])[:, :, 0]
    yaw = np.arctan2(x_base[:, 1], x_base[:, 0])
    f_h = task_np["ee_force_h"]
    force_w = np.column_stack([np.cos(yaw) * f_h[:, 0] - np.sin(yaw) * f_h[:, 1],
                               np.sin(yaw) * f_h[:, 0] + np.cos(yaw) * f_h[:, 1], f_h[:, 2]])
    x_ee = q[ee_body]
    p_ee = x_ee[:, :3] + quat_rotate(x_ee[:, 3:], ee_offset)
    c_ee = x_ee[:, :3] + quat_rotate(x_ee[:, 3:], body_com[ee_body])
    expected = np.column_stack([force_w, np.cross(p_ee - c_ee, force_w)])
    others = np.setdiff1d(np.arange(n * NB), ee_body)
    for before, after in zip(body_f, out):
        after = after.numpy()
        close(after[ee_body], expected, rtol=1e-4, atol=1e-3)
        close(after[others], before[others], atol=0, err_msg="other bodies untouched")


def test_update_feet():
    rng = np.random.default_rng(2)
    n, margin, radius = 64, 0.02, 0.03
    offset = np.array([0.02, -0.01, -0.3])
    view_np, task_np = random_scene(rng, n)
    shank = view_np["shank_body"]
    case = rng.permutation(np.arange(4 * n) % 4).reshape(n, 4)  # 0 stays down, 1 lifts off, 2 stays up, 3 touches down
    was_down, is_down = (case <= 1), (case % 3 == 0)
    clear = margin + np.where(is_down, -1, 1) * rng.uniform(0.005, 0.2, (n, 4))  # foot sphere height above ground
    q_s = view_np["body_q"][shank, 3:]
    view_np["body_q"][shank, 2] = clear + radius - quat_rotate(q_s, offset)[..., 2]
    task_np["foot_contact"] = was_down.astype(np.int32)
    task_np["foot_air_time"] = np.where(was_down, 0.0, rng.uniform(0.0, 0.6, (n, 4)))
    view_np, task_np = as_f32(view_np), as_f32(task_np)
    view, task = structs(view_np, task_np)
    limits = limits_struct(contact_margin=margin, foot_radius=radius, foot_offset=tuple(offset))
    launch(contacts_k.update_feet, n, view, limits, task)

    air = np.float32(task_np["foot_air_time"]) + np.float32(DT)  # float32 sum, as the kernel
    np.testing.assert_array_equal(task.foot_contact.numpy(), is_down.astype(int))
    close(task.foot_air_time.numpy(), np.where(is_down, 0.0, air), rtol=1e-6, atol=0, err_msg="air time")
    close(task.touchdown_air_time.numpy(), np.where(case == 3, air, -1.0), rtol=1e-6, atol=0, err_msg="touchdown")
    assert np.isin(np.arange(4), case).all()


# --------------------------------------------------------------------------- rewards
def test_compute_rewards():
    rng = np.random.default_rng(3)
    n = 512
    view_np, task_np = random_scene(rng, n)
    base = view_np["base_body"]
    view_np["body_q"][base[: n // 8], 3:] = random_quat(rng, n // 8)  # a few fully random attitudes
    view_np["body_qd"][base] *= 0.6
    view_np["body_q"][base, 2] = rng.uniform(0.2, 0.7, n)
    view_np = as_f32(view_np)
    sig = np.array([0.5, 0.7, 0.2, 0.02])
    task_np["command"][: n // 4, :3] = 0.0  # standing commands collect no stepping reward
    air = rng.uniform(0.0, 1.0, (n, 4)).astype(np.float32)
    task_np["touchdown_air_time"] = np.where(rng.uniform(size=(n, 4)) < 0.3, air, -1.0).astype(np.float32)
    prm = make_struct(rewards_k.LocomotionRewardParams, weights=rng.uniform(0.5, 2.0, rewards_k.NUM_REWARD_TERMS))
    prm.sigma_linear_velocity, prm.sigma_yaw_rate, prm.sigma_attitude, prm.sigma_height = sig
    prm.air_time_target, prm.moving_command = 0.5, 0.1
    view, task = structs(view_np, task_np)
    reward = wp.zeros(n, dtype=float, device=DEVICE)
    terms = wp.zeros((n, rewards_k.NUM_REWARD_TERMS), dtype=float, device=DEVICE)
    error = wp.zeros((n, 6), dtype=float, device=DEVICE)
    launch(rewards_k.compute_rewards, n, view, task, prm, reward, terms, error)

    x_b, qd_b, u = view_np["body_q"][base], view_np["body_qd"][base], task_np["command"]
    v_h, roll, pitch = heading(x_b[:, 3:], qd_b[:, :3])
    e = [np.sum((u[:, :2] - v_h[:, :2]) ** 2, 1), (u[:, 2] - qd_b[:, 5]) ** 2,
         (u[:, 3] - roll) ** 2 + (u[:, 4] - pitch) ** 2, (u[:, 5] - x_b[:, 2]) ** 2]
    moving = np.linalg.norm(u[:, :2], axis=1) + np.abs(u[:, 2]) > 0.1
    touchdown = task_np["touchdown_air_time"]
    stepping = np.where(moving, np.where(touchdown >= 0.0, touchdown - 0.5, 0.0).sum(1), 0.0)
    assert (~moving).sum() >= n // 4 and (stepping != 0).mean() > 0.5
    action_rate = -np.sum((task_np["actions"] - task_np["last_actions"]) ** 2, axis=1)
    vertical_velocity = -qd_b[:, 2] ** 2
    omega_b = np.einsum("nji,nj->ni", quat_matrix(x_b[:, 3:]), qd_b[:, 3:])  # R_b^T omega_w
    roll_pitch_rate = -(omega_b[:, 0] ** 2 + omega_b[:, 1] ** 2)
    ref = np.column_stack([*(np.exp(-ei / s) for ei, s in zip(e, sig)), stepping, action_rate, vertical_velocity,
                           roll_pitch_rate]) * prm.weights.numpy()
    assert (ref.std(axis=0) > 0.1 * prm.weights.numpy()).all(), "every term should vary across the random states"
    close(terms.numpy(), ref, atol=2e-5, rtol=1e-5,
          err_msg="w_i exp(-e_i^2 / sigma_i), w_5 sum(t_air - target) at touchdowns while moving, -w_6 sum(da^2),"
                  " -w_7 v_z^2, -w_8 (omega_x,b^2 + omega_y,b^2)")
    close(reward.numpy(), ref.sum(1), atol=5e-5, rtol=1e-5)
    measured = np.column_stack([v_h[:, :2], qd_b[:, 5], roll, pitch, x_b[:, 2]])
    close(error.numpy(), u - measured, atol=2e-5, err_msg="tracking errors command - measured (vx, vy, yaw rate, roll, pitch, height)")


# --------------------------------------------------------------------------- constraints
def test_compute_constraints():
    rng = np.random.default_rng(4)
    n = 512
    view_np, task_np = random_scene(rng, n)
    base, shank = view_np["base_body"], view_np["shank_body"]
    view_np["body_q"][:, 2] = rng.uniform(-0.05, 0.45, n * NB)
    view_np["body_q"][base[: n // 4], 3:] = random_quat(rng, n // 4)
    view_np, task_np = as_f32(view_np), as_f32(task_np)
    lim = dict(stiffness=rng.uniform(20, 80, 12), damping=rng.uniform(0.5, 2, 12), effort_limit=rng.uniform(40, 80, 12),
               nominal_torque=rng.uniform(10, 40, 12), velocity_limit=rng.uniform(2, 6, 12),
               acceleration_limit=200.0, action_rate_limit=60.0, air_time_min=0.25, foot_force_limit=300.0, knee_radius=0.06,
               shank_end=(0.01, 0.02, -0.25), shank_radius=0.03, base_half_extents=(0.35, 0.15, 0.1), collision_margin=0.03)
    limits = limits_struct(**lim)
    lim = as_f32({n: np.asarray(v) for n, v in lim.items()})
    view, task = structs(view_np, task_np)
    out = wp.zeros((n, constraints_k.NUM_CONSTRAINTS), dtype=float, device=DEVICE)
    foot_force = f32(rng.uniform(0.0, 600.0, (n, 4)))
    launch(constraints_k.compute_constraints, n, view, task, limits, arr(foot_force), out)

    q, qd = view_np["joint_q"][view_np["leg_q"]], view_np["joint_qd"][view_np["leg_qd"]]
    tau_pd = lim["stiffness"] * (task_np["leg_target"] - q) - lim["damping"] * qd
    tau = np.clip(tau_pd, -lim["effort_limit"], lim["effort_limit"])
    x_b, x_s = view_np["body_q"][base], view_np["body_q"][shank]
    signs = np.array([[1 if c >> i & 1 else -1 for i in range(3)] for c in range(8)])
    corners = x_b[:, None, :3] + quat_rotate(x_b[:, None, 3:], signs * lim["base_half_extents"])
    knee = x_s[..., 2] - lim["knee_radius"]
    end = x_s[..., 2] + quat_rotate(x_s[..., 3:], lim["shank_end"])[..., 2] - lim["shank_radius"]
    touchdown = task_np["touchdown_air_time"]
    groups = {
        "leg_joint_torque": np.abs(tau) - lim["nominal_torque"],
        "leg_joint_velocity": np.abs(qd) - lim["velocity_limit"],
        "leg_joint_acceleration": np.abs(qd - task_np["leg_velocity_last"]) / DT - 200.0,
        "leg_action_rate": np.abs(task_np["actions"] - task_np["last_actions"]) / DT - 60.0,
        "collision": 0.03 - np.column_stack([corners[..., 2].min(1), np.minimum(knee, end)]),
        "foot_air_time": np.where(touchdown >= 0, 0.25 - touchdown, 0.0),
        "foot_contact_force": foot_force - 300.0,
    }
    assert [(name, g.shape[1]) for name, g in groups.items()] == list(constraints_k.CONSTRAINT_GROUPS)
    assert (tau_pd > lim["effort_limit"]).any() and (tau_pd < -lim["effort_limit"]).any(), "both clip sides"
    assert (np.abs(tau_pd) > lim["nominal_torque"]).any() and (knee < end).any() and (end < knee).any()
    actual, start = out.numpy(), 0
    for name, g in groups.items():
        assert (g > 0).any() and (g < 0).any(), f"random states should both violate and satisfy {name}"
        close(actual[:, start: start + g.shape[1]], g, rtol=1e-4, atol=1e-4, err_msg=name)
        start += g.shape[1]
    np.testing.assert_array_equal(actual[:, -8][touchdown[:, 0] < 0], 0.0)
    close(task.leg_velocity_last.numpy(), qd, atol=0, err_msg="leg_velocity_last <- this step's qd")


def test_gather_foot_forces():
    """Sensor row 4 w + f (world w, lower leg f) -> |F| [N] at foot_force[w, f]."""
    rng = np.random.default_rng(7)
    n = 64
    total = f32(rng.normal(0.0, 150.0, (n * 4, 3)))
    out = wp.zeros((n, 4), dtype=float, device=DEVICE)
    launch(contacts_k.gather_foot_forces, n, wp.array(total, dtype=wp.vec3, device=DEVICE), out)
    close(out.numpy(), np.linalg.norm(total, axis=1).reshape(n, 4), rtol=1e-5)


# --------------------------------------------------------------------------- terminations
def test_compute_terminations():
    rng = np.random.default_rng(5)
    n, max_steps, max_tilt, min_height = 512, 500, 0.8, 0.25
    view_np, task_np = random_scene(rng, n)
    base = view_np["base_body"]
    view_np["body_q"][base, 3:] = tilted_quat(rng, n, 1.6)
    view_np["body_q"][base, 2] = rng.uniform(0.1, 0.7, n)
    task_np["episode_step"] = rng.integers(max_steps - 4, max_steps, n)
    view_np = as_f32(view_np)
    view, task = structs(view_np, task_np)
    limits = limits_struct(base_tilt=max_tilt, base_min_height=min_height, max_episode_steps=max_steps)
    reset, time_out = wp.zeros(n, dtype=int, device=DEVICE), wp.zeros(n, dtype=int, device=DEVICE)
    launch(terminations_k.compute_terminations, n, view, task, limits, reset, time_out)

    step = task_np["episode_step"] + 1
    tilt = np.arccos(np.clip(quat_rotate(view_np["body_q"][base, 3:], EZ)[:, 2], -1, 1))
    tilted, low, timed = tilt > max_tilt, view_np["body_q"][base, 2] < min_height, step >= max_steps
    for label, mask in (("timed out", timed & ~tilted & ~low), ("tilted", tilted & ~low & ~timed),
                        ("low", low & ~tilted & ~timed), ("fallen at time-out", timed & (tilted | low)),
                        ("normal", ~timed & ~tilted & ~low)):
        assert mask.any(), f"no world in case {label}"
    np.testing.assert_array_equal(task.episode_step.numpy(), step)
    np.testing.assert_array_equal(reset.numpy(), (tilted | low | timed).astype(int))
    np.testing.assert_array_equal(time_out.numpy(), (timed & ~tilted & ~low).astype(int), err_msg="time-out only")


# --------------------------------------------------------------------------- observations
def test_compute_observations():
    rng = np.random.default_rng(6)
    n = 128
    view_np, task_np = random_scene(rng, n)
    view_np["body_q"][view_np["base_body"][::2], 3:] = random_quat(rng, n // 2)
    view_np = as_f32(view_np)
    params, p = loco_params(rng)
    scale = f32(rng.uniform(0.01, 0.2, observations_k.NUM_POLICY_OBS))
    scale[::7] = 0.0
    x_b, qd_b = view_np["body_q"][view_np["base_body"]], view_np["body_qd"][view_np["base_body"]]
    jq, jqd = view_np["joint_q"], view_np["joint_qd"]
    ref = np.column_stack([
        quat_rotate_inv(x_b[:, 3:], qd_b[:, :3]), quat_rotate_inv(x_b[:, 3:], qd_b[:, 3:]),
        quat_rotate_inv(x_b[:, 3:], -EZ), task_np["command"], jq[view_np["leg_q"]] - p["leg_default"],
        jqd[view_np["leg_qd"]], task_np["actions"], jq[view_np["arm_q"][:, :5]] - p["arm_default"][:5],
        jqd[view_np["arm_qd"][:, :5]], x_b[:, 2], task_np["foot_contact"], task_np["base_mass_offset"],
    ])
    assert ref.shape[1] == observations_k.NUM_CRITIC_OBS
    policies = []
    for noise in (0, 1):
        view, task = structs(view_np, task_np)
        policy = wp.zeros((n, observations_k.NUM_POLICY_OBS), dtype=float, device=DEVICE)
        critic = wp.zeros((n, observations_k.NUM_CRITIC_OBS), dtype=float, device=DEVICE)
        launch(observations_k.compute_observations, n, view, task, params, arr(scale), noise, 7, policy, critic)
        close(critic.numpy(), ref, rtol=1e-5, atol=1e-5, err_msg=f"critic observation (noise {noise})")
        policies.append(policy.numpy() - critic.numpy()[:, : observations_k.NUM_POLICY_OBS])
    np.testing.assert_array_equal(policies[0], 0.0, err_msg="noise disabled: policy = critic[:61]")
    d = np.abs(policies[1])
    assert (d <= scale * (1 + 1e-5) + 1e-6).all(), "noise within +- noise_scale"
    assert (d[:, scale == 0] == 0).all() and (d[:, scale > 0] > 0).mean() > 0.99
    assert (d / np.maximum(scale, 1e-9))[:, scale > 0].max() > 0.95, "noise spans its range"


# --------------------------------------------------------------------------- episodes and events
def test_start_episodes():
    rng = np.random.default_rng(7)
    n = 4000
    view_np, task_np = random_scene(rng, n)
    reset = (rng.uniform(size=n) < 0.7).astype(np.int32)
    r = reset == 1
    params, p = loco_params(rng)
    view, task = structs(view_np, task_np)
    launch(sampling_k.start_episodes, n, arr(reset, int), 3, params, view, task)
    out = read(views_k.LocomotionTask, task)
    jq, jqd = view.joint_q.numpy().reshape(n, NQ), view.joint_qd.numpy().reshape(n, NQD)
    leg_q, arm_q = jq[np.arange(n)[:, None], view_np["leg_q"] % NQ], jq[np.arange(n)[:, None], view_np["arm_q"] % NQ]

    close(jq[~r], view_np["joint_q"].reshape(n, NQ)[~r], atol=0, err_msg="joint_q of worlds that did not reset")
    close(jqd[~r], view_np["joint_qd"].reshape(n, NQD)[~r], atol=0, err_msg="joint_qd of worlds that did not reset")
    for name, value in out.items():
        close(value[~r], task_np[name][~r], atol=0, err_msg=f"{name} of a world that did not reset")
    np.testing.assert_array_equal(out["rng_counter"], task_np["rng_counter"] + reset)

    close(jq[r, :3], np.tile([0.0, 0.0, 0.55], (r.sum(), 1)), atol=1e-6, err_msg="base at (0, 0, start_height)")
    quat = jq[r, 3:7]
    close(quat[:, :2], 0.0, atol=0, err_msg="pure-yaw quaternion")
    close(np.linalg.norm(quat, axis=1), 1.0, atol=1e-6)
    yaw = 2 * np.arctan2(quat[:, 2], quat[:, 3])
    assert yaw.min() < -3.0 and yaw.max() > 3.0 and abs(np.mean(yaw > 0) - 0.5) < 0.05
    dev = leg_q[r] - p["leg_default"]
    assert (np.abs(dev) <= 0.1 + 1e-6).all() and dev.min() < -0.09 and dev.max() > 0.09, "legs within default +- noise"
    close(out["leg_target"][r], leg_q[r], atol=0, err_msg="leg targets = the reset leg positions")
    close(arm_q[r], np.tile(p["arm_default"], (r.sum(), 1)), atol=0, err_msg="arm at its default")
    close(out["arm_target"][r], np.tile(p["arm_default"], (r.sum(), 1)), atol=0)
    np.testing.assert_array_equal(jqd[r], 0.0, err_msg="velocities zeroed")
    for name, value in (("actions", 0), ("last_actions", 0), ("leg_velocity_last", 0), ("foot_contact", 1),
                        ("foot_air_time", 0), ("touchdown_air_time", -1), ("episode_step", 0), ("ee_force_h", 0)):
        np.testing.assert_array_equal(out[name][r], value, err_msg=name)
    check_commands(out["command"][r], p, "start_episodes")
    for name, (lo, hi) in (("next_command_step", (100, 200)), ("next_arm_step", (50, 150)), ("next_push_step", (300, 400)),
                           ("next_ee_force_step", (60, 120))):
        s = out[name][r]
        assert s.min() >= lo and s.max() <= hi and s.max() - s.min() > 0.9 * (hi - lo), f"{name} in [{lo}, {hi}]"
    # Every draw is its own (a wp.func gets the rng state by value: draws inside one that did not fork a
    # stream repeated the caller's next draw, tying the event steps together and to the standing decision).
    standing = (out["command"][r, :3] == 0).all(1).astype(float)
    draws = {"standing": standing, "height": out["command"][r, 5], "yaw": yaw,
             "leg_noise": dev[:, 0], **{name: out[name][r].astype(float) for name in ("next_command_step", "next_arm_step",
                                                                                     "next_push_step", "next_ee_force_step")}}
    names = list(draws)
    corr = np.corrcoef(np.array([draws[name] for name in names]))
    np.fill_diagonal(corr, 0.0)
    i, j = np.unravel_index(np.abs(corr).argmax(), corr.shape)
    assert abs(corr[i, j]) < 0.1, f"{names[i]} and {names[j]} are correlated (r = {corr[i, j]:.3f})"


def check_commands(u, p, label):
    """Commands within [lower, upper]; a standing_probability share has vx = vy = yaw rate = 0."""
    assert ((u >= p["command_lower"] - 1e-6) & (u <= p["command_upper"] + 1e-6)).all(), f"{label}: commands in range"
    standing = (u[:, :3] == 0).all(1)
    share, m = standing.mean(), len(u)
    assert abs(share - 0.25) < 4 * math.sqrt(0.25 * 0.75 / m), f"{label}: standing share {share:.3f} of {m}"
    assert (u[~standing, :3] != 0).all() and (u[standing, 3:] != 0).all()
    for i in range(6):
        x = u[~standing, i]
        lo, hi = p["command_lower"][i], p["command_upper"][i]
        assert x.min() < lo + 0.05 * (hi - lo) and x.max() > hi - 0.05 * (hi - lo), f"{label}: command {i} spread"


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_apply_events(scale):
    """``scale``: the disturbance curriculum's share of the arm amplitudes (0.8, 0.8, 0.8, 0.8, 0.6 rad), push
    velocity (0.5 m/s) and end-effector force (up to 80 N)."""
    rng = np.random.default_rng(8)
    n = 6000
    view_np, task_np = random_scene(rng, n)
    step = task_np["episode_step"]
    events = ("next_command_step", "next_arm_step", "next_push_step", "next_ee_force_step")
    for name in events:
        task_np[name] = step + rng.integers(-2, 3, n)
    cmd, arm, push, force = (step >= task_np[name] for name in events)
    params, p = loco_params(rng, disturbance_scale=[scale])
    amplitude, push_velocity = p["arm_amplitude"] * scale, 0.5 * scale
    view, task = structs(view_np, task_np)
    launch(sampling_k.apply_events, n, 5, params, view, task)
    out = read(views_k.LocomotionTask, task)

    changed = (("command", cmd), ("next_command_step", cmd), ("arm_target", arm), ("next_arm_step", arm),
               ("next_push_step", push), ("ee_force_h", force), ("next_ee_force_step", force))
    for name, fired in changed:
        close(out[name][~fired], task_np[name][~fired], atol=0, err_msg=f"{name} without its event")
    for name in (n for n in out if n not in dict(changed) and n != "rng_counter"):
        close(out[name], task_np[name], atol=0, err_msg=name)
    np.testing.assert_array_equal(out["rng_counter"], task_np["rng_counter"] + cmd + arm + push + force)
    for name, fired, (lo, hi) in (("next_command_step", cmd, (100, 200)), ("next_arm_step", arm, (50, 150)),
                                  ("next_push_step", push, (300, 400)), ("next_ee_force_step", force, (60, 120))):
        d = out[name][fired] - step[fired]
        assert d.min() >= lo and d.max() <= hi and d.max() - d.min() > 0.9 * (hi - lo), f"{name} rescheduled"

    check_commands(out["command"][cmd], p, "apply_events")
    target, default = out["arm_target"][arm], p["arm_default"]
    lo, hi = p["arm_lower"][:5], p["arm_upper"][:5]
    dev = target[:, :5] - default[:5]
    assert (np.abs(dev) <= amplitude + 1e-6).all(), "within default +- amplitude"
    close(dev.min(0), np.maximum(-amplitude, lo - default[:5]), atol=0.02 * amplitude.min(), err_msg="lowest target per joint")
    close(dev.max(0), np.minimum(amplitude, hi - default[:5]), atol=0.02 * amplitude.min(), err_msg="highest target per joint")
    assert ((target[:, :5] >= lo) & (target[:, :5] <= hi)).all(), "clipped to the limits"
    at_lo, at_hi = (target[:, :5] == lo).mean(0), (target[:, :5] == hi).mean(0)
    expect_lo = np.maximum(lo - (default[:5] - amplitude), 0) / (2 * amplitude)
    expect_hi = np.maximum(default[:5] + amplitude - hi, 0) / (2 * amplitude)
    close(at_lo, expect_lo, atol=0.04, err_msg="share of targets clipped at the lower limit")
    close(at_hi, expect_hi, atol=0.04, err_msg="share of targets clipped at the upper limit")
    close(target[:, 5], np.full(arm.sum(), default[5]), atol=0, err_msg="6th arm joint at its default")

    before, after = view_np["joint_qd"].reshape(n, NQD), view.joint_qd.numpy().reshape(n, NQD)
    dv = after - before
    np.testing.assert_array_equal(dv[~push], 0.0, err_msg="joint_qd of worlds without a push")
    np.testing.assert_array_equal(dv[:, 2:], 0.0, err_msg="only the linear xy free-joint velocity changes")
    assert (np.abs(dv[push, :2]) <= push_velocity + 1e-5).all() and (np.abs(dv[push, :2]) > 0).mean() > 0.99
    assert np.abs(dv[push, :2]).max() > 0.98 * push_velocity
    close(view.joint_q.numpy(), view_np["joint_q"], atol=0, err_msg="joint_q untouched")

    # End-effector force: none for 1 - probability of the draws, else horizontal, magnitude uniform in
    # [0, 80 scale] N, direction uniform within +- 0.7 rad of the heading frame's -x.
    f = out["ee_force_h"][force]
    magnitude = np.linalg.norm(f, axis=1)
    on = magnitude > 0
    assert abs(on.mean() - 0.6) < 4 * math.sqrt(0.24 / len(f)), f"share of forces {on.mean():.3f}"
    np.testing.assert_array_equal(f[:, 2], 0.0, err_msg="horizontal")
    f_max = 80.0 * scale
    assert magnitude.max() <= f_max * (1 + 1e-6) and magnitude.max() > 0.98 * f_max
    assert abs(np.mean(magnitude[on]) / f_max - 0.5) < 0.03, "uniform magnitude"
    angle = np.arctan2(-f[on, 1], -f[on, 0])  # from -x
    assert np.abs(angle).max() <= 0.7 + 1e-5 and angle.min() < -0.68 and angle.max() > 0.68
    assert abs(np.mean(angle)) < 0.04 and abs(np.corrcoef(angle, magnitude[on])[0, 1]) < 0.1
