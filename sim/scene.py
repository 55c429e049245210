"""Builds the Newton model of the push scene from the USD assets: N worlds, one robot and one object each.

The robot comes from ``robot.usda`` through Newton's USD importer; the object is one free body whose
shape is a body variant (cuboid or cylinder, from ``object_*.usda``) selected per world at every
reset; the ground comes from ``ground.usda`` and is shared by all worlds. Worlds do not collide with
each other, so every environment has its origin at the world origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import newton
import numpy as np
import warp as wp
from pxr import Usd

from dynpush.assets_usd import (
    ARM_JOINT_NAMES, ARM_LINK_NAMES, CUBOID_USD, CYLINDER_USD, EE_SHAPE, GROUND_USD, LEG_JOINT_NAMES, LEG_SHAPE_NAMES, ROBOT_USD,
)
from dynpush.kernels.push.contacts import ROLE_EE, ROLE_NONE, ROLE_OBJECT, ROLE_ROBOT

from .leg_statics import leg_torque_map
from .legged_scene import LEGS, LeggedRobotDescription, legged_robot_builder

wp.config.log_level = wp.LOG_WARNING  # no per-module "load on device" lines on the console

# Collision columns (paper Table "Rewards and constraints", 18): object vs each of these robot parts ...
OBJECT_COLLISION_PARTS = ("base_collision", *LEG_SHAPE_NAMES, "shoulder", "upper_arm", "elbow", "forearm")
# ... then self-collisions of these arm links with the base or legs.
SELF_COLLISION_LINKS = ("upper_arm", "elbow", "forearm", "wrist_1", "wrist_2")


def _leaf(label: str) -> str:
    return label.rstrip("/").rsplit("/", 1)[-1]


@dataclass
class RobotDescription:
    """What the environment reads from ``robot.usda`` (all SI, radians)."""

    arm_default: np.ndarray  # (6,) default arm configuration
    arm_lower: np.ndarray  # (6,)
    arm_upper: np.ndarray  # (6,)
    arm_velocity_limit: np.ndarray  # (6,)
    arm_stiffness: np.ndarray  # (6,)
    arm_damping: np.ndarray  # (6,)
    arm_peak_torque: np.ndarray  # (6,)
    base_mass: float
    leg_torque_map: np.ndarray | None  # (12, 6) quasi-static leg torques of a base wrench; None with articulated legs
    legged: LeggedRobotDescription | None = None  # the articulated legs (robot_legged.usda), else None


@dataclass
class Scene:
    """The finalized model and the per-world indices the kernels need."""

    model: newton.Model
    robot: RobotDescription
    ground_friction: float  # the floor's own coefficient (ground.usda)
    num_worlds: int
    bodies_per_world: int
    base_body: np.ndarray  # (N,) per world
    object_body: np.ndarray
    ee_body: np.ndarray
    ee_offset: np.ndarray  # (3,) in the ee body frame
    object_shape: np.ndarray  # (N,) the object's collider row
    robot_q_start: np.ndarray  # (N,) joint_q index of the robot's free joint
    robot_qd_start: np.ndarray
    robot_qd_count: int
    arm_q_start: np.ndarray  # (N,) joint_q index of SH_ROT
    arm_qd_start: np.ndarray
    object_q_start: np.ndarray
    object_qd_start: np.ndarray
    robot_body_start: np.ndarray
    robot_body_count: int
    shape_role: np.ndarray  # (shape_count,) ROLE_* or a collision column
    shape_self_column: np.ndarray  # (shape_count,) self-collision column or -1
    # Articulated legs only (build_scene(legged=True)), in LEG_JOINT_NAMES order, else None:
    leg_q: np.ndarray | None = None  # (N, 12) joint_q indices
    leg_qd: np.ndarray | None = None  # (N, 12) joint_qd indices
    arm_q: np.ndarray | None = None  # (N, 6) joint_q indices
    arm_qd: np.ndarray | None = None  # (N, 6)
    shank_body: np.ndarray | None = None  # (N, 4) LF, RF, LH, RH


def _read_robot_attributes() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    stage = Usd.Stage.Open(str(ROBOT_USD))
    root = stage.GetDefaultPrim()
    arm_default = np.asarray(root.GetAttribute("dynpush:defaultArmJointPositions").Get(), dtype=np.float64)
    base = next(p for p in stage.Traverse() if p.GetName() == "base")
    legs = {
        "hip": np.asarray(base.GetAttribute("dynpush:legHipPositions").Get(), dtype=np.float64),
        "foot": np.asarray(base.GetAttribute("dynpush:legNominalFootPositions").Get(), dtype=np.float64),
        "thigh_length": float(base.GetAttribute("dynpush:legThighLength").Get()),
    }
    return arm_default, legs


def _robot_builder(legged: bool) -> tuple[newton.ModelBuilder, RobotDescription, dict]:
    if legged:
        builder, legs_description = legged_robot_builder(enable_self_collisions=True)
    else:
        builder = newton.ModelBuilder()
        builder.add_usd(str(ROBOT_USD), enable_self_collisions=True)
    arm_default, legs = _read_robot_attributes()

    joint_index = {_leaf(label): j for j, label in enumerate(builder.joint_label)}
    dofs = [builder.joint_qd_start[joint_index[name]] for name in ARM_JOINT_NAMES]
    take = lambda values: np.array([values[d] for d in dofs], dtype=np.float64)  # noqa: E731
    shape_index = {_leaf(label): s for s, label in enumerate(builder.shape_label)}
    body_index = {_leaf(label): b for b, label in enumerate(builder.body_label)}

    # Arm links do not collide with each other (adjacent capsules overlap by construction); articulated legs
    # collide with neither the base nor each other (hips and thighs overlap the base box by construction).
    arm_shapes = [s for s in range(builder.shape_count) if _leaf(builder.body_label[builder.shape_body[s]]) in ARM_LINK_NAMES]
    body_shapes = [s for s in range(builder.shape_count) if s not in arm_shapes] if legged else []
    for group in (arm_shapes, body_shapes):
        for i, a in enumerate(group):
            for b in group[i + 1 :]:
                builder.add_shape_collision_filter_pair(a, b)

    torque_map = None
    if not legged:  # knees from the thigh capsules on the base: the capsule end farther from the hip
        knees, haa, hfe = [], [], []
        for leg, name in enumerate(LEGS):
            s = shape_index[f"{name}_thigh"]
            xform = builder.shape_transform[s]
            half = builder.shape_scale[s][1]
            ends = [np.array(wp.transform_point(xform, wp.vec3(0.0, 0.0, sign * half))) for sign in (-1.0, 1.0)]
            hip = legs["hip"][leg]
            ends.sort(key=lambda p: np.linalg.norm(p - hip))
            hfe.append(ends[0])
            knees.append(ends[1])
            haa.append(hip)
        torque_map = leg_torque_map(np.array(haa), np.array(hfe), np.array(knees), legs["foot"])

    description = RobotDescription(
        arm_default=arm_default,
        arm_lower=take(builder.joint_limit_lower),
        arm_upper=take(builder.joint_limit_upper),
        arm_velocity_limit=take(builder.joint_velocity_limit),
        arm_stiffness=take(builder.joint_target_ke),
        arm_damping=take(builder.joint_target_kd),
        arm_peak_torque=take(builder.joint_effort_limit),
        base_mass=float(builder.body_mass[body_index["base"]]),
        leg_torque_map=torque_map,
        legged=legs_description if legged else None,
    )
    names = {"shape": shape_index, "body": body_index, "joint": joint_index, "arm_shapes": arm_shapes}
    return builder, description, names


def build_scene(num_worlds: int, device: str, legged: bool = False) -> Scene:
    """Replicates robot + object into ``num_worlds`` worlds and finalizes the model on ``device``.

    ``legged``: the robot of ``robot_legged.usda`` (articulated legs whose feet stand on the ground) instead of
    the tracked base's ``robot.usda`` (leg colliders on the base that never touch the ground)."""
    robot, description, names = _robot_builder(legged)

    variants = []
    for path in (CUBOID_USD, CYLINDER_USD):
        variant = newton.ModelBuilder()
        variant.add_usd(str(path))
        variants.append(variant)

    world = newton.ModelBuilder()
    world.add_builder(robot)
    robot_body_count = world.body_count
    object_body = world.add_body(label="object")
    world.add_body_variants(object_body, variants, labels=["cuboid", "cylinder"])

    builder = newton.ModelBuilder()
    builder.replicate(world, num_worlds)
    builder.add_usd(str(GROUND_USD))
    ground_shapes = [s for s in range(builder.shape_count) if builder.shape_world[s] < 0]

    # Leg capsules of the tracked base stand for stepping legs: they never touch the floor (the base floats).
    shapes_per_world = world.shape_count
    leg_local = [] if legged else [names["shape"][n] for n in LEG_SHAPE_NAMES]
    for w in range(num_worlds):
        for s in leg_local:
            for g in ground_shapes:
                builder.add_shape_collision_filter_pair(w * shapes_per_world + s, g)

    model = builder.finalize(device=device)

    # Roles of the shapes of world 0, repeated for every world.
    role = np.full(shapes_per_world, ROLE_NONE, dtype=np.int32)
    self_column = np.full(shapes_per_world, -1, dtype=np.int32)
    link_of = {s: _leaf(robot.body_label[robot.shape_body[s]]) for s in range(robot.shape_count)}
    for s in range(robot.shape_count):
        role[s] = ROLE_ROBOT
    for column, part in enumerate(OBJECT_COLLISION_PARTS):
        for s in range(robot.shape_count):
            if _leaf(robot.shape_label[s]) == part or (part in ARM_LINK_NAMES and link_of[s] == part):
                role[s] = column
    for offset, link in enumerate(SELF_COLLISION_LINKS):
        for s in names["arm_shapes"]:
            if link_of[s] == link:
                self_column[s] = len(OBJECT_COLLISION_PARTS) + offset
    role[names["shape"][EE_SHAPE]] = ROLE_EE
    role[robot.shape_count :] = ROLE_OBJECT
    shape_role = np.concatenate([np.tile(role, num_worlds), np.full(model.shape_count - shapes_per_world * num_worlds, ROLE_NONE, np.int32)])
    shape_self_column = np.concatenate([np.tile(self_column, num_worlds), np.full(model.shape_count - shapes_per_world * num_worlds, -1, np.int32)])

    bodies_per_world = world.body_count
    w_idx = np.arange(num_worlds)
    coords_per_world, dofs_per_world = world.joint_coord_count, world.joint_dof_count
    joint_q_start = np.asarray(world.joint_q_start)
    joint_qd_start = np.asarray(world.joint_qd_start)
    robot_free = 0
    arm_first = names["joint"][ARM_JOINT_NAMES[0]]
    object_joint = world.joint_count - 1
    ee_shape = names["shape"][EE_SHAPE]
    ee_local_body = robot.shape_body[ee_shape]
    ee_offset = np.array(wp.transform_get_translation(robot.shape_transform[ee_shape]))
    object_first_shape = robot.shape_count
    legs = {}
    if legged:
        def coordinates(joints):
            return w_idx[:, None] * coords_per_world + np.array([joint_q_start[names["joint"][n]] for n in joints])

        def velocities(joints):
            return w_idx[:, None] * dofs_per_world + np.array([joint_qd_start[names["joint"][n]] for n in joints])

        legs = {"leg_q": coordinates(LEG_JOINT_NAMES), "leg_qd": velocities(LEG_JOINT_NAMES),
                "arm_q": coordinates(ARM_JOINT_NAMES), "arm_qd": velocities(ARM_JOINT_NAMES),
                "shank_body": w_idx[:, None] * bodies_per_world + np.array([names["body"][f"{leg}_SHANK"] for leg in LEGS])}

    return Scene(
        model=model,
        robot=description,
        ground_friction=float(builder.shape_material_mu[ground_shapes[0]]),
        num_worlds=num_worlds,
        bodies_per_world=bodies_per_world,
        base_body=w_idx * bodies_per_world + names["body"]["base"],
        object_body=w_idx * bodies_per_world + object_body,
        ee_body=w_idx * bodies_per_world + ee_local_body,
        ee_offset=ee_offset,
        object_shape=w_idx * shapes_per_world + object_first_shape,
        robot_q_start=w_idx * coords_per_world + joint_q_start[robot_free],
        robot_qd_start=w_idx * dofs_per_world + joint_qd_start[robot_free],
        robot_qd_count=int(robot.joint_dof_count),
        arm_q_start=w_idx * coords_per_world + joint_q_start[arm_first],
        arm_qd_start=w_idx * dofs_per_world + joint_qd_start[arm_first],
        object_q_start=w_idx * coords_per_world + joint_q_start[object_joint],
        object_qd_start=w_idx * dofs_per_world + joint_qd_start[object_joint],
        robot_body_start=w_idx * bodies_per_world,
        robot_body_count=robot_body_count,
        shape_role=shape_role,
        shape_self_column=shape_self_column,
        **legs,
    )
