"""The scripted pusher (the imitation expert): its object geometry, and that it pushes an object to a goal."""

import math

import numpy as np
import pytest
import torch

from dynpush.policies.env_probe import yaw_of
from dynpush.policies.scripted import ScriptedPusher, ScriptedPusherConfig, wrap
from dynpush.sim.episode import EpisodeSpec
from warp_numpy_helpers import quat_mul


def box_ray_exit(dims_xy: np.ndarray, yaw: float, direction: np.ndarray) -> tuple[float, float]:
    """Independent reference: where a ray from a box's centre leaves it (slab method), and the half width of
    the face it leaves through."""
    local = np.array([[math.cos(yaw), math.sin(yaw)], [-math.sin(yaw), math.cos(yaw)]]) @ direction
    half = 0.5 * dims_xy
    with np.errstate(divide="ignore"):
        t = np.where(np.abs(local) > 1e-12, half / np.abs(local), np.inf)
    axis = int(np.argmin(t))
    return float(t[axis]), float(half[1 - axis])


def test_centre_of_mass_across_the_push(small_env):
    """Independent reference: the object-frame CoM turned by the object's yaw with a rotation matrix, projected."""
    env, rng = small_env, np.random.default_rng(5)
    pusher = ScriptedPusher(env)
    com = rng.uniform(-0.2, 0.2, (env.num_envs, 3)).astype(np.float32)
    env.task.object_com_o.assign(com)
    yaw, angle = rng.uniform(-math.pi, math.pi, env.num_envs), rng.uniform(-math.pi, math.pi, env.num_envs)
    side = np.column_stack([np.cos(angle), np.sin(angle)])
    expected = [np.array([[math.cos(y), -math.sin(y)], [math.sin(y), math.cos(y)]]) @ c[:2] @ d for y, c, d in zip(yaw, com, side)]
    np.testing.assert_allclose(pusher._com_across(side, yaw), expected, rtol=1e-5, atol=1e-7)


def test_half_extent_matches_ray_box_exit(small_env):
    env = small_env
    pusher = ScriptedPusher(env)
    rng = np.random.default_rng(4)
    for _ in range(5):
        dims = np.column_stack([rng.uniform(0.25, 0.75, (4, 2)), rng.uniform(0.4, 1.0, 4)]).astype(np.float32)
        shape = np.array([0, 0, 0, 1], dtype=np.int32)
        env.task.object_dims.assign(dims)
        env.task.object_shape.assign(shape)
        yaw = rng.uniform(-math.pi, math.pi, 4)
        angle = rng.uniform(-math.pi, math.pi, 4)
        direction = np.column_stack([np.cos(angle), np.sin(angle)])
        depth, half_width = pusher._half_extent(direction, yaw)
        for w in range(3):
            expected = box_ray_exit(dims[w, :2].astype(np.float64), yaw[w], direction[w])
            np.testing.assert_allclose((depth[w], half_width[w]), expected, rtol=1e-5)
        np.testing.assert_allclose((depth[3], half_width[3]), (0.5 * dims[3, 0], 0.5 * dims[3, 0]), rtol=1e-6)


def test_nominal_object_size_acts_on_observable_state_only(small_env):
    """With ``object_size`` set, the actions ignore the true size, shape and centre of mass (which the
    privileged pusher's do not), and the geometry is that of a cuboid of that edge."""
    env, rng = small_env, np.random.default_rng(6)
    env.reset(randomize_episode_step=False)
    nominal, privileged = ScriptedPusher(env, ScriptedPusherConfig(object_size=0.4)), ScriptedPusher(env)
    saved = [a.numpy().copy() for a in (env.task.object_dims, env.task.object_shape, env.task.object_com_o)]
    before_nominal, before_privileged = nominal(None), privileged(None)
    try:
        env.task.object_dims.assign(np.column_stack([rng.uniform(0.25, 0.75, (4, 2)), rng.uniform(0.4, 1.0, 4)]).astype(np.float32))
        env.task.object_shape.assign(np.array([1, 0, 1, 0], dtype=np.int32))
        env.task.object_com_o.assign(rng.uniform(-0.1, 0.1, (4, 3)).astype(np.float32))
        np.testing.assert_array_equal(nominal(None), before_nominal)
        assert not np.array_equal(privileged(None), before_privileged)
        yaw, angle = rng.uniform(-math.pi, math.pi, 4), rng.uniform(-math.pi, math.pi, 4)
        direction = np.column_stack([np.cos(angle), np.sin(angle)])
        depth, half_width = nominal._half_extent(direction, yaw)
        expected = [box_ray_exit(np.array([0.4, 0.4]), y, d) for y, d in zip(yaw, direction)]
        np.testing.assert_allclose(np.column_stack([depth, half_width]), expected, rtol=1e-6)
    finally:
        for array, values in zip((env.task.object_dims, env.task.object_shape, env.task.object_com_o), saved):
            array.assign(values)


@pytest.mark.parametrize("goal_yaw_deg", [0.0, 25.0])
def test_pushes_a_cuboid_to_its_goal(small_env, goal_yaw_deg):
    """From behind the object on the goal line: within 15 s the object reaches the goal, yaw included, upright."""
    env = small_env
    goal_yaw = math.radians(goal_yaw_deg)
    episode = EpisodeSpec(dims=(0.5, 0.4, 0.6), mass=4.0, friction=0.6, goal=(1.2, 0.3, goal_yaw),
                          base=(-1.8, -0.3, 0.2))
    env.set_episodes({w: episode for w in range(env.num_envs)})
    pusher = ScriptedPusher(env)
    goal = np.array(episode.goal)
    best_distance, best_yaw_error = np.inf, np.inf
    for _ in range(750):
        env.step(torch.from_numpy(pusher(None)))
        assert not (env.reset_t != 0).any(), "episode ended early (object toppled or robot fell)"
        obj = pusher.probe.object()[0]
        best_distance = min(best_distance, float(np.linalg.norm(obj[:2] - goal[:2])))
        if best_distance < 0.1:
            best_yaw_error = min(best_yaw_error, abs(float(wrap(goal[2] - yaw_of(obj[3:])))))
    assert best_distance < 0.1
    assert best_yaw_error < math.radians(10.0)


def test_backs_off_an_object_that_tilts(small_env, monkeypatch):
    """While pushing, an object tilted past ``tilt_limit`` makes the base back off along the push; a smaller
    tilt leaves the push command as it is."""
    env = small_env
    env.set_episodes({w: EpisodeSpec(dims=(0.5, 0.4, 0.6), mass=4.0, friction=0.6, goal=(1.2, 0.0, 0.0),
                                     base=(-1.8, 0.0, 0.0)) for w in range(env.num_envs)})
    pusher = ScriptedPusher(env)
    for _ in range(150):
        env.step(torch.from_numpy(pusher(None)))

    true_object = pusher.probe.object

    def base_vx(tilt: float) -> np.ndarray:
        """The commanded forward base velocity [m/s] with the object's pose tilted by ``tilt`` about world y."""
        pose = true_object().copy()
        q_tilt = np.array([0.0, math.sin(0.5 * tilt), 0.0, math.cos(0.5 * tilt)])
        pose[:, 3:] = quat_mul(q_tilt, pose[:, 3:])
        with monkeypatch.context() as patch:
            patch.setattr(pusher.probe, "object", lambda: pose)
            actions = pusher(None)
        return env.action_mapping.commands(actions)[0][:, 0]

    pushing_vx = base_vx(0.0)
    assert (pushing_vx > 0.2).all(), "the expert should be pushing forward after 3 s"
    np.testing.assert_allclose(base_vx(0.8 * pusher.cfg.tilt_limit), pushing_vx, rtol=1e-6)
    np.testing.assert_allclose(base_vx(1.5 * pusher.cfg.tilt_limit), -pusher.cfg.back_off_speed, atol=0.05)


def test_walks_around_the_object_within_command_limits(small_env):
    """From the goal's side of the object: the expert walks around it without touching it with anything but
    the end-effector, never commands the base or arm outside their limits nor moves the arm command faster than the
    action-rate constraint allows (it switches between its carry and push poses here), and then pushes it toward
    the goal."""
    env = small_env
    episode = EpisodeSpec(dims=(0.5, 0.4, 0.6), mass=4.0, friction=0.6, goal=(1.2, 0.3, 0.0), base=(1.4, -0.4, 3.0))
    env.set_episodes({w: episode for w in range(env.num_envs)})
    pusher = ScriptedPusher(env, ScriptedPusherConfig(arm_rate_share=0.8))
    limit_groups = [i for i, (name, _) in enumerate(env.constraint_groups) if name in ("base_command", "arm_command",
                                                                                           "arm_action_rate")]
    goal = np.array(episode.goal[:2])
    start_distance = float(np.linalg.norm(pusher.probe.object()[0, :2] - goal))
    for _ in range(500):
        env.step(torch.from_numpy(pusher(None)))
        assert not (env.reset_t != 0).any(), "episode ended early (object toppled or robot fell)"
        assert not env.violated_groups_t[:, limit_groups].any(), "a base or arm command outside its limits or rate"
        assert not env.task.contacts.numpy()[:, :-1].any(), "a robot part other than the end-effector touched the object"
    distance = float(np.linalg.norm(pusher.probe.object()[0, :2] - goal))
    assert distance < start_distance - 0.3


@pytest.mark.parametrize("override, message", [
    ("push_speed=1.5", r"scripted.push_speed must be in \(0, 1\] m/s"),
    ("max_offset=0.0", r"scripted.max_offset must be in \(0, 1\]"),
    ("yaw_gain=-0.5", r"scripted.yaw_gain must be a finite number >= 0"),
    ("object_size=3.0", r"scripted.object_size must be None or in \(0, 2\] m"),
    ("push_arm_action=(0.0, 0.2)", r"scripted.push_arm_action must be 5 finite arm actions"),
    ("arm_rate_share=1.5", r"scripted.arm_rate_share must be None or in \(0, 1\] \(a share of the arm joints' velocity limits\)"),
])
def test_overrides_out_of_range_name_the_field(small_env, override, message):
    """`benchmarks/scripted_push.py --set` applies overrides with the training config's parser; the pusher checks them."""
    from dynpush.policies.train import apply_overrides
    from dynpush.sim.config import ConfigError

    cfg = apply_overrides(ScriptedPusherConfig(), [override])
    with pytest.raises(ConfigError, match=message):
        ScriptedPusher(small_env, cfg)
    ScriptedPusher(small_env, apply_overrides(ScriptedPusherConfig(), ["push_speed=0.8", "object_size=0.4"]))


def test_benchmark_reports_how_the_episodes_end(load_benchmark):
    """`benchmarks/scripted_push.py` sorts every episode as `dynpush eval` does (goal_error): its success and toppled
    shares are the run's, and each episode falls in one bin of the rotation and of the distance its goal asks."""
    result = load_benchmark("scripted_push").run(num_envs=3, goal_yaw_difficulty=1.0, seed=2, png=None)
    outcome = result["goal_error"]["outcome_percent"]
    assert outcome["success"] == pytest.approx(100.0 * result["success_rate"])
    assert outcome["toppled"] == pytest.approx(100.0 * result["toppled_rate"])
    assert sum(outcome.values()) <= 100.0 + 1e-9
    for bins in ("success_by_goal_rotation_deg", "success_by_goal_distance_m"):
        assert sum(row["episodes"] for row in result["goal_error"][bins]) == 3
