"""The task registry (policies/tasks.py) reads a run folder's task and config class from its config.json."""

from __future__ import annotations

import json

import pytest

from dynpush.errors import MissingFileError
from dynpush.policies.locomotion_train import LocomotionTrainConfig
from dynpush.policies.tasks import LOCOMOTION, PUSH, load_run_config, task_of_config, task_of_run
from dynpush.policies.train import TrainConfig
from dynpush.sim.config import ConfigError


def run_folder(tmp_path, config: dict):
    """A run folder holding only ``config.json`` (no training)."""
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "config.json").write_text(json.dumps(config))
    return folder


@pytest.mark.parametrize(("config", "task", "config_class"), [
    (TrainConfig.preset_config("cpu").to_dict(), PUSH, TrainConfig),  # a push run's config names no task
    (LocomotionTrainConfig.preset_config("cpu").to_dict(), LOCOMOTION, LocomotionTrainConfig),
    ({"task": "locomotion"}, LOCOMOTION, LocomotionTrainConfig),
    ({}, PUSH, TrainConfig),
])
def test_the_registry_reads_a_run_as_its_tasks_config_class(tmp_path, config, task, config_class):
    run = run_folder(tmp_path, config)
    assert task_of_run(run) is task
    assert type(load_run_config(run)) is config_class and task.config_class() is config_class


def test_a_locomotion_run_says_so_in_its_config():
    assert LocomotionTrainConfig.preset_config("cpu").to_dict()["task"] == LOCOMOTION.name
    assert "task" not in TrainConfig.preset_config("cpu").to_dict()


def test_an_unknown_task_or_a_missing_config_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="task must be one of"):
        task_of_config({"task": "swim"})
    with pytest.raises(MissingFileError, match="not a dynpush run folder"):
        load_run_config(tmp_path)


def test_the_curve_marks_the_papers_success_of_push_runs_only():
    push = TrainConfig.preset_config("cpu").to_dict()
    assert PUSH.paper_success(push) == 91.35  # paper Table I, "Ours (with all the above)"
    assert LOCOMOTION.paper_success(LocomotionTrainConfig.preset_config("cpu").to_dict()) is None
