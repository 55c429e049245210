"""robot_legged.usda: structure, leg kinematics of the nominal stance, and standing in Newton.

The standing test closes the loop between the asset and ``dynpush.sim.leg_statics``: with joint
targets offset by the static torques ``tau / k_p`` (the map the tracked base uses for its leg-torque
constraint) the PD-driven legs hold the 50 kg base at its nominal 0.50 m; without the offset the
same drives sag. Expected numbers are typed in from the asset specification.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynpush.assets_usd import ARM_JOINT_NAMES, LEG_JOINT_NAMES, ROBOT_LEGGED_USD, GROUND_USD

SPEC_LEG_JOINTS = [f"{leg}_{j}" for leg in ("LF", "RF", "LH", "RH") for j in ("HAA", "HFE", "KFE")]
SPEC_LEG_BODIES = [f"{leg}_{b}" for leg in ("LF", "RF", "LH", "RH") for b in ("HIP", "THIGH", "SHANK")]
SPEC_LIMITS = [(-0.72, 0.72), (-1.6, 1.6), (-2.6, 2.6)] * 4
SPEC_HFE, SPEC_KFE = 0.772294, 1.459455  # acos(0.202 / 0.282), acos(1 / 9)
SPEC_DEFAULT = [v for sx in (1, 1, -1, -1) for v in (0.0, sx * SPEC_HFE, -sx * SPEC_KFE)]
SPEC_FEET = np.array([[0.30, 0.19, -0.47], [0.30, -0.19, -0.47], [-0.30, 0.19, -0.47], [-0.30, -0.19, -0.47]])
SPEC_ROBOT_MASS = 50.0 + 6.7  # legged robot + arm
STANDING_SECONDS = 2.0


def _leaf(label: str) -> str:
    return label.split("/")[-1]


@pytest.fixture(scope="module")
def legged_builder():
    import newton

    builder = newton.ModelBuilder()
    builder.add_usd(str(ROBOT_LEGGED_USD), enable_self_collisions=False)
    return builder


def _set_joint_positions(builder, positions: dict[str, float]) -> None:
    index = {_leaf(label): j for j, label in enumerate(builder.joint_label)}
    q = list(builder.joint_q)
    q[0:7] = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]  # base at its nominal height
    for name, value in positions.items():
        q[builder.joint_q_start[index[name]]] = value
    builder.joint_q = q


def _default_positions() -> dict[str, float]:
    from pxr import Usd

    stage = Usd.Stage.Open(str(ROBOT_LEGGED_USD))
    root = stage.GetDefaultPrim()
    legs = list(root.GetAttribute("dynpush:defaultLegJointPositions").Get())
    arm = list(root.GetAttribute("dynpush:defaultArmJointPositions").Get())
    return dict(zip(LEG_JOINT_NAMES, legs)) | dict(zip(ARM_JOINT_NAMES, arm))


def test_legged_robot_bodies_joints_and_drives(legged_builder):
    import newton

    b = legged_builder
    assert list(LEG_JOINT_NAMES) == SPEC_LEG_JOINTS
    assert sorted(_leaf(lab) for lab in b.body_label) == sorted(["base", *SPEC_LEG_BODIES, "shoulder", "upper_arm",
                                                                  "elbow", "forearm", "wrist_1", "wrist_2"])
    assert sum(b.body_mass) == pytest.approx(SPEC_ROBOT_MASS, abs=1e-4)
    index = {_leaf(label): j for j, label in enumerate(b.joint_label)}
    for name, (lo, hi) in zip(SPEC_LEG_JOINTS, SPEC_LIMITS):
        j = index[name]
        assert b.joint_type[j] == newton.JointType.REVOLUTE
        d = b.joint_qd_start[j]
        assert (b.joint_limit_lower[d], b.joint_limit_upper[d]) == pytest.approx((lo, hi), abs=1e-5), name
        assert b.joint_effort_limit[d] == pytest.approx(80.0) and b.joint_velocity_limit[d] == pytest.approx(7.5, rel=1e-5)
        assert b.joint_target_ke[d] == pytest.approx(80.0, rel=1e-5) and b.joint_target_kd[d] == pytest.approx(2.0, rel=1e-5)
    shapes = {_leaf(label) for label in b.shape_label}
    assert {f"{leg}_foot" for leg in ("LF", "RF", "LH", "RH")} <= shapes
    assert "LF_thigh" in shapes and "LF_shank" in shapes


def test_default_leg_positions_put_the_feet_at_the_nominal_stance(legged_builder):
    import copy

    import newton

    assert list(_default_positions().values())[:12] == pytest.approx(SPEC_DEFAULT, abs=1e-6)
    builder = copy.deepcopy(legged_builder)
    _set_joint_positions(builder, _default_positions())
    model = builder.finalize(device="cpu")
    state = model.state()
    newton.eval_fk(model, model.joint_q, model.joint_qd, state)
    body_q = state.body_q.numpy()
    shape_index = {_leaf(label): s for s, label in enumerate(builder.shape_label)}
    base = body_q[0]
    assert base[:3] == pytest.approx([0.0, 0.0, 0.5])
    for leg, expected in zip(("LF", "RF", "LH", "RH"), SPEC_FEET):
        s = shape_index[f"{leg}_foot"]
        x = body_q[builder.shape_body[s]]
        offset = np.array(builder.shape_transform[s][:3])
        u, w = x[3:6], x[6]
        foot = x[:3] + offset + 2.0 * np.cross(u, np.cross(u, offset) + w * offset)
        np.testing.assert_allclose(foot - base[:3], expected, atol=1e-5, err_msg=leg)


def _stand(legged_builder, solver: str, compensate: bool) -> np.ndarray:
    """Base poses (x, y, z, quaternion) once per 0.1 s over STANDING_SECONDS on the ground."""
    import copy

    import newton

    from dynpush.sim.leg_statics import leg_torque_map
    from dynpush.assets_usd import generate as spec

    builder = copy.deepcopy(legged_builder)
    builder.add_usd(str(GROUND_USD))
    _set_joint_positions(builder, _default_positions())
    model = builder.finalize(device="cpu")
    state_0, state_1, control = model.state(), model.state(), model.control()
    newton.eval_fk(model, state_0.joint_q, state_0.joint_qd, state_0)
    targets = state_0.joint_q.numpy().copy()
    if compensate:  # the legs carry the weight at the whole robot's CoM: tau = M @ (support wrench on the base)
        body_q, mass, com = state_0.body_q.numpy(), model.body_mass.numpy(), model.body_com.numpy()
        u, w = body_q[:, 3:6], body_q[:, 6:7]
        world_com = body_q[:, :3] + com + 2.0 * np.cross(u, np.cross(u, com) + w * com)
        robot_com = (world_com * mass[:, None]).sum(0) / mass.sum()
        weight = np.array([0.0, 0.0, mass.sum() * 9.81])
        wrench = np.concatenate([weight, np.cross(robot_com - body_q[0, :3], weight)])
        torque_map = leg_torque_map(*(np.array(v) for v in (spec.LEG_HIP_POSITIONS, spec.LEG_THIGH_START_POSITIONS,
                                                            spec.LEG_NOMINAL_KNEE_POSITIONS, spec.LEG_NOMINAL_FOOT_POSITIONS)))
        index = {_leaf(label): j for j, label in enumerate(builder.joint_label)}
        for name, tau in zip(LEG_JOINT_NAMES, torque_map @ wrench):
            targets[builder.joint_q_start[index[name]]] -= tau / spec.LEG_STIFFNESS
    control.joint_target_q.assign(targets)
    if solver == "xpbd":
        sim = newton.solvers.SolverXPBD(model, iterations=4, rigid_contact_con_weighting=False)
    else:
        sim = newton.solvers.SolverMuJoCo(model, use_mujoco_contacts=False)
    pipeline = newton.CollisionPipeline(model, rigid_contact_max=64)
    contacts = pipeline.contacts()
    substeps, poses = 4, []
    for step in range(int(round(STANDING_SECONDS / 0.02))):
        for _ in range(substeps):
            state_0.clear_forces()
            pipeline.collide(state_0, contacts)
            sim.step(state_0, state_1, control, contacts, 0.02 / substeps)
            state_0, state_1 = state_1, state_0
        if step % 5 == 4:
            poses.append(state_0.body_q.numpy()[0].copy())
    return np.array(poses)


def _tilt_deg(quat_xyzw: np.ndarray) -> float:
    x, y = quat_xyzw[0], quat_xyzw[1]
    return math.degrees(math.acos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0)))


def test_legs_hold_the_base_with_gravity_compensated_targets_and_sag_without(legged_builder):
    held = _stand(legged_builder, "xpbd", compensate=True)
    assert np.all(np.abs(held[:, 2] - 0.50) < 0.03), held[:, 2]
    assert max(_tilt_deg(q) for q in held[:, 3:]) < 2.0
    assert np.linalg.norm(held[-1, :2]) < 0.03  # the feet do not slide away
    sagged = _stand(legged_builder, "xpbd", compensate=False)
    assert sagged[-1, 2] < 0.45, sagged[:, 2]  # the drives are compliant: k_p = 80 N m/rad


@pytest.mark.slow
def test_legs_hold_the_base_in_mujoco_warp(legged_builder):
    held = _stand(legged_builder, "mujoco", compensate=True)
    assert np.all(np.abs(held[-10:, 2] - 0.50) < 0.01), held[:, 2]
    assert max(_tilt_deg(q) for q in held[-10:, 3:]) < 1.0
