"""The actor network (rsl_rl ``MLPModel``: empirical observation normaliser, MLP, Gaussian head) outside the training
runner: built as the runner builds it, loaded from a checkpoint, or filled from an exported ``policy.onnx``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import torch
from onnx import numpy_helper
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from dynpush.runtime.observation import NUM_ACTIONS, POLICY_OBSERVATION_SIZE
from dynpush.sim.config import ConfigError
from dynpush.sim.onnx_session import load_onnx

from .checkpoint_file import CheckpointError, read_checkpoint
from .onnx_policy import OnnxPolicy

if TYPE_CHECKING:
    from .locomotion_train import LocomotionTrainConfig
    from .train import TrainConfig


def build_actor(cfg: TrainConfig | LocomotionTrainConfig, observation_size: int = POLICY_OBSERVATION_SIZE,
                num_actions: int = NUM_ACTIONS) -> MLPModel:
    """rsl_rl's actor ``MLPModel`` exactly as the training runner builds it from ``cfg.runner_cfg()`` (default
    sizes: the push policy's)."""
    runner_cfg = cfg.runner_cfg()
    actor_cfg = {k: v for k, v in runner_cfg["actor"].items() if k != "class_name"}
    obs = TensorDict({"policy": torch.zeros(1, observation_size)}, batch_size=[1])
    return MLPModel(obs, runner_cfg["obs_groups"], "actor", num_actions, **actor_cfg)


def load_actor(checkpoint: Path, cfg: TrainConfig | LocomotionTrainConfig, observation_size: int = POLICY_OBSERVATION_SIZE,
               num_actions: int = NUM_ACTIONS) -> MLPModel:
    """The trained actor (normaliser included) of a checkpoint, in eval mode on the CPU."""
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

    The graph is :func:`~dynpush.policies.export.write_onnx`'s: ``(obs - mean) / (std + eps)``, then the MLP's
    ``Gemm`` layers in order. The normaliser's std is the divisor less ``actor``'s own ``eps``. The file keeps no
    sample count: the statistics count as the samples of the training run that wrote it (``iterations * num_envs *
    num_steps_per_env`` of the ``training_config`` in its metadata), so that the new run's rollouts refine them
    instead of replacing them. Raises a ConfigError naming network.actor_hidden when the network sizes differ.
    """
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
    trained = policy.contract.training_config  # the config.json of the run that wrote the file
    try:
        samples = int(trained["iterations"]) * int(trained["env"]["num_envs"]) * int(trained["num_steps_per_env"])
    except (KeyError, TypeError, ValueError) as error:
        raise ConfigError(f"{path}: its training_config lacks the iterations, env.num_envs or num_steps_per_env that"
                          f" count its normaliser's samples ({error!r})") from None
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
