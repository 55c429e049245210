"""ONNX export of a trained push policy with its contract, and the loader that runs such a file.

``policy.onnx`` (DESIGN.md decision 4): input ``obs`` [1, 54] float32, the un-normalised actor
observation (layout ``dynpush.runtime.observation.POLICY_OBSERVATION_LAYOUT``); output ``actions``
[1, 11] float32, the deterministic mean of the policy *before* the environment's clip to
``+-action_clip``. The empirical observation normaliser is part of the graph. The graph is rsl_rl's own
export module (``MLPModel.as_onnx``: normaliser, MLP, deterministic output), traced with the same
``torch.onnx.export`` arguments as ``OnPolicyRunner.export_policy_to_onnx`` (opset 18). The file's
``metadata_props`` hold :class:`~dynpush.runtime.contract.PolicyContract`, filled from the run's
``config.json`` and the robot of the scene (``robot.usda``).

``training_config_sha256`` is the SHA-256 of the training config serialised as canonical JSON
(``json.dumps(config, sort_keys=True, separators=(",", ":"))``), so a reader can verify the embedded
``training_config`` with :func:`config_sha256`.
"""

from __future__ import annotations

import hashlib
import json
import logging
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import onnx
import onnxruntime

from dynpush.errors import CorruptFileError, MissingFileError
from dynpush.runtime.contract import INPUT_NAME, OUTPUT_NAME, ContractError, PolicyContract
from dynpush.runtime.observation import NUM_ACTIONS, NUM_ARM_JOINTS, POLICY_OBSERVATION_SIZE
from dynpush.sim.config import ConfigError
from dynpush.sim.onnx_session import (  # noqa: F401  (load_onnx, read_metadata: also read from here)
    batched_session,
    check_io,
    load_onnx,
    read_metadata,
    single_thread_options,
)

if TYPE_CHECKING:  # torch and rsl_rl are imported where needed: loading and running a policy needs neither
    from rsl_rl.models import MLPModel

    from dynpush.policies.locomotion_train import LocomotionTrainConfig
    from dynpush.policies.train import TrainConfig

OPSET = 18  # as rsl_rl's OnPolicyRunner.export_policy_to_onnx


def config_sha256(config: dict) -> str:
    """SHA-256 (hex) of ``config`` as canonical JSON (sorted keys, no spaces)."""
    return hashlib.sha256(json.dumps(config, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def read_json(path: Path) -> dict:
    """The JSON object in ``path``; a MissingFileError or CorruptFileError naming the file otherwise."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise MissingFileError(f"{path} not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CorruptFileError(f"{path} is not readable JSON: {error}") from error
    if not isinstance(data, dict):
        raise CorruptFileError(f"{path} holds a JSON {type(data).__name__}, not an object")
    return data


def load_run_config(run_dir: Path) -> TrainConfig | LocomotionTrainConfig:
    """The training config of a run folder (its ``config.json``): a locomotion run's says ``"task": "locomotion"``."""
    from dynpush.policies.locomotion_train import LocomotionTrainConfig
    from dynpush.policies.train import TrainConfig

    path = Path(run_dir) / "config.json"
    if not path.exists():
        raise MissingFileError(f"{path} not found: {run_dir} is not a dynpush run folder")
    data = read_json(path)
    return (LocomotionTrainConfig if data.get("task") == "locomotion" else TrainConfig).from_dict(data)


def resolve_checkpoint(run_dir: Path, checkpoint: str | None) -> Path:
    """``run_dir / checkpoint``, or the run's latest ``model_K.pt`` when ``checkpoint`` is None."""
    from dynpush.policies.run_folder import latest_checkpoint

    run_dir = Path(run_dir)
    path = latest_checkpoint(run_dir) if checkpoint is None else run_dir / checkpoint
    if path is None or not path.exists():
        raise MissingFileError(f"checkpoint {checkpoint or 'model_*.pt'} not found in {run_dir}")
    return path


def build_actor(cfg: TrainConfig | LocomotionTrainConfig, observation_size: int = POLICY_OBSERVATION_SIZE,
                num_actions: int = NUM_ACTIONS) -> MLPModel:
    """rsl_rl's actor ``MLPModel`` exactly as the training runner builds it from ``cfg.runner_cfg()`` (default
    sizes: the push policy's)."""
    import torch
    from rsl_rl.models import MLPModel
    from tensordict import TensorDict

    runner_cfg = cfg.runner_cfg()
    actor_cfg = {k: v for k, v in runner_cfg["actor"].items() if k != "class_name"}
    obs = TensorDict({"policy": torch.zeros(1, observation_size)}, batch_size=[1])
    return MLPModel(obs, runner_cfg["obs_groups"], "actor", num_actions, **actor_cfg)


def load_actor(checkpoint: Path, cfg: TrainConfig | LocomotionTrainConfig, observation_size: int = POLICY_OBSERVATION_SIZE,
               num_actions: int = NUM_ACTIONS) -> MLPModel:
    """The trained actor (normaliser included) of a checkpoint, in eval mode on the CPU."""
    from dynpush.policies.checkpoint_file import CheckpointError, read_checkpoint

    saved = read_checkpoint(checkpoint)
    if "actor_state_dict" not in saved:
        raise CheckpointError(f"checkpoint {checkpoint} has no 'actor_state_dict' (not an rsl_rl checkpoint)")
    actor = build_actor(cfg, observation_size, num_actions)
    try:
        actor.load_state_dict(saved["actor_state_dict"])
    except RuntimeError as error:
        raise CheckpointError(f"checkpoint {checkpoint} does not fit the network of the run's config.json: "
                              f"{' '.join(str(error).split())}") from error
    return actor.eval()


def load_onnx_actor(actor: MLPModel, path: Path) -> None:
    """Copies the actor of an exported ``policy.onnx`` (its MLP weights and observation normaliser) into ``actor``,
    the actor of a new run (``dynpush train --init-from policy.onnx``), so that training can go on from a shipped
    or exported policy when the run's checkpoints are gone.

    The graph is :func:`write_onnx`'s: ``(obs - mean) / (std + eps)``, then the MLP's ``Gemm`` layers in order.
    The normaliser's std is the divisor less ``actor``'s own ``eps``. The file keeps no sample count: the
    statistics count as the samples of the training run that wrote it (``iterations * num_envs *
    num_steps_per_env`` of the ``training_config`` in its metadata), so that the new run's rollouts refine them
    instead of replacing them. Raises a ConfigError naming network.actor_hidden when the network sizes differ.
    """
    import torch
    from onnx import numpy_helper

    from dynpush.policies.train import TrainConfig

    policy = OnnxPolicy(path)  # checks the contract and the input / output shapes
    model = load_onnx(path)
    weights = {tensor.name: numpy_helper.to_array(tensor) for tensor in model.graph.initializer}
    nodes = {node.op_type: node for node in reversed(model.graph.node)}  # the first node of each type
    mean, divisor = weights[nodes["Sub"].input[1]], weights[nodes["Div"].input[1]]
    gemms = [node for node in model.graph.node if node.op_type == "Gemm"]
    layers = [module for module in actor.mlp if isinstance(module, torch.nn.Linear)]
    if len(gemms) != len(layers):
        raise ConfigError(f"{path} has {len(gemms)} layers, the run's actor {len(layers)}: set network.actor_hidden to the"
                         f" hidden sizes of the file ({[int(weights[g.input[2]].shape[0]) for g in gemms[:-1]]})")
    trained = TrainConfig.from_dict(policy.contract.training_config)
    samples = trained.iterations * trained.env.num_envs * trained.num_steps_per_env
    with torch.no_grad():
        for index, (gemm, layer) in enumerate(zip(gemms, layers)):
            transposed = any(a.name == "transB" and a.i == 1 for a in gemm.attribute)
            weight = weights[gemm.input[1]] if transposed else weights[gemm.input[1]].T
            if tuple(weight.shape) != tuple(layer.weight.shape):
                raise ConfigError(f"{path}: layer {index} is {list(weight.shape)} (out, in), the run's actor has"
                                 f" {list(layer.weight.shape)}: set network.actor_hidden to the file's hidden sizes")
            layer.weight.copy_(torch.tensor(weight))
            layer.bias.copy_(torch.tensor(weights[gemm.input[2]]))
        normalizer = actor.obs_normalizer
        std = torch.tensor(divisor).reshape(normalizer._std.shape) - normalizer.eps
        normalizer._mean.copy_(torch.tensor(mean).reshape(normalizer._mean.shape))
        normalizer._std.copy_(std)
        normalizer._var.copy_(std.square())
        normalizer.count.fill_(samples)


def build_contract(cfg: TrainConfig) -> PolicyContract:
    """The contract of a policy trained with ``cfg`` (a TrainConfig), with the robot read from ``robot.usda``."""
    import dataclasses
    import math

    import dynpush
    from dynpush.assets_usd import ARM_JOINT_NAMES
    from dynpush.sim.scene import build_scene

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
    cfg = load_run_config(run_dir)
    checkpoint_path = resolve_checkpoint(run_dir, checkpoint)
    out = Path(out) if out is not None else run_dir / "policy.onnx"
    metadata = build_contract(cfg).to_metadata() | {"checkpoint": checkpoint_path.name}
    write_onnx(load_actor(checkpoint_path, cfg), out, metadata,
               f"dynpush push policy from {run_dir.name}/{checkpoint_path.name}; contract in metadata_props")
    return out


def write_onnx(actor: MLPModel, out: Path, metadata: dict[str, str], doc_string: str) -> None:
    """Writes ``actor`` (normaliser, MLP, deterministic mean) as one self-contained ONNX file with ``metadata``."""
    import torch

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


class OnnxPolicy:
    """A ``policy.onnx`` executed by onnxruntime, checked against the contract on load and on every call.

    With ``batched=True`` the batch dimension of ``obs`` and ``actions`` is relaxed to a symbolic one in
    an in-memory copy (same graph and weights), so that all worlds of an environment run in one call.
    """

    def __init__(self, path: Path, batched: bool = False):
        self.path = Path(path)
        model = load_onnx(self.path)
        try:
            self.contract = PolicyContract.from_metadata(read_metadata(model))
        except ContractError as error:
            raise ContractError(f"{self.path}: {error}") from None
        self.batch_size: int | None = None if batched else 1
        if batched:
            self.session = batched_session(model, INPUT_NAME, POLICY_OBSERVATION_SIZE, OUTPUT_NAME, NUM_ACTIONS, str(self.path))
        else:
            check_io(model, INPUT_NAME, POLICY_OBSERVATION_SIZE, OUTPUT_NAME, NUM_ACTIONS, str(self.path))
            self.session = onnxruntime.InferenceSession(model.SerializeToString(), single_thread_options(),
                                                        providers=["CPUExecutionProvider"])

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Actions [B, 11] (float32, unclipped mean) for observations ``obs`` [B, 54] (B = 1 unless batched)."""
        obs = np.asarray(obs)
        expected = f"[{self.batch_size or 'B'}, {POLICY_OBSERVATION_SIZE}]"
        if obs.ndim != 2 or obs.shape[1] != POLICY_OBSERVATION_SIZE or (self.batch_size and obs.shape[0] != self.batch_size):
            raise ValueError(f"policy input {INPUT_NAME!r} must have shape {expected} (float32), got {list(obs.shape)}")
        if obs.dtype != np.float32:
            raise ValueError(f"policy input {INPUT_NAME!r} must be float32, got {obs.dtype}")
        return self.session.run([OUTPUT_NAME], {INPUT_NAME: obs})[0]
