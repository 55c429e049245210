"""Fidelity cross-check: the same push with SolverXPBD (training) and MuJoCo-Warp (slow: ~2 min compile)."""

import numpy as np
import pytest
import torch

from dynpush.sim.config import PushEnvConfig, SimConfig
from dynpush.sim.episode import EpisodeSpec
from dynpush.sim.push_env import PushEnv



@pytest.mark.slow
@pytest.mark.parametrize("solver", ["xpbd", "mujoco"])
def test_both_solvers_push_the_box_forward(solver):
    env = PushEnv(PushEnvConfig(num_envs=2, sim=SimConfig(solver=solver)))
    env.set_episodes({0: EpisodeSpec(base=(-1.5, 0.0, 0.0)), 1: EpisodeSpec(base=(-2.4, 0.0, 0.0))})
    actions = torch.zeros(2, 11)
    actions[0, 0] = 0.3  # world 0 drives into the box at 0.3 m/s; world 1 stands still
    start = env.state_0.body_q.numpy()[env.scene.object_body].copy()
    contact = np.zeros(2, bool)
    for _ in range(200):
        obs, _, _, _ = env.step(actions)
        contact |= env.critic_obs_t[:, 54].numpy() > 0.5
    moved = env.state_0.body_q.numpy()[env.scene.object_body, :3] - start[:, :3]
    print(f"{solver}: box moved {moved[0]} m")
    assert contact.tolist() == [True, False]
    assert moved[0, 0] > 0.05 and abs(moved[0, 1]) < 0.02  # pushed forward, not aside
    assert np.abs(moved[1]).max() < 0.005  # the untouched box rests
