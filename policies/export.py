"""ONNX export of a trained push policy with its contract.

``policy.onnx`` (the deployment contract, docs/runtime.md): input ``obs`` [1, 54] float32, the un-normalised actor
observation (layout ``dynpush.runtime.observation.POLICY_OBSERVATION_LAYOUT``); output ``actions``
[1, 11] float32, the deterministic mean of the policy *before* the environment's clip to
``+-action_clip``. The empirical observation normaliser is part of the graph. The graph is rsl_rl's own
export module (``MLPModel.as_onnx``: normaliser, MLP, deterministic output), traced with the same
``torch.onnx.export`` arguments as ``OnPolicyRunner.export_policy_to_onnx`` (opset 18). The file's
``metadata_props`` hold :class:`~dynpush.runtime.contract.PolicyContract`, filled from the run's
``config.json`` and the robot of the scene (``robot.usda``). :class:`~dynpush.policies.onnx_policy.OnnxPolicy`
runs such a file.

``training_config_sha256`` is the SHA-256 of the training config serialised as canonical JSON
(``json.dumps(config, sort_keys=True, separators=(",", ":"))``), so a reader can verify the embedded
``training_config`` with :func:`config_sha256`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import onnx
import torch

import dynpush
from dynpush.assets_usd import ARM_JOINT_NAMES
from dynpush.errors import MissingFileError
from dynpush.runtime.contract import PolicyContract
from dynpush.runtime.observation import NUM_ARM_JOINTS
from dynpush.sim.scene import build_scene

from .actor import load_actor
from .run_folder import latest_checkpoint, read_run_config
from .train import TrainConfig

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel

OPSET = 18  # as rsl_rl's OnPolicyRunner.export_policy_to_onnx


def config_sha256(config: dict) -> str:
    """SHA-256 (hex) of ``config`` as canonical JSON (sorted keys, no spaces)."""
    return hashlib.sha256(json.dumps(config, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def resolve_checkpoint(run_dir: Path, checkpoint: str | None) -> Path:
    """``run_dir / checkpoint``, or the run's latest ``model_K.pt`` when ``checkpoint`` is None."""
    run_dir = Path(run_dir)
    path = latest_checkpoint(run_dir) if checkpoint is None else run_dir / checkpoint
    if path is None or not path.exists():
        raise MissingFileError(f"checkpoint {checkpoint or 'model_*.pt'} not found in {run_dir}")
    return path


def build_contract(cfg: TrainConfig) -> PolicyContract:
    """The contract of a policy trained with ``cfg`` (a TrainConfig), with the robot read from ``robot.usda``."""
    env = cfg.env
    robot = build_scene(1, "cpu").robot
    arm = slice(0, NUM_ARM_JOINTS)
    noise = {f.name: getattr(env.noise, f.name) for f in dataclasses.fields(env.noise) if f.name != "enabled"}
    training_config = cfg.to_dict()
    training_config = json.loads(json.dumps(training_config))  # tuples -> lists, exactly as the metadata stores it
    contract = PolicyContract(
        observation_noise=noise,
        base_command_default=list(env.actions.base_default),
        base_command_scale=list(env.actions.base_scale),
        base_command_lower=list(env.constraints.base_command_lower),
        base_command_upper=list(env.constraints.base_command_upper),
        arm_joint_names=list(ARM_JOINT_NAMES[arm]),
        arm_default_joint_positions=robot.arm_default[arm].tolist(),
        arm_action_scale=env.actions.arm_scale,
        arm_joint_lower=robot.arm_lower[arm].tolist(),
        arm_joint_upper=robot.arm_upper[arm].tolist(),
        arm_joint_velocity_limit=robot.arm_velocity_limit[arm].tolist(),
        frozen_joint_name=ARM_JOINT_NAMES[NUM_ARM_JOINTS],
        frozen_joint_position=float(robot.arm_default[NUM_ARM_JOINTS]),
        action_clip=env.actions.clip,
        control_period_s=env.control_dt,
        success_distance_m=env.rewards.success_distance,
        success_angle_rad=math.radians(env.rewards.success_angle_deg),
        dynpush_version=dynpush.__version__,
        training_config=training_config,
        training_config_sha256=config_sha256(training_config),
    )
    contract.validate()
    return contract


def export_policy(run_dir: Path, checkpoint: str | None = None, out: Path | None = None) -> Path:
    """Exports a run's checkpoint (default: the latest) to ONNX with its contract; returns the file.

    ``out`` defaults to ``run_dir / "policy.onnx"``.
    """
    run_dir = Path(run_dir)
    # The push task's config class directly, not the task registry's load_run_config: the registry's export hooks
    # import this module. A locomotion run's config is a ConfigError here (its "task" field is no TrainConfig field).
    cfg = TrainConfig.from_dict(read_run_config(run_dir))
    checkpoint_path = resolve_checkpoint(run_dir, checkpoint)
    out = Path(out) if out is not None else run_dir / "policy.onnx"
    metadata = build_contract(cfg).to_metadata() | {"checkpoint": checkpoint_path.name}
    write_onnx(load_actor(checkpoint_path, cfg), out, metadata,
               f"dynpush push policy from {run_dir.name}/{checkpoint_path.name}; contract in metadata_props")
    return out


def write_onnx(actor: MLPModel, out: Path, metadata: dict[str, str], doc_string: str) -> None:
    """Writes ``actor`` (normaliser, MLP, deterministic mean) as one self-contained ONNX file with ``metadata``."""
    module = actor.as_onnx(verbose=False).to("cpu").eval()
    out.parent.mkdir(parents=True, exist_ok=True)
    # torch's exporter warns about its own internals (deprecated pytree API, optional torchvision ops).
    registration_log = logging.getLogger("torch.onnx._internal.exporter._registration")
    level = registration_log.level
    registration_log.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            torch.onnx.export(module, module.get_dummy_inputs(), str(out), export_params=True, opset_version=OPSET,
                              verbose=False, input_names=module.input_names, output_names=module.output_names)
    finally:
        registration_log.setLevel(level)
    model = onnx.load(str(out))
    onnx.helper.set_model_props(model, metadata)
    model.doc_string = doc_string
    onnx.checker.check_model(model)
    onnx.save(model, str(out))  # one self-contained file: the weights are inlined again
    out.with_name(out.name + ".data").unlink(missing_ok=True)  # the exporter's external weights, now stale
