import pytest
import torch

torch.set_num_threads(1)


@pytest.fixture(scope="session")
def small_env():
    """One 4-world push environment shared by the tests that drive it (Warp compiles once)."""
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    return PushEnv(PushEnvConfig(num_envs=4, seed=1))
