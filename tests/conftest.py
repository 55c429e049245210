import pytest
import torch

torch.set_num_threads(1)


@pytest.fixture(scope="session")
def small_env():
    """One 4-world push environment shared by the tests that drive it (Warp compiles once)."""
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    return PushEnv(PushEnvConfig(num_envs=4, seed=1))


@pytest.fixture(scope="session")
def load_benchmark():
    """Imports a script of ``benchmarks/`` (a folder of scripts, not a package) by its name without ``.py``."""
    import importlib.util
    from pathlib import Path

    def load(name: str):
        path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load
