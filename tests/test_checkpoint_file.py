"""Checkpoints are read with ``weights_only=True``: what dynpush saves (a tiny training run's checkpoints, DAgger's data
set) loads and resumes; a crafted ``.pt`` whose pickle would run code is refused with one line, and runs nothing."""

import os
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

from dynpush.policies.checkpoint_file import CheckpointError, read_checkpoint
from dynpush.policies.train import train

from train_helpers import tiny

PACKAGE_DIRS = ("dynpush", "policies", "sim", "runtime", "kernels", "assets_usd")


class RunsCode:
    """Pickles as a call of ``os.system``: loading it with ``weights_only=False`` would create ``marker``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def test_training_checkpoints_load_with_weights_only_and_resume(tmp_path):
    run = tmp_path / "run"
    train(tiny(1), run)
    saved = read_checkpoint(run / "model_0.pt")
    state = saved["infos"]["env_state"]
    assert state and all(isinstance(v, np.ndarray) for v in state.values()), "the environment state's numpy arrays"
    assert isinstance(saved["infos"]["torch_rng"], torch.Tensor) and "optimizer_state_dict" in saved
    resumed = train(tiny(2), run, resume=True)  # the runner reads its checkpoint the same way
    assert resumed.current_learning_iteration == 1


def test_dagger_data_set_loads_with_weights_only(tmp_path):
    """The structure ``dynpush imitate`` saves in ``imitation_data.pt`` (Dagger.state_dict)."""
    actor = torch.nn.Linear(4, 2)
    optimizer = torch.optim.Adam(actor.parameters())
    actor(torch.ones(1, 4)).sum().backward()
    optimizer.step()
    torch.save({"dagger": {"observations": torch.ones(3, 4), "labels": torch.zeros(3, 2),
                           "optimizer": optimizer.state_dict(), "generator": torch.Generator().get_state()},
                "rounds_done": 2}, tmp_path / "imitation_data.pt")
    loaded = read_checkpoint(tmp_path / "imitation_data.pt")
    assert loaded["rounds_done"] == 2 and loaded["dagger"]["optimizer"]["state"][0]["step"] == 1


@pytest.mark.parametrize("writer", ["torch.save", "pickle.dump"])
def test_a_crafted_checkpoint_is_refused_without_running_code(tmp_path, writer):
    marker = tmp_path / "code_ran"
    path = tmp_path / "model_9.pt"
    payload = {"actor_state_dict": {}, "iter": 9, "infos": RunsCode(marker)}
    if writer == "torch.save":
        torch.save(payload, path)
    else:
        path.write_bytes(pickle.dumps(payload, protocol=2))  # torch warns about newer protocols
    with pytest.raises(CheckpointError, match=f"checkpoint {path} refused") as refused:
        read_checkpoint(path)
    assert "\n" not in str(refused.value)
    if writer == "torch.save":
        assert f"it would import {os.system.__module__}.system" in str(refused.value)
    assert not marker.exists(), "nothing in the file ran"


def test_truncated_and_missing_checkpoints_are_named(tmp_path):
    (tmp_path / "short.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match=f"checkpoint {tmp_path / 'short.pt'} refused: it is no pickle"):
        read_checkpoint(tmp_path / "short.pt")
    (tmp_path / "cut.pt").write_bytes((tmp_path / "short.pt").read_bytes()[:0] + b"PK\x03\x04" + bytes(40))
    with pytest.raises(CheckpointError, match=f"cannot read checkpoint {tmp_path / 'cut.pt'}: RuntimeError"):
        read_checkpoint(tmp_path / "cut.pt")
    with pytest.raises(CheckpointError, match="does not exist"):
        read_checkpoint(tmp_path / "none.pt")


def test_no_module_loads_a_pickle_that_may_run_code():
    root = Path(__file__).parents[1]
    offenders = [str(path.relative_to(root)) for folder in PACKAGE_DIRS for path in (root / folder).rglob("*.py")
                 if "weights_only=False" in path.read_text()]
    assert offenders == [], f"torch.load(weights_only=False) runs code from the file: {offenders}"
