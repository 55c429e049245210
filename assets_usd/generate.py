"""Generator for the dynpush USD assets (robot, two push objects, ground).

Run ``python -m dynpush.assets_usd.generate`` to (re)write ``robot.usda``, ``robot_legged.usda``,
``object_cuboid.usda``, ``object_cylinder.usda`` and ``ground.usda`` beside this file
(``--out DIR`` writes elsewhere, ``--check`` also runs the USD validators).  The output is
deterministic: every computed number is rounded to 1e-9 before it is authored, and the
files are written from an anonymous layer, so no path or time stamp ends up in them.

Conventions: Z up, metres, kilograms, seconds.  Angles in USD are in degrees (UsdPhysics),
angles in the Python constants below and in the ``dynpush:*`` custom attributes are in
radians.  "Base frame" = frame of the ``base`` rigid body: origin at the centre of the
base box, x forward, y left, z up.

Robot (``robot.usda``, defaultPrim ``/Robot``, ``PhysicsArticulationRootAPI`` on ``/Robot``)
-------------------------------------------------------------------------------------------
A quadrupedal mobile manipulator in the spirit of Dadiotis et al., ICRA 2025 (ANYmal D with
a 6-DoF DynaArm).  It is *not* a model of the real robot; the numbers are the project's
simplified stand-ins:

* ``base`` (floating; Newton adds the free joint on import): box collider ``base_collision``
  0.60 x 0.30 x 0.20 m centred on the base frame, 50 kg.  Source for the mass: ANYbotics
  states ANYmal D weighs about 50 kg *including the legs*; here the whole 50 kg sits in
  the base body (legs have no joints and no separate mass).  The inertia is that of a
  solid 50 kg box of the collider size (approximation, ignores the legs' spread).  Box
  size, hip positions and leg lengths are approximations of ANYmal's trunk and legs, not
  data-sheet values.  The base frame stands at ``NOMINAL_BASE_HEIGHT`` = 0.50 m above the
  ground; ``robot.usda`` places it there.
* Legs: collision shapes only, on the ``base`` body.  Per leg a thigh capsule
  (``LF_thigh`` ...; length 0.30 m between cap centres, radius 0.06) and a shank capsule
  (``LF_shank`` ...; radius 0.04).  L/R = +y/-y, F/H = +x/-x.  Hips (HAA) at
  (+-0.30, +-0.10, 0); the thigh (HFE axis) starts 0.09 m further out, at y = +-0.19.
  The shank runs 0.33 m from the knee to the *foot centre*; the foot is modelled as a
  0.03 m sphere end, so the foot centre sits 0.03 m above the ground (z = -0.47 in the
  base frame).  A single capsule cannot have a 0.04 m body and a 0.03 m end, so the shank
  capsule (radius 0.04) is shortened along its axis until its lowest point is exactly
  z = -0.50 (ground contact at nominal height), i.e. by 0.01 / cos(shank pitch) = 12.9 mm
  (capsule segment 0.3171 m); the 0.03 m foot sphere would stick out of it by at most
  2.9 mm along the shank axis.
  Stance: ANYmal "X" configuration, knees pointing inward (front knees backward, hind knees
  forward), feet straight below the HFE axes.  Sign convention as ANYmal: HFE and KFE
  rotate about +y; positive HFE swings the thigh backward.  Exact values:
  |KFE| = acos(1/9) = 1.459455 rad (83.62 deg),
  |HFE| = acos(0.202/0.282) = 0.772294 rad (44.25 deg);
  LF/RF: HFE = +0.772294, KFE = -1.459455; LH/RH: HFE = -0.772294, KFE = +1.459455.
  Foot centres (base frame): LF (0.30, 0.19, -0.47), RF (0.30, -0.19, -0.47),
  LH (-0.30, 0.19, -0.47), RH (-0.30, -0.19, -0.47).  Knees at x = +-0.0907, z = -0.2149.
  These are authored on the ``base`` prim as custom attributes (leg order LF, RF, LH, RH):
  ``dynpush:legHipPositions`` (float3[], HAA points), ``dynpush:legThighStartPositions``
  (float3[], HFE points), ``dynpush:legNominalFootPositions`` (float3[], foot centres),
  ``dynpush:legNominalHFE`` / ``dynpush:legNominalKFE`` (float[], rad),
  ``dynpush:legThighLength`` (0.30), ``dynpush:legShankLength`` (0.33, knee to foot centre),
  ``dynpush:legFootRadius`` (0.03).
* Arm, DynaArm-like, mounted on the base top at (0.25, 0, 0.10) (base frame).  Bodies and
  the revolute joints that move them (axis given in the parent body's frame):

  ===========  ========  ==============================================  =====
  body         joint     joint position / axis                            mass
  ===========  ========  ==============================================  =====
  shoulder     SH_ROT    mount point, z of base                          1.5
  upper_arm    SH_FLE    0.10 above the mount, y                         2.0
  elbow        EL_FLE    0.40 along the upper arm, y                     1.2
  forearm      FA_ROT    0.10 along the arm past EL_FLE, x               1.0
  wrist_1      WRIST_1   0.40 past EL_FLE (0.30 past FA_ROT), y          0.6
  wrist_2      WRIST_2   0.10 past WRIST_1, x                            0.4
  ===========  ========  ==============================================  =====

  At q = 0 the arm points straight up (+z of the base; the paper puts shoulder-flexion
  zero on the base +z axis).  ``base``, ``shoulder`` and ``upper_arm`` frames are parallel
  to the base frame at q = 0; ``elbow``, ``forearm``, ``wrist_1`` and ``wrist_2`` frames
  are turned by -90 deg about y so that their local +x runs along the arm (distal), local
  y = base y and local z = base -x.  That makes FA_ROT and WRIST_2 rolls about the
  forearm / wrist axis while their axis is "x in the parent frame" as specified.
  Positive SH_FLE, EL_FLE and WRIST_1 all rotate about +y of the base (with SH_ROT =
  FA_ROT = 0) and so tip the distal links toward +x (forward).  The EL_FLE -> FA_ROT split
  (0.10 / 0.30) is an assumption; only EL_FLE -> WRIST_1 = 0.40 is specified.
  Arm mass 6.7 kg, robot total 56.7 kg.

  Each link has an explicit ``MassAPI`` (mass, centre of mass at the link's middle,
  diagonal inertia of a solid cylinder of the link's length and collider radius) **plus
  0.1 kg m^2 on every diagonal entry**: XPBD ignores joint armature, and without it the arm
  sagged (measured, docs/simulator.md); the extra inertia is the armature stand-in.

  Limits (deg): SH_ROT [-170, 170], SH_FLE [-95, 95], EL_FLE [-15, 165],
  FA_ROT [-170, 170], WRIST_1 [-115, 115], WRIST_2 [-170, 170].
  Drives: ``PhysicsDriveAPI:angular``, type force, target 0, maxForce (peak effort, N m)
  [90, 90, 90, 30, 30, 30], stiffness [200, 300, 200, 50, 50, 50] N m/rad and damping
  [10, 15, 10, 2, 2, 2] N m s/rad, authored per degree (value * pi / 180) as UsdPhysics
  requires.  Velocity limits [7.5, 7.5, 7.5, 10, 10, 10] rad/s are authored as
  ``newton:velocityLimit`` (NewtonJointAPI) in **degrees per second** (value * 180 / pi);
  Newton's default schema resolver reads that attribute and converts it to rad/s
  (``physxJoint:maxJointVelocity`` is only read when a PhysX resolver is passed).
  WRIST_2 is a normal revolute joint; the controller freezes it.

  Capsule colliders ``<link>_collision`` (radius / extent along the arm, measured from the
  link's own joint): shoulder 0.06 / [0.01, 0.15], upper_arm 0.05 / [0.05, 0.40],
  elbow 0.045 / [0, 0.10], forearm 0.04 / [0, 0.30], wrist_1 0.035 / [0, 0.10],
  wrist_2 0.03 / [0, 0.08].  Non-adjacent links and the base/legs are clear of each other
  at q = 0 and at the default pose (adjacent, jointed links are filtered anyway).
  End effector: sphere ``ee_collision`` radius 0.04 on ``wrist_2``, 0.08 m past the
  WRIST_2 axis along the arm, and an ``Xform`` ``ee_frame`` at its centre.

  Default pushing pose, custom attribute ``dynpush:defaultArmJointPositions`` (float[6], rad)
  on ``/Robot``: [SH_ROT, SH_FLE, EL_FLE, FA_ROT, WRIST_1, WRIST_2] =
  [0, 70, 115, 0, -65, 0] deg = [0, 1.2217305, 2.0071286, 0, -1.1344640, 0] rad: upper arm
  forward, forearm hanging almost vertical, wrist 30 deg below horizontal pointing forward.
  Resulting ``ee_frame`` position: (0.7469, 0.0, -0.1517) m in the base frame, i.e.
  (0.7469, 0.0, 0.3483) m in the world with the base at its nominal pose (0, 0, 0.50):
  0.447 m in front of the base front face (x = 0.30) and 0.348 m above the ground.

Legged robot (``robot_legged.usda``, for the legged mode and locomotion training)
-------------------------------------------------------------------------------
The same robot with articulated legs instead of leg colliders on the base: per leg three bodies
``<leg>_HIP`` (1.4 kg), ``<leg>_THIGH`` (1.6 kg), ``<leg>_SHANK`` (0.5 kg) and three revolute
joints ``<leg>_HAA`` (axis x, at the hip point), ``<leg>_HFE`` (axis y, at the thigh start) and
``<leg>_KFE`` (axis y, at the knee, 0.30 m below the HFE axis at q = 0); the base keeps 36 kg so the
robot still weighs 50 kg without the arm.  At q = 0 every leg body frame is parallel to the base
frame and the leg points straight down; the sign convention and the nominal stance are those of
the leg attributes above, so ``dynpush:defaultLegJointPositions`` on ``/Robot`` (float[12], rad,
order LF HAA, HFE, KFE, RF ..., LH ..., RH ...) = (0, +-0.772294, -+1.459455) puts the feet at
``dynpush:legNominalFootPositions``.  The bodies are authored in that stance; Newton does not
import joint positions, so a simulator sets them.  Colliders: ``<leg>_thigh`` capsule (radius 0.06,
0.30 m between cap centres) on the thigh; ``<leg>_shank`` capsule (radius 0.04, 0.27 m from the
knee) and the foot sphere ``<leg>_foot`` (radius 0.03, centre 0.33 m from the knee, the only part
meant to touch the ground) on the shank.  Limits HAA +-0.72, HFE +-1.6, KFE +-2.6 rad; drives
(ANYmal-like, legged_gym's PD gains): peak effort 80 N m, 7.5 rad/s, stiffness 80 N m/rad, damping
2 N m s/rad.  Leg links get 0.02 kg m^2 on every diagonal inertia entry (armature stand-in, as the
arm).  With these gains the robot sags under its weight unless the joint targets carry the static
torques (``tests/test_legged_asset.py`` stands it at 0.50 m with targets offset by ``tau / k_p``
from ``dynpush.sim.leg_statics``).

Objects (``object_cuboid.usda``, ``object_cylinder.usda``, defaultPrim ``/Object``)
--------------------------------------------------------------------------------
Exactly one rigid body ``/Object/object`` (at the origin; place it at z = 0.35 to rest on
the ground) with one collider ``/Object/object/collision`` centred on the body origin:
a 0.5 x 0.5 x 0.7 m box, resp. a z-axis cylinder of radius 0.25 and height 0.7.  5 kg with
the uniform-solid inertia, physics material friction 0.8 (static and dynamic), restitution 0.
No ground, no joints, no scene.

Ground (``ground.usda``, defaultPrim ``/Ground``)
-------------------------------------------------
A static z-up ``Plane`` collider ``/Ground/plane`` at z = 0 with a physics material of
friction 0.4 (static and dynamic), restitution 0. Newton combines the coefficients of a contact
by their mean, so the simulator gives each object ``2 * combined - 0.4``: the floor's 0.4 lets the
combined object-floor coefficient span the paper's randomisation range [0.4, 1.25] (III-E).

None of the files holds a ``PhysicsScene``: the simulator owns gravity and solver settings.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path

from dynpush.assets_usd import ARM_JOINT_NAMES, ARM_LINK_NAMES, LEG_JOINT_NAMES, LEG_NAMES

# ---------------------------------------------------------------------------------------
# Numbers (SI units; angles in radians unless the name says DEG)
# ---------------------------------------------------------------------------------------

ROUND_DIGITS = 9


def _r(x: float) -> float:
    """Round for deterministic authoring (and turn -0.0 into 0.0)."""
    return round(float(x), ROUND_DIGITS) + 0.0


NOMINAL_BASE_HEIGHT = 0.50
BASE_SIZE = (0.60, 0.30, 0.20)
BASE_MASS = 50.0

# --- legs (order LEG_NAMES: LF, RF, LH, RH) ---
HIP_X = 0.30
HIP_Y = 0.10
THIGH_LATERAL_OFFSET = 0.09
THIGH_LENGTH = 0.30
THIGH_RADIUS = 0.06
SHANK_LENGTH = 0.33  # knee to foot centre
SHANK_RADIUS = 0.04
FOOT_RADIUS = 0.03
LEG_GROUND_Z = -NOMINAL_BASE_HEIGHT  # ground in the base frame at nominal height
FOOT_CENTRE_Z = LEG_GROUND_Z + FOOT_RADIUS  # -0.47

_LEG_SIGNS = {"LF": (1.0, 1.0), "RF": (1.0, -1.0), "LH": (-1.0, 1.0), "RH": (-1.0, -1.0)}

LEG_HIP_POSITIONS = tuple((sx * HIP_X, sy * HIP_Y, 0.0) for sx, sy in (_LEG_SIGNS[n] for n in LEG_NAMES))
LEG_THIGH_START_POSITIONS = tuple(
    (sx * HIP_X, sy * (HIP_Y + THIGH_LATERAL_OFFSET), 0.0) for sx, sy in (_LEG_SIGNS[n] for n in LEG_NAMES)
)

# Feet straight below the HFE axes: the hip-foot distance is the vertical drop D.
_D = -FOOT_CENTRE_Z
_KFE_MAG = math.acos((_D**2 - THIGH_LENGTH**2 - SHANK_LENGTH**2) / (2.0 * THIGH_LENGTH * SHANK_LENGTH))
_HFE_MAG = math.acos((THIGH_LENGTH**2 + _D**2 - SHANK_LENGTH**2) / (2.0 * THIGH_LENGTH * _D))
# ANYmal "X" stance: front HFE > 0 / KFE < 0 (knee backward), hind mirrored (knee forward).
LEG_NOMINAL_HFE = tuple(_r(_HFE_MAG if sx > 0 else -_HFE_MAG) for sx, _ in (_LEG_SIGNS[n] for n in LEG_NAMES))
LEG_NOMINAL_KFE = tuple(_r(-_KFE_MAG if sx > 0 else _KFE_MAG) for sx, _ in (_LEG_SIGNS[n] for n in LEG_NAMES))


def leg_forward_kinematics(thigh_start: Sequence[float], hfe: float, kfe: float):
    """Knee and foot-centre positions (base frame) of a sagittal leg (rotations about +y)."""
    tx, ty, tz = thigh_start
    knee = (tx - THIGH_LENGTH * math.sin(hfe), ty, tz - THIGH_LENGTH * math.cos(hfe))
    foot = (
        knee[0] - SHANK_LENGTH * math.sin(hfe + kfe),
        ty,
        knee[2] - SHANK_LENGTH * math.cos(hfe + kfe),
    )
    return knee, foot


LEG_NOMINAL_KNEE_POSITIONS = tuple(
    tuple(_r(v) for v in leg_forward_kinematics(t, h, k)[0])
    for t, h, k in zip(LEG_THIGH_START_POSITIONS, LEG_NOMINAL_HFE, LEG_NOMINAL_KFE, strict=True)
)
LEG_NOMINAL_FOOT_POSITIONS = tuple(
    tuple(_r(v) for v in leg_forward_kinematics(t, h, k)[1])
    for t, h, k in zip(LEG_THIGH_START_POSITIONS, LEG_NOMINAL_HFE, LEG_NOMINAL_KFE, strict=True)
)

# --- articulated legs (robot_legged.usda only; ANYmal-like stand-ins, see the module docstring) ---
LEG_LINK_MASSES = (1.4, 1.6, 0.5)  # hip, thigh, shank [kg]; 3.5 kg per leg
LEG_LIMITS = ((-0.72, 0.72), (-1.6, 1.6), (-2.6, 2.6))  # HAA, HFE, KFE [rad]
LEG_EFFORT_LIMIT = 80.0  # N m, peak (ANYmal C/D drives)
LEG_VELOCITY_LIMIT = 7.5  # rad/s
LEG_STIFFNESS = 80.0  # N m / rad (legged_gym's ANYmal PD gains)
LEG_DAMPING = 2.0  # N m s / rad
LEG_ARMATURE_INERTIA = 0.02  # kg m^2 on every diagonal entry of every leg link (XPBD ignores armature)
SHANK_COLLIDER_LENGTH = SHANK_LENGTH - 0.06  # knee to the capsule's end centre: the foot sphere reaches lower
LEGGED_BASE_MASS = BASE_MASS - 4.0 * sum(LEG_LINK_MASSES)  # the robot still weighs 50 kg without the arm
DEFAULT_LEG_JOINT_POSITIONS = tuple(
    v for hfe, kfe in zip(LEG_NOMINAL_HFE, LEG_NOMINAL_KFE, strict=True) for v in (0.0, hfe, kfe)
)

# --- arm ---
ARM_MOUNT = (0.25, 0.0, 0.10)
ARM_JOINT_AXES = ("Z", "Y", "Y", "X", "Y", "X")  # in the parent body frame
# distance from a link's own joint to the next joint, along the arm
ARM_LINK_LENGTHS = (0.10, 0.40, 0.10, 0.30, 0.10, 0.08)  # wrist_2: to the EE centre
ARM_LINK_MASSES = (1.5, 2.0, 1.2, 1.0, 0.6, 0.4)
ARM_LINK_RADII = (0.06, 0.05, 0.045, 0.04, 0.035, 0.03)
# collider extent along the arm [start, end] measured from the link's own joint
ARM_COLLIDER_SPANS = ((0.01, 0.15), (0.05, 0.40), (0.0, 0.10), (0.0, 0.30), (0.0, 0.10), (0.0, 0.08))
ARMATURE_INERTIA = 0.1  # kg m^2 added to every diagonal inertia entry of every arm link
# body frames: "z" = parallel to the base frame (arm along +z), "x" = turned -90 deg about y
ARM_LINK_FRAME = ("z", "z", "x", "x", "x", "x")
EE_OFFSET = 0.08
EE_RADIUS = 0.04

ARM_LIMITS_DEG = ((-170.0, 170.0), (-95.0, 95.0), (-15.0, 165.0), (-170.0, 170.0), (-115.0, 115.0), (-170.0, 170.0))
ARM_EFFORT_LIMITS = (90.0, 90.0, 90.0, 30.0, 30.0, 30.0)  # N m
ARM_VELOCITY_LIMITS = (7.5, 7.5, 7.5, 10.0, 10.0, 10.0)  # rad/s
ARM_STIFFNESS = (200.0, 300.0, 200.0, 50.0, 50.0, 50.0)  # N m / rad
ARM_DAMPING = (10.0, 15.0, 10.0, 2.0, 2.0, 2.0)  # N m s / rad

DEFAULT_ARM_JOINT_POSITIONS_DEG = (0.0, 70.0, 115.0, 0.0, -65.0, 0.0)
DEFAULT_ARM_JOINT_POSITIONS = tuple(_r(math.radians(a)) for a in DEFAULT_ARM_JOINT_POSITIONS_DEG)


def arm_ee_position_base(q: Sequence[float]) -> tuple[float, float, float]:
    """EE centre in the base frame for joint positions ``q`` (only valid for SH_ROT and FA_ROT = 0)."""
    if abs(q[0]) > 1e-12 or abs(q[3]) > 1e-12:
        raise ValueError("planar helper: SH_ROT and FA_ROT must be 0")
    x, z = ARM_MOUNT[0], ARM_MOUNT[2] + ARM_LINK_LENGTHS[0]
    pitch = 0.0
    for angle, length in ((q[1], 0.40), (q[2], 0.40), (q[4], 0.10 + EE_OFFSET)):
        pitch += angle
        x += length * math.sin(pitch)
        z += length * math.cos(pitch)
    return (_r(x), 0.0, _r(z))


DEFAULT_EE_POSITION_BASE = arm_ee_position_base(DEFAULT_ARM_JOINT_POSITIONS)

# --- objects / ground ---
CUBOID_SIZE = (0.5, 0.5, 0.7)
CYLINDER_RADIUS = 0.25
CYLINDER_HEIGHT = 0.7
OBJECT_MASS = 5.0
OBJECT_FRICTION = 0.8
GROUND_FRICTION = 0.4

FILE_NAMES = {
    "robot": "robot.usda",
    "robot_legged": "robot_legged.usda",
    "cuboid": "object_cuboid.usda",
    "cylinder": "object_cylinder.usda",
    "ground": "ground.usda",
}
_LAYER_DOC = "Generated by `python -m dynpush.assets_usd.generate`; do not edit by hand."

# ---------------------------------------------------------------------------------------
# USD authoring helpers (pxr is imported lazily)
# ---------------------------------------------------------------------------------------


def _pxr():
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt

    try:  # registers NewtonJointAPI etc.; the authored text does not depend on it
        import newton_usd_schemas  # noqa: F401
    except ImportError:  # pragma: no cover
        pass
    return Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt


def _quat_y(angle: float):
    """(w, x, y, z) of a rotation by ``angle`` rad about +y."""
    return (_r(math.cos(angle / 2.0)), 0.0, _r(math.sin(angle / 2.0)), 0.0)


_Q_IDENTITY = (1.0, 0.0, 0.0, 0.0)
_Q_ARM_X = _quat_y(-math.pi / 2.0)  # local +x = base +z


def _new_stage(default_prim: str):
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.documentation = _LAYER_DOC
    stage = Usd.Stage.Open(layer)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, default_prim)
    stage.SetDefaultPrim(root.GetPrim())
    return stage, root


def _set_pose(xformable, translate=None, orient=None, scale=None):
    Gf = _pxr()[0]
    if translate is not None:
        xformable.AddTranslateOp().Set(Gf.Vec3d(*(_r(v) for v in translate)))
    if orient is not None and tuple(orient) != _Q_IDENTITY:
        w, x, y, z = orient
        xformable.AddOrientOp().Set(Gf.Quatf(w, Gf.Vec3f(x, y, z)))
    if scale is not None:
        xformable.AddScaleOp().Set(Gf.Vec3f(*(_r(v) for v in scale)))


def _capsule(stage, path, radius, height, axis, translate, orient=_Q_IDENTITY):
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    cap = UsdGeom.Capsule.Define(stage, path)
    cap.CreateRadiusAttr(_r(radius))
    cap.CreateHeightAttr(_r(height))
    cap.CreateAxisAttr(axis)
    half = {"X": (height / 2 + radius, radius, radius), "Y": (radius, height / 2 + radius, radius)}.get(
        axis, (radius, radius, height / 2 + radius)
    )
    cap.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*(-_r(h) for h in half)), Gf.Vec3f(*(_r(h) for h in half))]))
    _set_pose(cap, translate=translate, orient=orient)
    UsdPhysics.CollisionAPI.Apply(cap.GetPrim())
    return cap


def _sphere(stage, path, radius, translate):
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    sph = UsdGeom.Sphere.Define(stage, path)
    sph.CreateRadiusAttr(_r(radius))
    sph.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-_r(radius)), Gf.Vec3f(_r(radius))]))
    _set_pose(sph, translate=translate)
    UsdPhysics.CollisionAPI.Apply(sph.GetPrim())
    return sph


def _mass(prim, mass, com, diag_inertia):
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    api = UsdPhysics.MassAPI.Apply(prim)
    api.CreateMassAttr(_r(mass))
    api.CreateCenterOfMassAttr(Gf.Vec3f(*(_r(v) for v in com)))
    api.CreateDiagonalInertiaAttr(Gf.Vec3f(*(_r(v) for v in diag_inertia)))
    api.CreatePrincipalAxesAttr(Gf.Quatf(1.0, Gf.Vec3f(0.0, 0.0, 0.0)))


def _physics_material(stage, path, friction):
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    mat = UsdShade.Material.Define(stage, path)
    api = UsdPhysics.MaterialAPI.Apply(mat.GetPrim())
    api.CreateStaticFrictionAttr(_r(friction))
    api.CreateDynamicFrictionAttr(_r(friction))
    api.CreateRestitutionAttr(0.0)
    return mat


def _bind_physics_material(prim, mat):
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    binding = UsdShade.MaterialBindingAPI.Apply(prim)
    binding.Bind(mat, UsdShade.Tokens.weakerThanDescendants, "physics")


def _custom(prim, name, type_name, value, doc):
    attr = prim.CreateAttribute(name, type_name, custom=True)
    attr.Set(value)
    attr.SetDocumentation(doc)
    return attr


def _cylinder_inertia(mass, length, radius, long_axis):
    """Solid-cylinder diagonal inertia about the centre, long axis 'x' or 'z'."""
    i_long = 0.5 * mass * radius**2
    i_trans = mass * (3.0 * radius**2 + length**2) / 12.0
    return (i_long, i_trans, i_trans) if long_axis == "x" else (i_trans, i_trans, i_long)


def _revolute_joint(stage, name, parent_path, child_path, pos0, rot0, axis, limits_deg, effort, stiffness, damping,
                    velocity_limit):
    """A revolute joint ``/Robot/joints/<name>`` with a PD position drive (target 0).

    Joint frame = child body frame (localPos1 = 0, localRot1 = identity); ``pos0``/``rot0`` place it in
    the parent body. Gains are given per radian and authored per degree (UsdPhysics); the velocity
    limit is given in rad/s and authored as ``newton:velocityLimit`` in deg/s.
    """
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    joint = UsdPhysics.RevoluteJoint.Define(stage, f"/Robot/joints/{name}")
    joint.CreateBody0Rel().SetTargets([Sdf.Path(parent_path)])
    joint.CreateBody1Rel().SetTargets([Sdf.Path(child_path)])
    joint.CreateLocalPos0Attr(Gf.Vec3f(*(_r(v) for v in pos0)))
    joint.CreateLocalRot0Attr(Gf.Quatf(rot0[0], Gf.Vec3f(*rot0[1:])))
    joint.CreateLocalPos1Attr(Gf.Vec3f(0.0, 0.0, 0.0))
    joint.CreateLocalRot1Attr(Gf.Quatf(1.0, Gf.Vec3f(0.0, 0.0, 0.0)))
    joint.CreateAxisAttr(axis)
    joint.CreateLowerLimitAttr(_r(limits_deg[0]))
    joint.CreateUpperLimitAttr(_r(limits_deg[1]))
    jprim = joint.GetPrim()
    drive = UsdPhysics.DriveAPI.Apply(jprim, "angular")
    drive.CreateTypeAttr("force")
    drive.CreateMaxForceAttr(effort)
    drive.CreateTargetPositionAttr(0.0)
    drive.CreateTargetVelocityAttr(0.0)
    drive.CreateStiffnessAttr(_r(stiffness * math.pi / 180.0))
    drive.CreateDampingAttr(_r(damping * math.pi / 180.0))
    jprim.AddAppliedSchema("NewtonJointAPI")
    vel = jprim.CreateAttribute("newton:velocityLimit", Sdf.ValueTypeNames.Float, custom=False)
    vel.Set(_r(math.degrees(velocity_limit)))
    return joint


# ---------------------------------------------------------------------------------------
# Builders
# ---------------------------------------------------------------------------------------


def _collider_legs(stage):
    """Thigh and shank capsules of the four legs in the nominal stance, on the ``base`` body (robot.usda)."""
    for leg, thigh_start, knee, foot, hfe, kfe in zip(
        LEG_NAMES,
        LEG_THIGH_START_POSITIONS,
        LEG_NOMINAL_KNEE_POSITIONS,
        LEG_NOMINAL_FOOT_POSITIONS,
        LEG_NOMINAL_HFE,
        LEG_NOMINAL_KFE,
        strict=True,
    ):
        # thigh: cap centres at the thigh start and at the knee; the capsule axis (z) is
        # tilted by the HFE angle (a rotation about y keeps z's sense when |angle| < 90 deg)
        mid = tuple(0.5 * (a + b) for a, b in zip(thigh_start, knee, strict=True))
        _capsule(stage, f"/Robot/base/{leg}_thigh", THIGH_RADIUS, THIGH_LENGTH, "Z", mid, _quat_y(hfe))
        # shank: from the knee toward the foot centre, shortened by t so that the lowest
        # point of the capsule (end centre z - radius) is exactly on the ground
        shank_pitch = hfe + kfe
        cos_p = math.cos(shank_pitch)
        t = (LEG_GROUND_Z + SHANK_RADIUS - foot[2]) / cos_p
        end = (foot[0] + t * math.sin(shank_pitch), foot[1], foot[2] + t * cos_p)
        shank_len = SHANK_LENGTH - t
        mid = tuple(0.5 * (a + b) for a, b in zip(knee, end, strict=True))
        _capsule(stage, f"/Robot/base/{leg}_shank", SHANK_RADIUS, shank_len, "Z", mid, _quat_y(shank_pitch))


def _articulated_leg(stage, leg, hip, thigh_start, knee, hfe, kfe):
    """Bodies ``<leg>_HIP``/``_THIGH``/``_SHANK`` (world pose = nominal stance with the base at its
    nominal height) and joints ``<leg>_HAA`` (x), ``_HFE`` (y), ``_KFE`` (y). At q = 0 every leg body
    frame is parallel to the base frame and the leg points straight down (-z); the thigh and shank
    run along their body's -z axis from the joint."""
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    lift = (0.0, 0.0, NOMINAL_BASE_HEIGHT)
    hip_mass, thigh_mass, shank_mass = LEG_LINK_MASSES
    hfe_offset = tuple(t - h for t, h in zip(thigh_start, hip, strict=True))  # HAA -> HFE, hip frame
    links = (  # name, origin (base frame), pitch, mass, com, length, radius
        ("HIP", hip, 0.0, hip_mass, tuple(0.5 * v for v in hfe_offset), abs(hfe_offset[1]), THIGH_RADIUS),
        ("THIGH", thigh_start, hfe, thigh_mass, (0.0, 0.0, -0.5 * THIGH_LENGTH), THIGH_LENGTH, THIGH_RADIUS),
        ("SHANK", knee, hfe + kfe, shank_mass, (0.0, 0.0, -0.5 * SHANK_LENGTH), SHANK_LENGTH, SHANK_RADIUS),
    )
    for name, origin, pitch, mass, com, length, radius in links:
        body = UsdGeom.Xform.Define(stage, f"/Robot/{leg}_{name}")
        _set_pose(body, translate=tuple(o + d for o, d in zip(origin, lift, strict=True)), orient=_quat_y(pitch))
        UsdPhysics.RigidBodyAPI.Apply(body.GetPrim())
        inertia = tuple(v + LEG_ARMATURE_INERTIA for v in _cylinder_inertia(mass, length, radius, "z"))
        _mass(body.GetPrim(), mass, com, inertia)
    _capsule(stage, f"/Robot/{leg}_THIGH/{leg}_thigh", THIGH_RADIUS, THIGH_LENGTH, "Z", (0.0, 0.0, -0.5 * THIGH_LENGTH))
    _capsule(stage, f"/Robot/{leg}_SHANK/{leg}_shank", SHANK_RADIUS, SHANK_COLLIDER_LENGTH, "Z",
             (0.0, 0.0, -0.5 * SHANK_COLLIDER_LENGTH))
    _sphere(stage, f"/Robot/{leg}_SHANK/{leg}_foot", FOOT_RADIUS, (0.0, 0.0, -SHANK_LENGTH))
    limits = [tuple(math.degrees(v) for v in pair) for pair in LEG_LIMITS]
    joints = (("HAA", "/Robot/base", "HIP", hip, "X"), ("HFE", f"/Robot/{leg}_HIP", "THIGH", hfe_offset, "Y"),
              ("KFE", f"/Robot/{leg}_THIGH", "SHANK", (0.0, 0.0, -THIGH_LENGTH), "Y"))
    for (joint, parent, child, pos0, axis), limit in zip(joints, limits, strict=True):
        _revolute_joint(stage, f"{leg}_{joint}", parent, f"/Robot/{leg}_{child}", pos0, _Q_IDENTITY, axis, limit,
                        LEG_EFFORT_LIMIT, LEG_STIFFNESS, LEG_DAMPING, LEG_VELOCITY_LIMIT)


def build_robot(legged: bool = False):
    """``robot.usda`` (legs as colliders on the base), or with ``legged`` ``robot_legged.usda``
    (12 revolute leg joints, authored in the nominal stance)."""
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    stage, root = _new_stage("/Robot")
    root_prim = root.GetPrim()
    UsdPhysics.ArticulationRootAPI.Apply(root_prim)
    _custom(
        root_prim,
        "dynpush:defaultArmJointPositions",
        Sdf.ValueTypeNames.FloatArray,
        Vt.FloatArray(list(DEFAULT_ARM_JOINT_POSITIONS)),
        "Default pushing pose [rad], order " + ", ".join(ARM_JOINT_NAMES) + f"; EE centre at "
        f"{DEFAULT_EE_POSITION_BASE} m in the base frame.",
    )

    # ---- base ----
    base = UsdGeom.Xform.Define(stage, "/Robot/base")
    _set_pose(base, translate=(0.0, 0.0, NOMINAL_BASE_HEIGHT))
    base_prim = base.GetPrim()
    UsdPhysics.RigidBodyAPI.Apply(base_prim)
    sx, sy, sz = BASE_SIZE
    m = LEGGED_BASE_MASS if legged else BASE_MASS
    _mass(base_prim, m, (0.0, 0.0, 0.0), (m * (sy**2 + sz**2) / 12.0, m * (sx**2 + sz**2) / 12.0, m * (sx**2 + sy**2) / 12.0))
    box = UsdGeom.Cube.Define(stage, "/Robot/base/base_collision")
    box.CreateSizeAttr(1.0)
    box.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-0.5), Gf.Vec3f(0.5)]))
    _set_pose(box, scale=BASE_SIZE)
    UsdPhysics.CollisionAPI.Apply(box.GetPrim())

    UsdGeom.Scope.Define(stage, "/Robot/joints")
    if legged:
        _custom(
            root_prim,
            "dynpush:defaultLegJointPositions",
            Sdf.ValueTypeNames.FloatArray,
            Vt.FloatArray(list(DEFAULT_LEG_JOINT_POSITIONS)),
            "Nominal stance [rad], order " + ", ".join(LEG_JOINT_NAMES) + "; joint positions are not imported: set them.",
        )
        for leg, hip, thigh_start, knee, hfe, kfe in zip(
            LEG_NAMES, LEG_HIP_POSITIONS, LEG_THIGH_START_POSITIONS, LEG_NOMINAL_KNEE_POSITIONS, LEG_NOMINAL_HFE,
            LEG_NOMINAL_KFE, strict=True,
        ):
            _articulated_leg(stage, leg, hip, thigh_start, knee, hfe, kfe)
    else:
        _collider_legs(stage)
    _custom(
        base_prim,
        "dynpush:legHipPositions",
        Sdf.ValueTypeNames.Float3Array,
        Vt.Vec3fArray([Gf.Vec3f(*p) for p in LEG_HIP_POSITIONS]),
        "Hip (HAA) points, base frame [m], legs LF, RF, LH, RH.",
    )
    _custom(
        base_prim,
        "dynpush:legThighStartPositions",
        Sdf.ValueTypeNames.Float3Array,
        Vt.Vec3fArray([Gf.Vec3f(*p) for p in LEG_THIGH_START_POSITIONS]),
        "Thigh start (HFE axis) points, base frame [m], legs LF, RF, LH, RH.",
    )
    _custom(
        base_prim,
        "dynpush:legNominalFootPositions",
        Sdf.ValueTypeNames.Float3Array,
        Vt.Vec3fArray([Gf.Vec3f(*p) for p in LEG_NOMINAL_FOOT_POSITIONS]),
        "Nominal foot centres, base frame [m], legs LF, RF, LH, RH; the ground contact is "
        "legFootRadius below.",
    )
    _custom(
        base_prim,
        "dynpush:legNominalHFE",
        Sdf.ValueTypeNames.FloatArray,
        Vt.FloatArray(list(LEG_NOMINAL_HFE)),
        "Nominal hip flexion [rad] about +y, legs LF, RF, LH, RH.",
    )
    _custom(
        base_prim,
        "dynpush:legNominalKFE",
        Sdf.ValueTypeNames.FloatArray,
        Vt.FloatArray(list(LEG_NOMINAL_KFE)),
        "Nominal knee flexion [rad] about +y, legs LF, RF, LH, RH.",
    )
    _custom(base_prim, "dynpush:legThighLength", Sdf.ValueTypeNames.Float, THIGH_LENGTH, "Thigh length [m].")
    _custom(
        base_prim, "dynpush:legShankLength", Sdf.ValueTypeNames.Float, SHANK_LENGTH, "Knee to foot centre [m]."
    )
    _custom(base_prim, "dynpush:legFootRadius", Sdf.ValueTypeNames.Float, FOOT_RADIUS, "Foot radius [m].")

    # ---- arm ----
    # joint position along the arm (distance from the mount, arm straight up at q = 0)
    s_joint = [0.0]
    for length in ARM_LINK_LENGTHS[:-1]:
        s_joint.append(s_joint[-1] + length)
    mount_world = (ARM_MOUNT[0], ARM_MOUNT[1], ARM_MOUNT[2] + NOMINAL_BASE_HEIGHT)
    parent_path = "/Robot/base"
    parent_frame = "base"
    for i, link in enumerate(ARM_LINK_NAMES):
        frame = ARM_LINK_FRAME[i]
        orient = _Q_ARM_X if frame == "x" else _Q_IDENTITY
        body = UsdGeom.Xform.Define(stage, f"/Robot/{link}")
        _set_pose(body, translate=(mount_world[0], 0.0, mount_world[2] + s_joint[i]), orient=orient)
        prim = body.GetPrim()
        UsdPhysics.RigidBodyAPI.Apply(prim)
        length, radius, mass = ARM_LINK_LENGTHS[i], ARM_LINK_RADII[i], ARM_LINK_MASSES[i]
        along = (lambda d, f=frame: (d, 0.0, 0.0) if f == "x" else (0.0, 0.0, d))
        inertia = tuple(v + ARMATURE_INERTIA for v in _cylinder_inertia(mass, length, radius, frame))
        _mass(prim, mass, along(0.5 * length), inertia)
        s0, s1 = ARM_COLLIDER_SPANS[i]
        _capsule(
            stage,
            f"/Robot/{link}/{link}_collision",
            radius,
            (s1 - s0) - 2.0 * radius,
            frame.upper(),
            along(0.5 * (s0 + s1)),
        )
        if link == "wrist_2":
            _sphere(stage, "/Robot/wrist_2/ee_collision", EE_RADIUS, along(EE_OFFSET))
            ee = UsdGeom.Xform.Define(stage, "/Robot/wrist_2/ee_frame")
            _set_pose(ee, translate=along(EE_OFFSET))

        if i == 0:
            pos0 = ARM_MOUNT
        else:
            d = ARM_LINK_LENGTHS[i - 1]
            pos0 = (d, 0.0, 0.0) if parent_frame == "x" else (0.0, 0.0, d)
        rot0 = _Q_ARM_X if (frame == "x" and parent_frame != "x") else _Q_IDENTITY
        _revolute_joint(stage, ARM_JOINT_NAMES[i], parent_path, f"/Robot/{link}", pos0, rot0, ARM_JOINT_AXES[i],
                        ARM_LIMITS_DEG[i], ARM_EFFORT_LIMITS[i], ARM_STIFFNESS[i], ARM_DAMPING[i], ARM_VELOCITY_LIMITS[i])
        parent_path = f"/Robot/{link}"
        parent_frame = frame
    return stage


def _build_object(shape: str):
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    stage, root = _new_stage("/Object")
    mat = _physics_material(stage, "/Object/PhysicsMaterial", OBJECT_FRICTION)
    body = UsdGeom.Xform.Define(stage, "/Object/object")
    UsdPhysics.RigidBodyAPI.Apply(body.GetPrim())
    if shape == "cuboid":
        a, b, c = CUBOID_SIZE
        inertia = (OBJECT_MASS * (b**2 + c**2) / 12.0, OBJECT_MASS * (a**2 + c**2) / 12.0, OBJECT_MASS * (a**2 + b**2) / 12.0)
        geom = UsdGeom.Cube.Define(stage, "/Object/object/collision")
        geom.CreateSizeAttr(1.0)
        geom.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-0.5), Gf.Vec3f(0.5)]))
        _set_pose(geom, scale=CUBOID_SIZE)
    else:
        r, h = CYLINDER_RADIUS, CYLINDER_HEIGHT
        inertia = (OBJECT_MASS * (3 * r**2 + h**2) / 12.0,) * 2 + (0.5 * OBJECT_MASS * r**2,)
        geom = UsdGeom.Cylinder.Define(stage, "/Object/object/collision")
        geom.CreateRadiusAttr(r)
        geom.CreateHeightAttr(h)
        geom.CreateAxisAttr("Z")
        geom.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r, -r, -h / 2), Gf.Vec3f(r, r, h / 2)]))
    _mass(body.GetPrim(), OBJECT_MASS, (0.0, 0.0, 0.0), inertia)
    UsdPhysics.CollisionAPI.Apply(geom.GetPrim())
    _bind_physics_material(geom.GetPrim(), mat)
    return stage


def build_cuboid():
    return _build_object("cuboid")


def build_cylinder():
    return _build_object("cylinder")


def build_ground():
    Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt = _pxr()
    stage, root = _new_stage("/Ground")
    mat = _physics_material(stage, "/Ground/PhysicsMaterial", GROUND_FRICTION)
    plane = UsdGeom.Plane.Define(stage, "/Ground/plane")
    plane.CreateAxisAttr("Z")
    plane.CreateWidthAttr(100.0)
    plane.CreateLengthAttr(100.0)
    plane.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-50.0, -50.0, 0.0), Gf.Vec3f(50.0, 50.0, 0.0)]))
    UsdPhysics.CollisionAPI.Apply(plane.GetPrim())
    _bind_physics_material(plane.GetPrim(), mat)
    return stage


BUILDERS = {"robot": build_robot, "robot_legged": lambda: build_robot(legged=True), "cuboid": build_cuboid, "cylinder": build_cylinder, "ground": build_ground}


def usda_text(stage) -> str:
    text = stage.GetRootLayer().ExportToString()
    return text if text.endswith("\n") else text + "\n"


def generate(out_dir: str | Path | None = None) -> dict[str, Path]:
    """Write all asset files into ``out_dir`` (default: beside this module)."""
    out = Path(out_dir) if out_dir is not None else Path(__file__).resolve().parent
    out.mkdir(parents=True, exist_ok=True)
    written = {}
    for key, builder in BUILDERS.items():
        path = out / FILE_NAMES[key]
        path.write_text(usda_text(builder()), encoding="utf-8", newline="\n")
        written[key] = path
    return written


# ---------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------


def check_compliance(path: str | Path) -> list[str]:
    """Problems found in ``path`` by USD's checkers; empty when it passes.

    usd-core >= 25.x removed ``UsdUtils.ComplianceChecker`` (usdchecker moved to the
    UsdValidation framework).  This runs every registered UsdValidation validator
    (core, UsdGeom, UsdShade, UsdPhysics, UsdSkel, ...) and, where the installed USD
    still has it, the legacy ``UsdUtils.ComplianceChecker`` as well.
    """
    _pxr()
    from pxr import Usd, UsdUtils, UsdValidation

    problems: list[str] = []
    stage = Usd.Stage.Open(str(path))
    if not stage:
        return [f"cannot open {path}"]
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    for err in context.Validate(stage):
        if not err.HasNoError():
            problems.append(f"{err.GetName()}: {err.GetMessage()}")
    legacy = getattr(UsdUtils, "ComplianceChecker", None)
    if legacy is not None:  # pragma: no cover - depends on the USD version
        checker = legacy()
        checker.CheckCompliance(str(path))
        problems += list(checker.GetErrors()) + list(checker.GetFailedChecks())
    return problems


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="output folder (default: beside this module)")
    parser.add_argument("--check", action="store_true", help="run the USD validators on the written files")
    args = parser.parse_args(argv)
    written = generate(args.out)
    status = 0
    for path in written.values():
        print(path)
        if args.check:
            for problem in check_compliance(path):
                print(f"  {problem}")
                status = 1
    return status


if __name__ == "__main__":
    raise SystemExit(main())
