"""USD assets of dynpush: the robot (tracked-base and legged variants), the two push objects and the ground.

The files are written by :mod:`dynpush.assets_usd.generate` (run
``python -m dynpush.assets_usd.generate``); see its module docstring for every number,
its source and the conventions.  Importing this package does not import ``pxr``.
"""

from __future__ import annotations

from pathlib import Path

_HERE = Path(__file__).resolve().parent

ROBOT_USD: Path = _HERE / "robot.usda"
ROBOT_LEGGED_USD: Path = _HERE / "robot_legged.usda"
CUBOID_USD: Path = _HERE / "object_cuboid.usda"
CYLINDER_USD: Path = _HERE / "object_cylinder.usda"
GROUND_USD: Path = _HERE / "ground.usda"

#: Revolute arm joints, base to tip (prim names under ``/Robot/joints``).
ARM_JOINT_NAMES: tuple[str, ...] = ("SH_ROT", "SH_FLE", "EL_FLE", "FA_ROT", "WRIST_1", "WRIST_2")
#: Arm rigid bodies, base to tip (prim names under ``/Robot``); link i is moved by joint i.
ARM_LINK_NAMES: tuple[str, ...] = ("shoulder", "upper_arm", "elbow", "forearm", "wrist_1", "wrist_2")
#: The end-effector's collision sphere on the last arm link; its centre is the end-effector point.
EE_SHAPE: str = "ee_collision"
#: The legs, in the order of every per-leg list: left front, right front, left hind, right hind.
LEG_NAMES: tuple[str, ...] = ("LF", "RF", "LH", "RH")
#: Leg collision shapes on the ``base`` body (prim names under ``/Robot/base``): LF_thigh, LF_shank, RF_thigh, ...
LEG_SHAPE_NAMES: tuple[str, ...] = tuple(f"{leg}_{part}" for leg in LEG_NAMES for part in ("thigh", "shank"))

#: Revolute leg joints of ``robot_legged.usda`` (prim names under ``/Robot/joints``): LF_HAA, LF_HFE, LF_KFE, ...
LEG_JOINT_NAMES: tuple[str, ...] = tuple(f"{leg}_{joint}" for leg in LEG_NAMES for joint in ("HAA", "HFE", "KFE"))

__all__ = [
    "ARM_JOINT_NAMES",
    "ARM_LINK_NAMES",
    "CUBOID_USD",
    "CYLINDER_USD",
    "EE_SHAPE",
    "GROUND_USD",
    "LEG_JOINT_NAMES",
    "LEG_NAMES",
    "LEG_SHAPE_NAMES",
    "ROBOT_LEGGED_USD",
    "ROBOT_USD",
]
