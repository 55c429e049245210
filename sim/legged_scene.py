"""Builds the Newton model of the locomotion scene: N legged robots (``robot_legged.usda``) on the shared ground.

Worlds do not collide with each other, so every robot starts at the world origin. The robot's leg and arm
joints are located by name (Newton orders them as the USD file lists them, LF, LH, RF, RH), so every index
array here is in ``LEG_JOINT_NAMES`` / ``ARM_JOINT_NAMES`` order.
"""

from __future__ import annotations

from dataclasses import dataclass

import newton
import numpy as np
import warp as wp
from pxr import Usd

from dynpush.assets_usd import ARM_JOINT_NAMES, EE_SHAPE, GROUND_USD, LEG_JOINT_NAMES, ROBOT_LEGGED_USD
from dynpush.kernels.locomotion import views as loco_views

from .config import MuJoCoConfig

LEGS = ("LF", "RF", "LH", "RH")


def _leaf(label: str) -> str:
    return label.rstrip("/").rsplit("/", 1)[-1]


@dataclass
class LeggedRobotDescription:
    """What the locomotion environment reads from ``robot_legged.usda`` (SI units, radians)."""

    leg_default: np.ndarray  # (12,) nominal stance, LEG_JOINT_NAMES order
    leg_lower: np.ndarray  # (12,)
    leg_upper: np.ndarray  # (12,)
    leg_stiffness: np.ndarray  # (12,) [N m/rad]
    leg_damping: np.ndarray  # (12,) [N m s/rad]
    leg_effort_limit: np.ndarray  # (12,) [N m]
    leg_velocity_limit: np.ndarray  # (12,) [rad/s]
    arm_default: np.ndarray  # (6,)
    arm_lower: np.ndarray  # (6,)
    arm_upper: np.ndarray  # (6,)
    base_mass: float  # [kg]
    foot_offset: np.ndarray  # (3,) foot sphere centre in the shank frame
    foot_radius: float
    knee_radius: float  # thigh capsule radius (its lower cap is centred on the knee, the shank origin)
    shank_end: np.ndarray  # (3,) lower cap centre of the shank capsule in the shank frame
    shank_radius: float
    base_half_extents: np.ndarray  # (3,) of the base box collider


@dataclass
class LeggedScene:
    model: newton.Model
    robot: LeggedRobotDescription
    num_worlds: int
    base_body: np.ndarray  # (N,)
    base_q_start: np.ndarray  # (N,)
    base_qd_start: np.ndarray  # (N,)
    robot_qd_count: int
    leg_q: np.ndarray  # (N, 12) joint_q indices
    leg_qd: np.ndarray  # (N, 12)
    arm_q: np.ndarray  # (N, 6)
    arm_qd: np.ndarray  # (N, 6)
    shank_body: np.ndarray  # (N, 4)
    ee_body: np.ndarray  # (N,) the last arm link, which carries the end-effector
    ee_offset: np.ndarray  # (3,) end-effector point (centre of its collision sphere) in the ee_body frame [m]


def _read_defaults() -> tuple[np.ndarray, np.ndarray]:
    stage = Usd.Stage.Open(str(ROBOT_LEGGED_USD))
    root = stage.GetDefaultPrim()
    legs = np.asarray(root.GetAttribute("dynpush:defaultLegJointPositions").Get(), dtype=np.float64)
    arm = np.asarray(root.GetAttribute("dynpush:defaultArmJointPositions").Get(), dtype=np.float64)
    return legs, arm


def legged_robot_builder(enable_self_collisions: bool = False) -> tuple[newton.ModelBuilder, LeggedRobotDescription]:
    """The legged robot from its USD file, in its default stance at the nominal height."""
    builder = newton.ModelBuilder()
    builder.add_usd(str(ROBOT_LEGGED_USD), enable_self_collisions=enable_self_collisions)
    leg_default, arm_default = _read_defaults()
    joint = {_leaf(label): j for j, label in enumerate(builder.joint_label)}
    shape = {_leaf(label): s for s, label in enumerate(builder.shape_label)}
    leg_dofs = [builder.joint_qd_start[joint[name]] for name in LEG_JOINT_NAMES]
    arm_dofs = [builder.joint_qd_start[joint[name]] for name in ARM_JOINT_NAMES]
    take = lambda values, dofs: np.array([values[d] for d in dofs], dtype=np.float64)  # noqa: E731
    q = list(builder.joint_q)
    q[0:7] = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]
    for name, value in zip(LEG_JOINT_NAMES + ARM_JOINT_NAMES, np.concatenate([leg_default, arm_default])):
        q[builder.joint_q_start[joint[name]]] = float(value)
    builder.joint_q = q

    def translation(name: str) -> np.ndarray:
        return np.array(wp.transform_get_translation(builder.shape_transform[shape[name]]), dtype=np.float64)

    # The shank capsule's cap centre farther from the knee (the shank frame origin).
    shank = shape["LF_shank"]
    half = float(builder.shape_scale[shank][1])
    ends = [np.array(wp.transform_point(builder.shape_transform[shank], wp.vec3(0.0, 0.0, s * half))) for s in (-1.0, 1.0)]
    shank_end = max(ends, key=np.linalg.norm)
    description = LeggedRobotDescription(
        leg_default=leg_default,
        leg_lower=take(builder.joint_limit_lower, leg_dofs),
        leg_upper=take(builder.joint_limit_upper, leg_dofs),
        leg_stiffness=take(builder.joint_target_ke, leg_dofs),
        leg_damping=take(builder.joint_target_kd, leg_dofs),
        leg_effort_limit=take(builder.joint_effort_limit, leg_dofs),
        leg_velocity_limit=take(builder.joint_velocity_limit, leg_dofs),
        arm_default=arm_default,
        arm_lower=take(builder.joint_limit_lower, arm_dofs),
        arm_upper=take(builder.joint_limit_upper, arm_dofs),
        base_mass=float(builder.body_mass[builder.shape_body[shape["base_collision"]]]),
        foot_offset=translation("LF_foot"),
        foot_radius=float(builder.shape_scale[shape["LF_foot"]][0]),
        knee_radius=float(builder.shape_scale[shape["LF_thigh"]][0]),
        shank_end=shank_end,
        shank_radius=float(builder.shape_scale[shank][0]),
        base_half_extents=np.array(builder.shape_scale[shape["base_collision"]], dtype=np.float64),
    )
    return builder, description


def build_legged_scene(num_worlds: int, device: str) -> LeggedScene:
    """Replicates the legged robot into ``num_worlds`` worlds over one ground and finalizes on ``device``."""
    robot, description = legged_robot_builder()
    builder = newton.ModelBuilder()
    builder.replicate(robot, num_worlds)
    builder.add_usd(str(GROUND_USD))
    model = builder.finalize(device=device)

    joint = {_leaf(label): j for j, label in enumerate(robot.joint_label)}
    body = {_leaf(label): b for b, label in enumerate(robot.body_label)}
    ee_shape = next(s for s, label in enumerate(robot.shape_label) if _leaf(label) == EE_SHAPE)
    coords, dofs, bodies = robot.joint_coord_count, robot.joint_dof_count, robot.body_count
    w = np.arange(num_worlds)[:, None]
    q_index = lambda names: w * coords + np.array([robot.joint_q_start[joint[n]] for n in names])  # noqa: E731
    qd_index = lambda names: w * dofs + np.array([robot.joint_qd_start[joint[n]] for n in names])  # noqa: E731
    free = next(j for j in range(robot.joint_count) if robot.joint_type[j] == newton.JointType.FREE)
    return LeggedScene(
        model=model,
        robot=description,
        num_worlds=num_worlds,
        base_body=(w[:, 0] * bodies + body["base"]),
        base_q_start=w[:, 0] * coords + robot.joint_q_start[free],
        base_qd_start=w[:, 0] * dofs + robot.joint_qd_start[free],
        robot_qd_count=dofs,
        leg_q=q_index(LEG_JOINT_NAMES),
        leg_qd=qd_index(LEG_JOINT_NAMES),
        arm_q=q_index(ARM_JOINT_NAMES),
        arm_qd=qd_index(ARM_JOINT_NAMES),
        shank_body=w * bodies + np.array([body[f"{leg}_SHANK"] for leg in LEGS]),
        ee_body=w[:, 0] * bodies + robot.shape_body[ee_shape],
        ee_offset=np.array(wp.transform_get_translation(robot.shape_transform[ee_shape]), dtype=np.float64),
    )


def mujoco_solver(model: newton.Model, cfg: MuJoCoConfig, use_mujoco_contacts: bool) -> newton.solvers.SolverMuJoCo:
    """MuJoCo-Warp on ``model`` with ``cfg``'s solver, iteration caps and buffers. The iteration caps are deliberate
    (``MuJoCoConfig``): only buffer overflows still warn."""
    import mujoco_warp

    solver = newton.solvers.SolverMuJoCo(model, use_mujoco_contacts=use_mujoco_contacts, solver=cfg.solver,
                                         iterations=cfg.iterations, ls_iterations=cfg.ls_iterations,
                                         nconmax=cfg.nconmax, njmax=cfg.njmax)
    solver.mjw_model.opt.warn_overflow &= ~(mujoco_warp.OverflowType.ITERATIONS | mujoco_warp.OverflowType.LS_ITERATIONS)
    return solver


def legged_view(state: newton.State, base_body, base_q_start, base_qd_start, robot_qd_count: int, leg_q, leg_qd, arm_q,
                arm_qd, shank_body) -> loco_views.LeggedView:
    """The kernels' view of the legged robots in ``state`` from per-world index arrays (numpy)."""
    i32 = lambda a: wp.array(np.asarray(a, dtype=np.int32), dtype=int)  # noqa: E731
    i32_2d = lambda a: wp.array2d(np.asarray(a, dtype=np.int32), dtype=int)  # noqa: E731
    view = loco_views.LeggedView()
    view.body_q, view.body_qd, view.joint_q, view.joint_qd = state.body_q, state.body_qd, state.joint_q, state.joint_qd
    view.base_body, view.base_q_start, view.base_qd_start = i32(base_body), i32(base_q_start), i32(base_qd_start)
    view.robot_qd_count = robot_qd_count
    view.leg_q, view.leg_qd, view.arm_q, view.arm_qd = i32_2d(leg_q), i32_2d(leg_qd), i32_2d(arm_q), i32_2d(arm_qd)
    view.shank_body = i32_2d(shank_body)
    return view


def locomotion_task(num_worlds: int, command: wp.array2d | None = None) -> loco_views.LocomotionTask:
    """Zeroed locomotion task buffers; ``command`` (num_worlds, 6) is used as the command buffer if given."""
    n = num_worlds
    task = loco_views.LocomotionTask()
    task.command = command if command is not None else wp.zeros((n, loco_views.NUM_COMMANDS), dtype=float)
    for name, width in (("actions", loco_views.NUM_LEG_JOINTS), ("last_actions", loco_views.NUM_LEG_JOINTS),
                        ("leg_target", loco_views.NUM_LEG_JOINTS), ("leg_velocity_last", loco_views.NUM_LEG_JOINTS),
                        ("arm_target", loco_views.NUM_ARM_JOINTS + 1), ("foot_air_time", loco_views.NUM_FEET),
                        ("touchdown_air_time", loco_views.NUM_FEET), ("ee_force_h", 3)):
        setattr(task, name, wp.zeros((n, width), dtype=float))
    task.foot_contact = wp.zeros((n, loco_views.NUM_FEET), dtype=int)
    task.base_mass_offset = wp.zeros(n, dtype=float)
    for name in ("episode_step", "next_command_step", "next_arm_step", "next_push_step", "next_ee_force_step", "rng_counter"):
        setattr(task, name, wp.zeros(n, dtype=int))
    return task
