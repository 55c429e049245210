"""User errors end ``dynpush`` with one line naming the file or field and exit status 2, never a traceback: missing or
corrupt run folders, checkpoints, policies and tick logs, a crafted checkpoint, invalid runtime configs, a policy given
to the other task's evaluation and the options that moved from ``dynpush eval`` to commands of their own."""

import json
import os
from pathlib import Path

import pytest
import torch

from dynpush.cli import main
from test_runtime_helpers import write_policy


class RunsCode:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def one_line_error(capsys, argv: list[str]) -> str:
    """The stderr of ``dynpush argv``, which must fail with status 2 and exactly one line."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("dynpush: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.fixture
def run(tmp_path):
    """A run folder with a valid config.json and no checkpoint yet."""
    from dynpush.policies.train import TrainConfig

    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "config.json").write_text(json.dumps(TrainConfig.preset_config("cpu").to_dict()))
    return folder


def test_export_of_missing_or_corrupt_run_files(run, tmp_path, capsys):
    assert f"{tmp_path / 'none' / 'config.json'} not found" in one_line_error(capsys, ["export", str(tmp_path / "none")])
    assert "checkpoint model_*.pt not found in" in one_line_error(capsys, ["export", str(run)])
    (run / "model_3.pt").write_bytes(b"PK\x03\x04" + bytes(40))  # a zip cut short
    assert f"cannot read checkpoint {run / 'model_3.pt'}" in one_line_error(capsys, ["export", str(run)])
    (run / "config.json").write_text('{"iterations": 3,')
    assert f"{run / 'config.json'} is not readable JSON" in one_line_error(capsys, ["export", str(run)])


def test_export_refuses_a_crafted_checkpoint_without_running_it(run, tmp_path, capsys):
    marker = tmp_path / "code_ran"
    torch.save({"actor_state_dict": RunsCode(marker), "iter": 1}, run / "model_1.pt")
    err = one_line_error(capsys, ["export", str(run)])
    assert f"checkpoint {run / 'model_1.pt'} refused: it would import {os.system.__module__}.system" in err
    assert not marker.exists() and not (run / "policy.onnx").exists()


@pytest.mark.parametrize("command", [["play"], ["eval"], ["eval-locomotion"], ["footprints"], ["scenario", "s.yaml"]])
def test_play_and_evaluations_of_a_missing_policy(tmp_path, capsys, command):
    argv = [command[0], str(tmp_path / "none.onnx"), *command[1:]]
    assert f"ONNX file {tmp_path / 'none.onnx'} not found" in one_line_error(capsys, argv)


def test_play_of_a_corrupt_or_foreign_policy(tmp_path, capsys):
    (tmp_path / "junk.onnx").write_bytes(b"\x08\x07 not a model")
    assert f"{tmp_path / 'junk.onnx'} is not an ONNX model" in one_line_error(capsys, ["play", str(tmp_path / "junk.onnx")])


def test_imitate_resume_without_its_data(tmp_path, capsys):
    err = one_line_error(capsys, ["imitate", "--runs", str(tmp_path), "--name", "bc", "--resume"])
    assert f"--resume: no {tmp_path / 'bc' / 'imitation_data.pt'}" in err


@pytest.mark.parametrize("section, message", [
    ({"mocap": {"base_offset": {"position": [float("nan"), 0.0, 0.0]}}}, r"mocap.base_offset.position[0] must be finite"),
    ({"robot": {"timeout_s": 1e9}}, "robot.timeout_s must be <= 1.0"),
    ({"robot": {"bind_address": "0.0.0.0"}}, "robot.bind_address must name one interface's address"),
    ({"push_policy": {"path": "none.onnx"}}, "push_policy: ONNX file"),
])
def test_run_with_an_invalid_config(tmp_path, capsys, section, message):
    config = {"push_policy": {"path": str(write_policy(tmp_path / "p.onnx"))}, "log": {"directory": str(tmp_path)}}
    (tmp_path / "runtime.yaml").write_text(json.dumps(config | section))
    assert message in one_line_error(capsys, ["run", str(tmp_path / "runtime.yaml")])


def test_run_with_an_unwritable_log_directory(tmp_path, capsys):
    (tmp_path / "taken").write_text("a file")
    config = {"push_policy": {"path": str(write_policy(tmp_path / "p.onnx"))}, "log": {"directory": str(tmp_path / "taken")},
              "mocap": {"port": 0}, "robot": {"port": 0}, "goals": {"command_port": 0}}
    (tmp_path / "runtime.yaml").write_text(json.dumps(config))
    err = one_line_error(capsys, ["run", str(tmp_path / "runtime.yaml")])
    assert f"log.directory {tmp_path / 'taken'}: cannot create a tick log there" in err


def test_curve_of_a_missing_or_corrupt_run(run, tmp_path, capsys):
    assert "progress.jsonl not found: not a training run folder" in one_line_error(capsys, ["curve", str(tmp_path / "none")])
    (run / "progress.jsonl").write_text('{"iteration": 0, "time": 1.0}\n{"iteration": 1, "ti')
    assert f"{run / 'progress.jsonl'}:2: not a JSON record" in one_line_error(capsys, ["curve", str(run)])
    (run / "progress.jsonl").write_text('{"time": 1.0}\n')
    assert f"{run / 'progress.jsonl'}:1: not a JSON record with an iteration" in one_line_error(capsys, ["curve", str(run)])
    (run / "config.json").write_text("[1, 2")
    assert f"{run / 'config.json'} is not readable JSON" in one_line_error(capsys, ["curve", str(run)])


def test_eval_of_a_corrupt_policy(tmp_path, capsys):
    policy = tmp_path / "policy.onnx"
    policy.write_bytes(b"\x08\x07garbage" * 8)
    assert f"{policy} is not an ONNX model" in one_line_error(capsys, ["eval", str(policy)])


SCENARIO = Path(__file__).parents[1] / "scenarios" / "quick.yaml"


@pytest.mark.parametrize("command", [["eval"], ["footprints"], ["scenario", str(SCENARIO)]])
def test_push_evaluations_refuse_a_locomotion_policy_naming_eval_locomotion(tmp_path, capsys, command):
    from dynpush.shipped import LOCOMOTION_DIR

    policy, out = LOCOMOTION_DIR / "locomotion.onnx", tmp_path / "out"
    err = one_line_error(capsys, [command[0], str(policy), *command[1:], "--out", str(out)])
    assert f"{policy} is a locomotion policy: evaluate it with dynpush eval-locomotion" in err
    assert not out.exists()


def test_eval_locomotion_refuses_a_push_policy_naming_eval(tmp_path, capsys):
    out = tmp_path / "out"
    err = one_line_error(capsys, ["eval-locomotion", str(write_policy(tmp_path / "p.onnx")), "--out", str(out)])
    assert f"{tmp_path / 'p.onnx'} is not a locomotion policy" in err and "evaluate a push policy with dynpush eval" in err
    assert not out.exists()


@pytest.mark.parametrize("options, command", [
    (["--footprints"], "dynpush footprints POLICY"),
    (["--scenario", "scenarios/quick.yaml"], "dynpush scenario POLICY FILE"),
    (["--footprint-episodes", "5"], "dynpush footprints POLICY --episodes-per-footprint N"),
    (["--seconds", "3"], "dynpush eval-locomotion LOCOMOTION_ONNX --seconds S"),
])
def test_eval_options_of_the_other_studies_name_their_command(tmp_path, capsys, options, command):
    policy = write_policy(tmp_path / "p.onnx")
    err = one_line_error(capsys, ["eval", str(policy), *options])
    assert f"{options[0]} is no longer an option of dynpush eval: run {command}" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.onnx"], "nothing written, not even the default eval/"
