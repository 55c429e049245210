"""The runtime's numpy observation builder equals the simulator's ``compute_observations`` kernel.

Random states of many worlds go into a RobotView/PushTask on the CPU device; the kernel's actor
columns are compared with ``dynpush.runtime.observation.policy_observation`` fed the same raw
quantities, its privileged critic columns with a numpy reference written here from the paper's
Table "Observations", and its additive uniform noise with the table's half-widths.
"""

import subprocess
import sys

import numpy as np
import pytest
import warp as wp

from dynpush.kernels.push.observations import POLICY_TERMS, PRIVILEGED_TERMS, compute_observations
from dynpush.kernels.push.views import CONTACT_COLUMNS, EE_CONTACT, NUM_CRITIC_OBS, NUM_POLICY_OBS, PushTask, RobotView
from dynpush.runtime.observation import POLICY_OBSERVATION_LAYOUT, POLICY_OBSERVATION_SIZE, policy_observation
from warp_numpy_helpers import DEVICE, axis_angle_quat, make_struct, quat_mul, quat_rotate, quat_rotate_inv, random_quat

wp.config.quiet = True
STRIDE = 3  # bodies per world: object, base, end-effector link
Q, QD, ARM_Q, ARM_QD = 20, 18, 7, 6  # joint coordinates/DOFs per world and the arm's offsets
# Paper Table "Observations": noise half-width of each actor term, in POLICY_TERMS order.
PAPER_NOISE = {
    "ee_to_object_b": 0.02, "object_rotation_b": 0.01, "arm_joint_position": 0.01, "base_linear_velocity_b": 0.01,
    "base_angular_velocity_b": 0.20, "arm_joint_velocity": 0.50, "projected_gravity_b": 0.05,
    "object_to_goal_b": 0.02, "goal_rotation_o": 0.01, "last_actions": 0.0,
}
NOISE_SCALE = np.concatenate([np.full(size, PAPER_NOISE[name]) for name, size in POLICY_TERMS]).astype(np.float32)
SUCCESS_DISTANCE, SUCCESS_ANGLE = 0.1, np.radians(10.0)  # [m], [rad]: the paper's success rule (III-B)


def random_worlds(rng, n):
    """Random raw state of ``n`` worlds (float32-exact numpy): robot and task buffer values."""
    w = np.arange(n)
    nb = n * STRIDE
    body_com = rng.uniform(-0.1, 0.1, (nb, 3))
    body_com[w * STRIDE + 1] = 0.0  # the base's CoM is at the base frame origin (robot.usda)
    robot = dict(
        body_q=np.column_stack([rng.uniform(-2.0, 2.0, (nb, 2)), rng.uniform(0.1, 1.2, nb), random_quat(rng, nb)]),
        body_qd=rng.normal(size=(nb, 6)), body_com=body_com, body_mass=rng.uniform(1.0, 10.0, nb),
        joint_q=rng.normal(size=n * Q), joint_qd=2.0 * rng.normal(size=n * QD),
        base_body=w * STRIDE + 1, object_body=w * STRIDE, ee_body=w * STRIDE + 2,
        arm_q_start=w * Q + ARM_Q, arm_qd_start=w * QD + ARM_QD, robot_body_start=w * STRIDE + 1,
        robot_body_count=2, ee_offset=rng.uniform(-0.1, 0.1, 3),
    )
    shape = rng.integers(0, 2, n)
    # Half the goals near their objects, on both sides of the success distance and angle.
    x_o = robot["body_q"][w * STRIDE]
    goal_pos, goal_quat = rng.uniform(-2.0, 2.0, (n, 3)), random_quat(rng, n)
    near = w[: n // 2]
    offset = rng.uniform(0.0, 2.0 * SUCCESS_DISTANCE, (len(near), 1))
    goal_pos[near] = x_o[near, :3] + random_direction(rng, len(near)) * offset
    goal_quat[near] = quat_mul(x_o[near, 3:], axis_angle_quat(random_direction(rng, len(near)),
                                                              rng.uniform(0.0, 2.0 * SUCCESS_ANGLE, len(near))))
    task = dict(
        goal_pos=goal_pos, goal_quat=goal_quat, object_dims=rng.uniform(0.25, 1.0, (n, 3)),
        object_shape=shape, object_mass=rng.uniform(1.0, 10.0, n), object_com_o=rng.uniform(-0.2, 0.2, (n, 3)),
        object_inertia=rng.uniform(0.05, 1.0, (n, 3)), arm_default=rng.uniform(-1.0, 1.0, 5),
        actions=rng.normal(size=(n, 11)), last_actions=rng.normal(size=(n, 11)),
        contacts=rng.integers(0, 2, (n, CONTACT_COLUMNS)), rng_counter=np.zeros(n, dtype=int),
    )
    f32 = lambda d: {k: v.astype(np.float32).astype(np.float64) if np.asarray(v).dtype.kind == "f" else v for k, v in d.items()}  # noqa: E731
    return f32(robot), f32(task)


def random_direction(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def observe(robot, task, noise_enabled, seed=5):
    """Launches ``compute_observations``; returns (policy, critic) as numpy."""
    n = len(robot["base_body"])
    policy, critic = (wp.zeros((n, size), dtype=float, device=DEVICE) for size in (NUM_POLICY_OBS, NUM_CRITIC_OBS))
    wp.launch(compute_observations, dim=n, device=DEVICE,
              inputs=[make_struct(RobotView, **robot), make_struct(PushTask, **task),
                      wp.array(NOISE_SCALE, dtype=float, device=DEVICE), int(noise_enabled), seed, SUCCESS_DISTANCE,
                      wp.array([SUCCESS_ANGLE], dtype=float, device=DEVICE), policy, critic])
    return policy.numpy(), critic.numpy()


def raw_measurements(robot, task):
    """What the runtime measures in the same state: poses, the base twist, EE position, joints, goal."""
    x_b, x_o = robot["body_q"][robot["base_body"]], robot["body_q"][robot["object_body"]]
    x_e = robot["body_q"][robot["ee_body"]]
    qd_b = robot["body_qd"][robot["base_body"]]
    c_b = x_b[:, :3] + quat_rotate(x_b[:, 3:], robot["body_com"][robot["base_body"]])
    arm = np.arange(5)
    return dict(
        base_position=x_b[:, :3], base_quat=x_b[:, 3:],
        base_linear_velocity_w=qd_b[:, :3] + np.cross(qd_b[:, 3:], x_b[:, :3] - c_b),  # base frame origin
        base_angular_velocity_w=qd_b[:, 3:],
        object_position=x_o[:, :3], object_quat=x_o[:, 3:],
        ee_position=x_e[:, :3] + quat_rotate(x_e[:, 3:], robot["ee_offset"]),
        arm_joint_position=robot["joint_q"][robot["arm_q_start"][:, None] + arm],
        arm_joint_velocity=robot["joint_qd"][robot["arm_qd_start"][:, None] + arm],
        arm_default=task["arm_default"], goal_position=task["goal_pos"], goal_quat=task["goal_quat"],
        last_actions=task["actions"],  # a_t just applied = the next observation's "previous actions"
    )


def object_at_goal_reference(x_o, goal_pos, goal_quat):
    """The success rule (III-B): within the success distance, and the relative rotation's angle
    (``2 acos |<q_o, q_g>|``) within the success angle."""
    angle = 2.0 * np.arccos(np.clip(np.abs(np.sum(x_o[:, 3:] * goal_quat, axis=1)), 0.0, 1.0))
    return (np.linalg.norm(goal_pos - x_o[:, :3], axis=1) <= SUCCESS_DISTANCE) & (angle <= SUCCESS_ANGLE)


def privileged_reference(robot, task):
    """Paper Table "Observations", o_t^pr: contact, CoM, mass, dims, inertia, object twist, shape one-hot; then ours,
    whether the object is at its goal."""
    x_b, x_o = robot["body_q"][robot["base_body"]], robot["body_q"][robot["object_body"]]
    qd_o = robot["body_qd"][robot["object_body"]]
    q_b = x_b[:, 3:]
    com_w = x_o[:, :3] + quat_rotate(x_o[:, 3:], task["object_com_o"])
    v_origin = qd_o[:, :3] + np.cross(qd_o[:, 3:], x_o[:, :3] - com_w)  # Newton's twist is at the CoM
    shape = task["object_shape"]
    return np.column_stack([
        task["contacts"][:, EE_CONTACT], quat_rotate_inv(q_b, com_w - x_b[:, :3]), task["object_mass"],
        task["object_dims"], task["object_inertia"], quat_rotate_inv(q_b, v_origin), quat_rotate_inv(q_b, qd_o[:, 3:]),
        shape == 0, shape == 1, object_at_goal_reference(x_o, task["goal_pos"], task["goal_quat"]),
    ])


@pytest.fixture(scope="module")
def worlds():
    return random_worlds(np.random.default_rng(21), 4096)


def test_layout_is_the_papers_table():
    # Paper Table "Observations": sizes of o_t in order; the kernel uses the runtime's layout object.
    assert [size for _, size in POLICY_OBSERVATION_LAYOUT] == [3, 9, 5, 3, 3, 5, 3, 3, 9, 11]
    assert POLICY_TERMS is POLICY_OBSERVATION_LAYOUT
    assert POLICY_OBSERVATION_SIZE == NUM_POLICY_OBS == 54
    assert NUM_POLICY_OBS + sum(size for _, size in PRIVILEGED_TERMS) == NUM_CRITIC_OBS == 74


def test_runtime_imports_numpy_only():
    code = ("import sys, dynpush.runtime.observation; "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('warp', 'torch', 'newton', 'onnxruntime')); "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_policy_observation_equals_kernel(worlds):
    robot, task = worlds
    policy, critic = observe(robot, task, noise_enabled=False)
    expected = policy_observation(**raw_measurements(robot, task))
    assert expected.shape == (4096, 54) and expected.dtype == np.float32
    start = 0
    for name, size in POLICY_TERMS:
        columns = slice(start, start + size)
        np.testing.assert_allclose(expected[:, columns], policy[:, columns], atol=1e-5, rtol=1e-5, err_msg=name)
        start += size
    np.testing.assert_array_equal(critic[:, :54], policy, err_msg="the critic's first 54 entries are the noiseless o_t")


def test_critic_privileged_terms(worlds):
    robot, task = worlds
    _, critic = observe(robot, task, noise_enabled=False)
    np.testing.assert_allclose(critic[:, 54:], privileged_reference(robot, task), atol=1e-5, rtol=1e-5)
    at_goal = critic[:, -1]
    assert 0.05 < at_goal.mean() < 0.45, "the random worlds hold both objects at their goals and objects beside them"


def test_noise_bounded_zero_mean_and_actions_noise_free(worlds):
    robot, task = worlds
    n = len(robot["base_body"])
    _, clean = observe(robot, task, noise_enabled=False)
    noisy, critic = observe(robot, task, noise_enabled=True)
    np.testing.assert_array_equal(critic, clean, err_msg="the critic stays noiseless")
    noise = noisy.astype(np.float64) - clean[:, :54]
    noisy_cols = NOISE_SCALE > 0
    assert (np.abs(noise) <= NOISE_SCALE + 1e-6).all(), "noise beyond the Table's half-width"
    np.testing.assert_array_equal(noise[:, ~noisy_cols], 0.0, err_msg="previous actions are noise-free")
    assert (noise[:, noisy_cols] != 0.0).mean() > 0.99
    sigma = NOISE_SCALE[noisy_cols] / np.sqrt(3.0)  # std of U(-s, s)
    assert (np.abs(noise[:, noisy_cols].mean(axis=0)) < 5.0 * sigma / np.sqrt(n)).all(), "noise mean ~0"
    np.testing.assert_allclose(noise[:, noisy_cols].std(axis=0), sigma, rtol=0.06)
    # Independent draws: across entries of one world, and from one step to the next.
    assert abs(np.corrcoef(noise[:, 0], noise[:, 1])[0, 1]) < 0.06
    task_next = dict(task, rng_counter=task["rng_counter"] + 1)
    again, _ = observe(robot, task_next, noise_enabled=True)
    assert (again[:, noisy_cols] != noisy[:, noisy_cols]).mean() > 0.99


def test_policy_observation_batches_and_normalizes(worlds):
    robot, task = worlds
    raw = {k: v[:24] if np.ndim(v) == 2 else v for k, v in raw_measurements(robot, task).items()}
    flat = policy_observation(**raw)
    batched = policy_observation(**{k: v.reshape(4, 6, -1) if np.ndim(v) == 2 else v for k, v in raw.items()})
    np.testing.assert_array_equal(batched.reshape(24, 54), flat)
    single = policy_observation(**{k: v[3] if np.ndim(v) == 2 else v for k, v in raw.items()}, dtype=np.float64)
    assert single.shape == (54,)
    np.testing.assert_allclose(single, flat[3], atol=1e-6)
    scaled = dict(raw, base_quat=1.01 * raw["base_quat"], object_quat=0.99 * raw["object_quat"])
    np.testing.assert_allclose(policy_observation(**scaled), flat, atol=1e-5)
    with pytest.raises(ValueError, match="arm_joint_position"):
        policy_observation(**dict(raw, arm_joint_position=raw["arm_joint_position"][:, :4]))
