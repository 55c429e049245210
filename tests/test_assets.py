"""Tests of the generated USD assets (dynpush.assets_usd).

The expected numbers below are typed in from the asset specification (or derived here
from it), not read back from the generator's constants, so a wrong constant fails.
CPU only; Newton imports, one finalize and a few eval_fk calls.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynpush.assets_usd import (
    ARM_JOINT_NAMES,
    ARM_LINK_NAMES,
    CUBOID_USD,
    CYLINDER_USD,
    GROUND_USD,
    LEG_SHAPE_NAMES,
    ROBOT_LEGGED_USD,
    ROBOT_USD,
)

ALL_FILES = (ROBOT_USD, ROBOT_LEGGED_USD, CUBOID_USD, CYLINDER_USD, GROUND_USD)
DEG = math.pi / 180.0

# --- the specification, typed in ---
SPEC_ARM_JOINTS = ["SH_ROT", "SH_FLE", "EL_FLE", "FA_ROT", "WRIST_1", "WRIST_2"]
SPEC_ARM_LINKS = ["shoulder", "upper_arm", "elbow", "forearm", "wrist_1", "wrist_2"]
SPEC_LEG_SHAPES = ["LF_thigh", "LF_shank", "RF_thigh", "RF_shank", "LH_thigh", "LH_shank", "RH_thigh", "RH_shank"]
SPEC_LIMITS_DEG = [(-170, 170), (-95, 95), (-15, 165), (-170, 170), (-115, 115), (-170, 170)]
SPEC_EFFORT = [90, 90, 90, 30, 30, 30]
SPEC_VEL = [7.5, 7.5, 7.5, 10, 10, 10]
SPEC_KE = [200, 300, 200, 50, 50, 50]
SPEC_KD = [10, 15, 10, 2, 2, 2]
SPEC_LINK_MASS = [1.5, 2.0, 1.2, 1.0, 0.6, 0.4]
SPEC_BASE_MASS = 50.0
SPEC_BASE_HEIGHT = 0.50
# default pose and EE position as stated in the generator's docstring
DOC_DEFAULT_POSE_DEG = [0.0, 70.0, 115.0, 0.0, -65.0, 0.0]
DOC_EE_WORLD = np.array([0.7469, 0.0, 0.3483])


# ------------------------------------------------------------------------- helpers


def _qrot(q, v):
    """Rotate v by quaternion q = (x, y, z, w)."""
    q = np.asarray(q, dtype=float)
    u, w = q[:3], q[3]
    v = np.asarray(v, dtype=float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _compose(t_a, t_b):
    """Transform (p, q) composition a * b, arrays of 7 (px, py, pz, qx, qy, qz, qw)."""
    t_a, t_b = np.asarray(t_a, float), np.asarray(t_b, float)
    p = t_a[:3] + _qrot(t_a[3:], t_b[:3])
    return np.concatenate([p, _qmul(t_a[3:], t_b[3:])])


def _seg_dist(a0, a1, b0, b1, n=201):
    pa = a0[None, :] + np.linspace(0, 1, n)[:, None] * (a1 - a0)[None, :]
    pb = b0[None, :] + np.linspace(0, 1, n)[:, None] * (b1 - b0)[None, :]
    return float(np.min(np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=-1)))


def _points_box_dist(points, box_tf, half):
    local = np.array([_qrot(box_tf[3:] * np.array([-1, -1, -1, 1.0]), p - box_tf[:3]) for p in points])
    out = np.maximum(np.abs(local) - np.asarray(half)[None, :], 0.0)
    return float(np.min(np.linalg.norm(out, axis=-1)))


def _usd_stage(path):
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    assert stage, path
    return stage


# ------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def robot_builder():
    import newton

    builder = newton.ModelBuilder()
    builder.add_usd(str(ROBOT_USD), enable_self_collisions=False)
    return builder


@pytest.fixture(scope="module")
def robot_model(robot_builder):
    return robot_builder.finalize(device="cpu")


def _fk(model, arm_q):
    """World transforms (n_body, 7) with the base at its imported pose and the arm at arm_q."""
    import newton
    import warp as wp

    q = model.joint_q.numpy().copy()
    for j, name in enumerate(SPEC_ARM_JOINTS):
        idx = _joint_index(model.joint_label, name)
        q[model.joint_q_start.numpy()[idx]] = arm_q[j]
    state = model.state()
    newton.eval_fk(
        model,
        wp.array(q, dtype=wp.float32, device="cpu"),
        wp.zeros(model.joint_dof_count, dtype=wp.float32, device="cpu"),
        state,
    )
    return state.body_q.numpy().astype(float)


def _joint_index(labels, name):
    hits = [i for i, lab in enumerate(labels) if lab.split("/")[-1] == name]
    assert len(hits) == 1, (name, labels)
    return hits[0]


def _body_index(labels, name):
    hits = [i for i, lab in enumerate(labels) if lab.split("/")[-1] == name]
    assert len(hits) == 1, (name, labels)
    return hits[0]


def _ee_world(model, body_q):
    from pxr import UsdGeom

    stage = _usd_stage(ROBOT_USD)
    ee = stage.GetPrimAtPath("/Robot/wrist_2/ee_frame")
    assert ee.IsValid() and ee.IsA(UsdGeom.Xform)
    offset = np.array(UsdGeom.Xformable(ee).GetLocalTransformation().ExtractTranslation())
    w2 = body_q[_body_index(model.body_label, "wrist_2")]
    return w2[:3] + _qrot(w2[3:], offset)


# ------------------------------------------------------------------------- files


def test_package_constants():
    assert list(ARM_JOINT_NAMES) == SPEC_ARM_JOINTS
    assert list(ARM_LINK_NAMES) == SPEC_ARM_LINKS
    assert list(LEG_SHAPE_NAMES) == SPEC_LEG_SHAPES
    for path in ALL_FILES:
        assert path.is_file(), path


def test_generation_is_deterministic_and_matches_committed(tmp_path):
    from dynpush.assets_usd.generate import generate

    written = generate(tmp_path)
    assert sorted(p.name for p in written.values()) == sorted(p.name for p in ALL_FILES)
    for path in ALL_FILES:
        assert (tmp_path / path.name).read_bytes() == path.read_bytes(), f"{path.name} is stale: regenerate it"


@pytest.mark.parametrize("path", ALL_FILES, ids=lambda p: p.name)
def test_usd_compliance(path):
    from dynpush.assets_usd.generate import check_compliance

    assert check_compliance(path) == []


def test_compliance_check_can_fail(tmp_path):
    from dynpush.assets_usd.generate import check_compliance

    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\n\ndef Xform "A"\n{\n}\n')
    assert len(check_compliance(bad)) >= 2  # no defaultPrim, no metersPerUnit, no upAxis


@pytest.mark.parametrize("path", ALL_FILES, ids=lambda p: p.name)
def test_stage_metadata(path):
    from pxr import UsdGeom, UsdPhysics

    stage = _usd_stage(path)
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdPhysics.GetStageKilogramsPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().IsValid()


# ------------------------------------------------------------------------- robot


def test_robot_usd_structure():
    from pxr import UsdPhysics

    stage = _usd_stage(ROBOT_USD)
    root = stage.GetDefaultPrim()
    assert root.GetPath().pathString == "/Robot"
    assert root.HasAPI(UsdPhysics.ArticulationRootAPI)
    bodies = sorted(p.GetName() for p in stage.Traverse() if p.HasAPI(UsdPhysics.RigidBodyAPI))
    assert bodies == sorted(["base", *SPEC_ARM_LINKS])
    joints = [p for p in stage.Traverse() if p.IsA(UsdPhysics.Joint)]
    assert sorted(j.GetName() for j in joints) == sorted(SPEC_ARM_JOINTS)
    assert all(j.IsA(UsdPhysics.RevoluteJoint) for j in joints)
    assert not any(p.IsA(UsdPhysics.Scene) for p in stage.Traverse())
    base = stage.GetPrimAtPath("/Robot/base")
    assert stage.GetPrimAtPath("/Robot/base/base_collision").HasAPI(UsdPhysics.CollisionAPI)
    for name in SPEC_LEG_SHAPES:
        assert base.GetChild(name).HasAPI(UsdPhysics.CollisionAPI), name
    wrist_2 = stage.GetPrimAtPath("/Robot/wrist_2")
    assert wrist_2.GetChild("ee_collision").GetTypeName() == "Sphere"
    # the velocity limit rides on newton:velocityLimit in deg/s
    j = stage.GetPrimAtPath("/Robot/joints/FA_ROT")
    assert j.GetAttribute("newton:velocityLimit").Get() == pytest.approx(10.0 * 180.0 / math.pi, rel=1e-6)
    # drive gains are per degree in USD
    assert j.GetAttribute("drive:angular:physics:stiffness").Get() == pytest.approx(50.0 * DEG, rel=1e-6)


def test_newton_import_bodies_joints(robot_builder):
    import newton

    b = robot_builder
    names = [lab.split("/")[-1] for lab in b.body_label]
    assert sorted(names) == sorted(["base", *SPEC_ARM_LINKS])
    types = list(b.joint_type)
    assert types.count(newton.JointType.FREE) == 1
    assert types.count(newton.JointType.REVOLUTE) == 6
    assert len(types) == 7
    free = types.index(newton.JointType.FREE)
    assert b.body_label[b.joint_child[free]].endswith("/base")
    # each arm joint moves the link of the same index, parent = previous link
    parents = ["base", *SPEC_ARM_LINKS[:-1]]
    for name, child, parent in zip(SPEC_ARM_JOINTS, SPEC_ARM_LINKS, parents, strict=True):
        j = _joint_index(b.joint_label, name)
        assert types[j] == newton.JointType.REVOLUTE
        assert b.body_label[b.joint_child[j]].endswith("/" + child)
        assert b.body_label[b.joint_parent[j]].endswith("/" + parent)
    total = sum(b.body_mass)
    assert total == pytest.approx(SPEC_BASE_MASS + sum(SPEC_LINK_MASS), abs=1e-4)
    assert total == pytest.approx(56.7, abs=1e-4)
    assert b.body_mass[_body_index(b.body_label, "base")] == pytest.approx(50.0)
    for link, mass in zip(SPEC_ARM_LINKS, SPEC_LINK_MASS, strict=True):
        i = _body_index(b.body_label, link)
        assert b.body_mass[i] == pytest.approx(mass, rel=1e-6)
        inertia = np.array(b.body_inertia[i], dtype=float).reshape(3, 3)
        # explicit diagonal inertia including the 0.1 kg m^2 armature stand-in
        assert np.all(np.diag(inertia) > 0.1) and np.all(np.diag(inertia) < 0.2)
        assert np.allclose(inertia, np.diag(np.diag(inertia)), atol=1e-7)


def test_newton_import_limits_and_drives(robot_builder):
    b = robot_builder
    qd_start = list(b.joint_qd_start)
    for j_spec, name in enumerate(SPEC_ARM_JOINTS):
        dof = qd_start[_joint_index(b.joint_label, name)]
        lo, hi = SPEC_LIMITS_DEG[j_spec]
        assert b.joint_limit_lower[dof] == pytest.approx(lo * math.pi / 180.0, abs=1e-5), name
        assert b.joint_limit_upper[dof] == pytest.approx(hi * math.pi / 180.0, abs=1e-5), name
        assert b.joint_effort_limit[dof] == pytest.approx(SPEC_EFFORT[j_spec], rel=1e-6), name
        assert b.joint_velocity_limit[dof] == pytest.approx(SPEC_VEL[j_spec], rel=1e-5), name
        assert b.joint_target_ke[dof] == pytest.approx(SPEC_KE[j_spec], rel=1e-5), name
        assert b.joint_target_kd[dof] == pytest.approx(SPEC_KD[j_spec], rel=1e-5), name
        # joint_target_q is indexed by coordinate (the free joint takes 7), not by DOF
        assert b.joint_target_q[b.joint_q_start[_joint_index(b.joint_label, name)]] == 0.0


def test_legs_geometry(robot_builder):
    import newton

    b = robot_builder
    base = _body_index(b.body_label, "base")
    shapes = {lab.split("/")[-1]: i for i, lab in enumerate(b.shape_label)}
    box = shapes["base_collision"]
    assert b.shape_type[box] == newton.GeoType.BOX and b.shape_body[box] == base
    assert np.allclose(b.shape_scale[box], (0.30, 0.15, 0.10), atol=1e-6)
    assert np.allclose(np.asarray(b.shape_transform[box])[:3], 0.0, atol=1e-7)
    for leg, sx, sy in (("LF", 1, 1), ("RF", 1, -1), ("LH", -1, 1), ("RH", -1, -1)):
        thigh, shank = shapes[f"{leg}_thigh"], shapes[f"{leg}_shank"]
        ends = {}
        for key, s, radius in (("thigh", thigh, 0.06), ("shank", shank, 0.04)):
            assert b.shape_type[s] == newton.GeoType.CAPSULE and b.shape_body[s] == base
            r, half, _ = b.shape_scale[s]
            assert r == pytest.approx(radius, abs=1e-6)
            tf = np.asarray(b.shape_transform[s], dtype=float)
            axis = _qrot(tf[3:], (0, 0, 1))
            e0, e1 = tf[:3] + half * axis, tf[:3] - half * axis
            ends[key] = sorted([e0, e1], key=lambda p: -p[2])  # upper end first
            ends[key + "_half"] = half
        # thigh: from (+-0.30, +-0.19, 0) to the knee, 0.30 long
        assert np.allclose(ends["thigh"][0], (sx * 0.30, sy * 0.19, 0.0), atol=1e-5), leg
        assert 2 * ends["thigh_half"] == pytest.approx(0.30, abs=1e-6)
        knee = ends["thigh"][1]
        assert np.allclose(ends["shank"][0], knee, atol=1e-5), leg
        # knees inward ("X" stance): front knees behind the hip, hind knees in front
        assert sx * knee[0] < 0.30 - 0.05, leg
        # lowest point of the shank exactly on the ground at nominal height
        lowest = min(ends["shank"][0][2], ends["shank"][1][2]) - 0.04
        assert lowest + SPEC_BASE_HEIGHT == pytest.approx(0.0, abs=2e-6), leg
        # foot centre 0.33 from the knee on the shank line, 0.03 above the ground, below the hip
        u = (ends["shank"][1] - knee) / np.linalg.norm(ends["shank"][1] - knee)
        foot = knee + 0.33 * u
        assert np.allclose(foot, (sx * 0.30, sy * 0.19, -0.47), atol=1e-5), leg


def test_leg_attributes_and_constants():
    from dynpush.assets_usd import generate as gen

    stage = _usd_stage(ROBOT_USD)
    base = stage.GetPrimAtPath("/Robot/base")
    feet = np.array(base.GetAttribute("dynpush:legNominalFootPositions").Get(), dtype=float)
    hips = np.array(base.GetAttribute("dynpush:legHipPositions").Get(), dtype=float)
    starts = np.array(base.GetAttribute("dynpush:legThighStartPositions").Get(), dtype=float)
    hfe = np.array(base.GetAttribute("dynpush:legNominalHFE").Get(), dtype=float)
    kfe = np.array(base.GetAttribute("dynpush:legNominalKFE").Get(), dtype=float)
    assert base.GetAttribute("dynpush:legThighLength").Get() == pytest.approx(0.30)
    assert base.GetAttribute("dynpush:legShankLength").Get() == pytest.approx(0.33)
    signs = np.array([(1, 1), (1, -1), (-1, 1), (-1, -1)], dtype=float)
    assert np.allclose(hips, np.c_[signs * (0.30, 0.10), np.zeros(4)], atol=1e-6)
    assert np.allclose(starts, np.c_[signs * (0.30, 0.19), np.zeros(4)], atol=1e-6)
    assert np.allclose(feet, np.c_[signs * (0.30, 0.19), np.full(4, -0.47)], atol=1e-5)
    # independent planar FK of the authored angles (rotations about +y)
    for i in range(4):
        knee = starts[i] + 0.30 * np.array([-math.sin(hfe[i]), 0.0, -math.cos(hfe[i])])
        foot = knee + 0.33 * np.array([-math.sin(hfe[i] + kfe[i]), 0.0, -math.cos(hfe[i] + kfe[i])])
        assert np.allclose(foot, feet[i], atol=1e-5)
    assert hfe[0] > 0 > kfe[0] and hfe[2] < 0 < kfe[2]  # X stance
    assert abs(kfe[0]) == pytest.approx(math.acos(1.0 / 9.0), abs=1e-6)
    # module constants agree with what is authored
    assert np.allclose(gen.LEG_NOMINAL_FOOT_POSITIONS, feet, atol=1e-6)
    assert np.allclose(gen.LEG_NOMINAL_HFE, hfe, atol=1e-6)
    assert np.allclose(gen.LEG_NOMINAL_KFE, kfe, atol=1e-6)
    assert np.allclose(gen.LEG_HIP_POSITIONS, hips, atol=1e-7)


def test_arm_zero_pose_points_up(robot_model):
    model = robot_model
    body_q = _fk(model, [0.0] * 6)
    base = body_q[_body_index(model.body_label, "base")]
    assert np.allclose(base[:3], (0.0, 0.0, SPEC_BASE_HEIGHT), atol=1e-6)
    # joint origins along the arm at q = 0: mount 0.60, +0.10, +0.40, +0.10, +0.30, +0.10
    expected_z = {"shoulder": 0.60, "upper_arm": 0.70, "elbow": 1.10, "forearm": 1.20, "wrist_1": 1.50, "wrist_2": 1.60}
    for link, z in expected_z.items():
        assert np.allclose(body_q[_body_index(model.body_label, link)][:3], (0.25, 0.0, z), atol=1e-5), link
    assert np.allclose(_ee_world(model, body_q), (0.25, 0.0, 1.68), atol=1e-5)
    # positive SH_FLE tips the arm forward (+x); rolls about the arm axis leave the EE in place
    reach = 0.40 + 0.40 + 0.10 + 0.08  # SH_FLE axis to the EE centre
    tipped = _ee_world(model, _fk(model, [0.0, 0.3, 0.0, 0.0, 0.0, 0.0]))
    assert np.allclose(tipped, (0.25 + reach * math.sin(0.3), 0.0, 0.70 + reach * math.cos(0.3)), atol=1e-5)
    rolled = _ee_world(model, _fk(model, [0.0, 0.0, 0.0, 1.0, 0.0, 1.0]))
    assert np.allclose(rolled, (0.25, 0.0, 1.68), atol=1e-5)
    # EL_FLE and WRIST_1 also pitch forward about +y
    bent = _ee_world(model, _fk(model, [0.0, 0.0, 0.5, 0.0, 0.4, 0.0]))
    x = 0.25 + 0.40 * math.sin(0.5) + 0.18 * math.sin(0.9)
    z = 1.10 + 0.40 * math.cos(0.5) + 0.18 * math.cos(0.9)
    assert np.allclose(bent, (x, 0.0, z), atol=1e-5)
    # SH_ROT turns about the base z axis (+90 deg: forward becomes +y)
    turned = _ee_world(model, _fk(model, [math.pi / 2, 0.3, 0.0, 0.0, 0.0, 0.0]))
    assert np.allclose(turned, (0.25, reach * math.sin(0.3), 0.70 + reach * math.cos(0.3)), atol=1e-5)


def test_default_pose_ee_position(robot_model):
    stage = _usd_stage(ROBOT_USD)
    root = stage.GetPrimAtPath("/Robot")
    q = np.array(root.GetAttribute("dynpush:defaultArmJointPositions").Get(), dtype=float)
    assert q.shape == (6,)
    assert np.allclose(q, np.radians(DOC_DEFAULT_POSE_DEG), atol=1e-6)
    assert q[5] == 0.0
    for j, (lo, hi) in enumerate(SPEC_LIMITS_DEG):
        assert lo * DEG < q[j] < hi * DEG
    ee = _ee_world(robot_model, _fk(robot_model, q))
    assert np.linalg.norm(ee - DOC_EE_WORLD) < 0.01, ee
    assert np.linalg.norm(ee - DOC_EE_WORLD) < 2e-4, ee  # the docstring states 4 decimals
    # "about 0.45 m in front of the base front face, about 0.35 m above ground"
    assert ee[0] - 0.30 == pytest.approx(0.45, abs=0.01)
    assert ee[2] == pytest.approx(0.35, abs=0.01)


def _collision_geoms(model, body_q):
    """name -> (body name, kind, data) in world; capsule/sphere: (p0, p1, r), box: (tf, half)."""
    import newton

    out = {}
    shape_tf = model.shape_transform.numpy().astype(float)
    shape_scale = model.shape_scale.numpy().astype(float)
    shape_body = model.shape_body.numpy()
    shape_type = model.shape_type.numpy()
    for s, label in enumerate(model.shape_label):
        body = model.body_label[shape_body[s]].split("/")[-1]
        tf = _compose(body_q[shape_body[s]], shape_tf[s])
        if shape_type[s] == int(newton.GeoType.BOX):
            out[label] = (body, "box", (tf, shape_scale[s]))
        elif shape_type[s] == int(newton.GeoType.CAPSULE):
            r, half, _ = shape_scale[s]
            axis = _qrot(tf[3:], (0, 0, 1))
            out[label] = (body, "seg", (tf[:3] + half * axis, tf[:3] - half * axis, r))
        elif shape_type[s] == int(newton.GeoType.SPHERE):
            out[label] = (body, "seg", (tf[:3], tf[:3], shape_scale[s][0]))
        else:
            raise AssertionError(f"unexpected shape type on the robot: {label}")
    return out


def _clearance(a, b):
    (_, ka, da), (_, kb, db) = a, b
    if ka == "box":
        (ka, da), (kb, db) = (kb, db), (ka, da)
    p0, p1, r = da
    if kb == "box":
        pts = p0[None, :] + np.linspace(0, 1, 201)[:, None] * (p1 - p0)[None, :]
        return _points_box_dist(pts, db[0], db[1]) - r
    q0, q1, rb = db
    return _seg_dist(p0, p1, q0, q1) - r - rb


@pytest.mark.parametrize("pose", ["zero", "default"])
def test_arm_clear_of_base_legs_and_itself(robot_model, pose):
    model = robot_model
    q = [0.0] * 6
    if pose == "default":
        q = np.radians(DOC_DEFAULT_POSE_DEG)
    geoms = _collision_geoms(model, _fk(model, q))
    chain = ["base", *SPEC_ARM_LINKS]
    adjacent = {frozenset(p) for p in zip(chain[:-1], chain[1:])}
    checked = 0
    labels = sorted(geoms)
    for i, la in enumerate(labels):
        for lb in labels[i + 1 :]:
            ba, bb = geoms[la][0], geoms[lb][0]
            if ba == bb:
                continue
            if "base" in (ba, bb):
                pass  # every arm link, the shoulder included, must clear the base and legs
            elif frozenset((ba, bb)) in adjacent:
                continue
            gap = _clearance(geoms[la], geoms[lb])
            assert gap > 0.003, (pose, la, lb, gap)
            checked += 1
    assert checked > 40


# ------------------------------------------------------------------------- objects, ground


@pytest.mark.parametrize(
    ("path", "kind", "scale", "inertia"),
    [
        (CUBOID_USD, "BOX", (0.25, 0.25, 0.35), (5 * (0.25 + 0.49) / 12, 5 * (0.25 + 0.49) / 12, 5 * 0.5 / 12)),
        (CYLINDER_USD, "CYLINDER", (0.25, 0.35, 0.0), (5 * (0.1875 + 0.49) / 12, 5 * (0.1875 + 0.49) / 12, 0.15625)),
    ],
    ids=["cuboid", "cylinder"],
)
def test_object_files(path, kind, scale, inertia):
    import newton
    from pxr import UsdGeom, UsdPhysics, UsdShade

    stage = _usd_stage(path)
    prims = list(stage.Traverse())
    bodies = [p for p in prims if p.HasAPI(UsdPhysics.RigidBodyAPI)]
    assert [p.GetName() for p in bodies] == ["object"]
    assert not any(p.IsA(UsdPhysics.Joint) or p.IsA(UsdGeom.Plane) or p.IsA(UsdPhysics.Scene) for p in prims)
    colliders = [p for p in prims if p.HasAPI(UsdPhysics.CollisionAPI)]
    assert len(colliders) == 1
    mat, _ = UsdShade.MaterialBindingAPI(colliders[0]).ComputeBoundMaterial("physics")
    api = UsdPhysics.MaterialAPI(mat.GetPrim())
    assert api.GetDynamicFrictionAttr().Get() == pytest.approx(0.8)
    assert api.GetStaticFrictionAttr().Get() == pytest.approx(0.8)

    b = newton.ModelBuilder()
    b.add_usd(str(path))
    assert b.body_count == 1 and b.body_label[0].endswith("/object")
    assert list(b.joint_type) == [newton.JointType.FREE]  # added by Newton for the floating body
    assert b.body_mass[0] == pytest.approx(5.0)
    got_inertia = np.array(b.body_inertia[0], dtype=float).reshape(3, 3)
    assert np.allclose(got_inertia, np.diag(inertia), atol=1e-5)
    assert b.shape_count == 1
    assert b.shape_type[0] == getattr(newton.GeoType, kind)
    assert b.shape_body[0] == 0
    assert np.allclose(b.shape_scale[0], scale, atol=1e-6)
    assert np.allclose(np.asarray(b.shape_transform[0]), (0, 0, 0, 0, 0, 0, 1), atol=1e-7)
    assert b.shape_material_mu[0] == pytest.approx(0.8)


def test_ground_file():
    import newton

    b = newton.ModelBuilder()
    b.add_usd(str(GROUND_USD))
    assert b.body_count == 0 and b.joint_count == 0
    assert b.shape_count == 1
    assert b.shape_type[0] == newton.GeoType.PLANE and b.shape_body[0] == -1
    assert np.allclose(np.asarray(b.shape_transform[0]), (0, 0, 0, 0, 0, 0, 1), atol=1e-7)  # z-up at z = 0
    assert b.shape_material_mu[0] == pytest.approx(0.4)  # the floor's own coefficient (docs/task.md, "Deviations from the paper": friction)
