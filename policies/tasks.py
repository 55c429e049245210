"""The registry of dynpush's tasks (push and locomotion): what ``dynpush train``, ``export``, ``ship`` and the
evaluation commands need to know of a task, in one place (:data:`TASKS`).

Importing this module is cheap (standard library and ``dynpush.shipped`` only), so that ``import dynpush.cli`` stays
fast: each hook imports the task's heavy modules (torch, the simulator) when it is called. A run folder's task is
named by its ``config.json`` (:func:`task_of_config`: a locomotion run's says ``"task": "locomotion"``, a push run's
names none), which :func:`load_run_config` reads as that task's training config; an exported ONNX's task is told by
its metadata.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from dynpush.shipped import LOCOMOTION_DIR, SHIPPED_DIR

if TYPE_CHECKING:
    from .training import TaskTrainConfig


@dataclass(frozen=True)
class TaskSpec:
    """One task and the hooks the commands call for it."""

    name: str  # the value of ``dynpush train --task``
    config_class: Callable[[], type]  # its training config class (``preset_config``, ``from_dict``), imported on call
    run_prefix: str  # what the default run name puts before the preset (``dynpush train`` without --name)
    export: Callable[[Path, str | None, Path | None], Path]  # (run, checkpoint, out) -> the exported ONNX file
    exported: Callable[[Path], str]  # the line ``dynpush export`` prints for the exported file
    shipped_dir: Path  # where ``dynpush ship`` writes a run of this task without --to
    ship_files: Callable[..., dict]  # (run, checkpoint path, out folder, episodes=, worlds=, seed=) -> the ONNX and
    #                                  its evaluation written into the out folder; the training.json entries they add
    shipped_summary: Callable[[dict], str]  # the evaluation part of the line ``dynpush ship`` prints
    is_policy: Callable[[dict[str, str]], bool]  # whether an ONNX file's metadata_props are of a policy of this task
    refusal: Callable[[Path, str], str]  # (policy, command) -> the line a command of this task stops with on another
    #                                      task's ONNX
    paper_success: Callable[[dict], float | None]  # a run's config.json -> the paper's success rate [%] that
    #                                                ``dynpush curve`` marks (None: the paper has no such figure)


def _push_config() -> type:
    from .train import TrainConfig

    return TrainConfig


def _locomotion_config() -> type:
    from .locomotion_train import LocomotionTrainConfig

    return LocomotionTrainConfig


def _export_push(run_dir: Path, checkpoint: str | None, out: Path | None) -> Path:
    from .export import export_policy

    return export_policy(run_dir, checkpoint, out)


def _export_locomotion(run_dir: Path, checkpoint: str | None, out: Path | None) -> Path:
    from .locomotion_export import export_locomotion

    return export_locomotion(run_dir, checkpoint, out)


def _exported_push(path: Path) -> str:
    from .onnx_policy import OnnxPolicy

    contract = OnnxPolicy(path).contract
    return (f"{path}: obs [1, 54] -> actions [1, 11], dynpush {contract.dynpush_version},"
            f" training config sha256 {contract.training_config_sha256[:12]}")


def _ship_push(run_dir: Path, checkpoint_path: Path, out_dir: Path, episodes: int, worlds: int, seed: int) -> dict:
    """policy.onnx and eval.json / eval.png of ``episodes`` episodes (``dynpush eval``)."""
    from .evaluate import EvalConfig, evaluate
    from .onnx_policy import OnnxPolicy

    policy_path = _export_push(run_dir, checkpoint_path.name, out_dir / "policy.onnx")
    result = evaluate(policy_path, EvalConfig(episodes=episodes, seed=seed), out_dir)
    return {
        "training_config_sha256": OnnxPolicy(policy_path).contract.training_config_sha256,
        "evaluation": {"episodes": result["episodes"], "success_percent": result["success_rate"],
                       "toppled_percent": result["toppled_rate"],
                       "constraint_violation_percent": result["constraint_violation_percent"],
                       "paper": result["paper"]},
    }


def _ship_locomotion(run_dir: Path, checkpoint_path: Path, out_dir: Path, episodes: int, worlds: int, seed: int) -> dict:
    """locomotion.onnx and locomotion_eval.json / .png on ``worlds`` worlds (``dynpush eval-locomotion``)."""
    from .locomotion_eval import LocomotionEvalConfig, evaluate_locomotion

    policy_path = _export_locomotion(run_dir, checkpoint_path.name, out_dir / "locomotion.onnx")
    result = evaluate_locomotion(policy_path, LocomotionEvalConfig(num_envs=worlds, seed=seed), out_dir)
    return {"evaluation": {key: result[key] for key in ("worlds", "seconds_per_command", "fell_percent",
                                                        "tracking_rms", "units", "violated_percent_of_steps")}}


def _paper_success_push(training_config: dict) -> float:
    """The success rate [%] of the paper's Table I row of the ablation ``training_config`` describes."""
    from .tables import paper_table_i_row

    return paper_table_i_row(training_config)[1]


def _is_locomotion_policy(metadata: dict[str, str]) -> bool:
    from dynpush.runtime.locomotion_contract import LOCOMOTION_CONTRACT_KEY

    return LOCOMOTION_CONTRACT_KEY in metadata


def _not_locomotion(policy: Path, command: str) -> str:
    from dynpush.runtime.locomotion_contract import LOCOMOTION_CONTRACT_KEY

    return (f"{policy} is not a locomotion policy (no {LOCOMOTION_CONTRACT_KEY} metadata): evaluate a push policy with"
            f" dynpush eval (also dynpush scenario, dynpush footprints)")


PUSH = TaskSpec(
    name="push",
    config_class=_push_config,
    run_prefix="",
    export=_export_push,
    exported=_exported_push,
    shipped_dir=SHIPPED_DIR,
    ship_files=_ship_push,
    shipped_summary=lambda evaluation: (f"success {evaluation['success_percent']:.2f} %,"
                                        f" toppled {evaluation['toppled_percent']:.2f} %"
                                        f" over {evaluation['episodes']} episodes"),
    is_policy=lambda metadata: not _is_locomotion_policy(metadata),
    refusal=lambda policy, command: (f"{policy} is a locomotion policy: evaluate it with dynpush eval-locomotion"
                                     f" (dynpush {command} takes a push policy)"),
    paper_success=_paper_success_push,
)
LOCOMOTION = TaskSpec(
    name="locomotion",
    config_class=_locomotion_config,
    run_prefix="locomotion_",
    export=_export_locomotion,
    exported=lambda path: f"{path}: obs [1, 61] -> leg actions [1, 12] (runtime section: locomotion.mode onnx)",
    shipped_dir=LOCOMOTION_DIR,
    ship_files=_ship_locomotion,
    shipped_summary=lambda evaluation: ("tracking RMS " + ", ".join(f"{name} {value:.3f} {evaluation['units'][name]}"
                                                                    for name, value in evaluation["tracking_rms"].items())
                                        + f", fell {evaluation['fell_percent']:.1f} % of {evaluation['worlds']} worlds"),
    is_policy=_is_locomotion_policy,
    refusal=_not_locomotion,
    paper_success=lambda training_config: None,  # the paper trains its locomotion policy but reports no rate of it
)
TASKS: dict[str, TaskSpec] = {task.name: task for task in (PUSH, LOCOMOTION)}


def task_of_config(training_config: dict) -> TaskSpec:
    """The task of a run's ``config.json``: the one its ``"task"`` field names; the push task's config has no such
    field (it came before the locomotion task), so a config without one is of the push task."""
    from dynpush.sim.config import ConfigError

    name = training_config.get("task", PUSH.name)
    if name not in TASKS:
        raise ConfigError(f"task must be one of {sorted(TASKS)}, got {name!r}")
    return TASKS[name]


def task_of_run(run_dir: Path) -> TaskSpec:
    """The task of a run folder, named by its ``config.json`` (a missing or unreadable file: UserError)."""
    from .run_folder import read_run_config

    return task_of_config(read_run_config(run_dir))


def load_run_config(run_dir: Path) -> TaskTrainConfig:
    """The training config of a run folder (its ``config.json``), of its task's config class."""
    from .run_folder import read_run_config

    data = read_run_config(run_dir)
    return task_of_config(data).config_class().from_dict(data)


def task_of_onnx(path: Path) -> TaskSpec:
    """The task of an exported ONNX policy, told by its metadata (a missing or unreadable file: UserError)."""
    from dynpush.sim.onnx_session import load_onnx, read_metadata

    metadata = read_metadata(load_onnx(Path(path)))
    return next(task for task in TASKS.values() if task.is_policy(metadata))
