"""Physical sanity of the chosen solver and substeps (issue: resting, sliding, toppling)."""

import math

import numpy as np
import pytest
import torch

from dynpush.sim.episode import EpisodeSpec

G = 9.81


def object_poses(env):
    return env.state_0.body_q.numpy()[env.scene.object_body]


def tilt_deg(quat_xyzw):
    x, y, z, w = quat_xyzw
    return math.degrees(math.acos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0)))


def run(env, actions, steps):
    """Steps with constant actions; returns per-world 'toppled' flags seen at any episode end."""
    toppled = np.zeros(env.num_envs, dtype=bool)
    for _ in range(steps):
        env.step(actions)
        toppled |= env.episode_toppled_t.numpy().astype(bool)
    return toppled


def test_resting_objects_stay_put_for_20_s(small_env):
    env = small_env
    far = (-2.4, 0.0, 0.0)
    env.set_episodes({
        0: EpisodeSpec(shape="cuboid", dims=(0.5, 0.4, 0.8), mass=5.0, base=far),
        1: EpisodeSpec(shape="cylinder", dims=(0.4, 0.4, 1.0), mass=2.0, com_offset=(0.0, 0.0, -0.3), base=far),
        2: EpisodeSpec(shape="cuboid", dims=(0.25, 0.75, 1.0), mass=10.0, com_offset=(0.05, -0.1, -0.2), base=far),
        3: EpisodeSpec(shape="cylinder", dims=(0.75, 0.75, 0.4), mass=1.0, friction=0.4, base=far),
    })
    start = object_poses(env)
    run(env, torch.zeros(env.num_envs, 11), steps=995)  # 19.9 s, just inside one 20 s episode
    end = object_poses(env)
    drift = np.linalg.norm(end[:, :2] - start[:, :2], axis=1)
    assert all(tilt_deg(q) < 1.0 for q in end[:, 3:])
    centred = [0, 1, 3]  # CoM on the vertical axis through the centroid
    assert (drift[centred] < 0.01).all(), f"resting objects drifted {drift[centred]} m in 20 s"
    # Known Newton 1.8 XPBD artefact (docs/simulator.md, "Known simulator behaviour"): a horizontal CoM offset makes a resting body creep by
    # about a millimetre per second (also in a bare Newton scene). It must stay inside the 10 cm
    # success tolerance over a whole episode.
    assert drift[2] < 0.10, f"off-centre CoM creep {drift[2]:.3f} m in 20 s"


@pytest.mark.parametrize("mu", [0.4, 1.0])
def test_sliding_object_stops_after_v2_over_2_mu_g(small_env, mu):
    env = small_env
    far = (-2.4, 0.0, 0.0)
    env.set_episodes({w: EpisodeSpec(shape=shape, dims=(0.5, 0.5, 0.4), mass=5.0, friction=mu, base=far)
                      for w, shape in enumerate(("cuboid", "cylinder", "cuboid", "cylinder"))})
    v0 = 1.0
    qd = env.state_0.body_qd.numpy()
    qd[env.scene.object_body, 1] = v0  # +y, away from the robot
    env.state_0.body_qd.assign(qd)
    start = object_poses(env)
    run(env, torch.zeros(env.num_envs, 11), steps=100)
    slid = object_poses(env)[:, 1] - start[:, 1]
    expected = v0**2 / (2.0 * mu * G)
    np.testing.assert_allclose(slid, expected, rtol=0.2, err_msg=f"mu={mu}: slid {slid}, Coulomb says {expected:.3f} m")


def test_tall_object_topples_when_pushed_high_not_low(small_env):
    env = small_env
    arm_default = env.scene.robot.arm_default[:5]
    high = np.radians([0.0, 60.0, 30.0, 0.0, 0.0])  # forearm horizontal, EE ~0.9 m above ground
    tall = dict(shape="cuboid", dims=(0.5, 0.5, 1.0), mass=5.0, friction=0.4, base=(-1.5, 0.0, 0.0))
    env.set_episodes({0: EpisodeSpec(**tall), 1: EpisodeSpec(**tall, arm_q=tuple(high)),
                      2: EpisodeSpec(**tall), 3: EpisodeSpec(**tall, arm_q=tuple(high))})
    actions = torch.zeros(env.num_envs, 11)
    actions[:, 0] = 0.3 / env.cfg.actions.base_scale[0]  # drive forward at 0.3 m/s
    actions[1::2, 6:] = torch.tensor((high - arm_default) / env.cfg.actions.arm_scale, dtype=torch.float32)
    start = object_poses(env)
    toppled = run(env, actions, steps=300)
    low_push = object_poses(env)[0::2, 0] - start[0::2, 0]
    assert not toppled[0::2].any(), "pushed at 0.35 m, a 1 m tall box on mu = 0.4 must slide, not topple"
    assert (low_push > 0.5).all(), f"the low push moved the box only {low_push} m"
    assert toppled[1::2].all(), "pushed at 0.9 m (above h = w / 2 mu = 0.625 m) the box must topple"
