"""The environment an exported push policy was trained in, rebuilt from the ``training_config`` of its ONNX
metadata for evaluation (``dynpush eval``, ``scenario``, ``footprints``, ``play``, sim-to-sim)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from dynpush.sim.config import ConfigError, LeggedModeConfig, PushEnvConfig

from .train import TrainConfig
from .overrides import apply_overrides

if TYPE_CHECKING:
    from .onnx_policy import OnnxPolicy


def env_config_for(policy: OnnxPolicy, num_envs: int, noise: bool | None = None, device: str = "cpu",
                   seed: int = 0, overrides: tuple[str, ...] | list[str] = (), legs_from_outside: bool = False) -> PushEnvConfig:
    """The environment a policy was trained in (from its metadata), for evaluation.

    ``noise`` switches the actor observation noise (None keeps the training value); ``overrides`` are
    ``env.field=value`` strings applied last. Episodes start synchronized (no randomized first length).
    Legged mode needs ``env.legged.locomotion_policy`` unless ``legs_from_outside`` (sim-to-sim: the runtime
    runs the locomotion policy and sends the leg targets).
    """
    cfg = TrainConfig.from_dict(policy.contract.training_config)
    if not cfg.env.legged.enabled:  # trained on the tracked base: legged mode, if asked for, has today's settings
        cfg.env.legged = LeggedModeConfig()
    cfg.env.num_envs = num_envs
    cfg.env.device = device
    cfg.env.seed = seed
    cfg.env.randomize_first_episode_length = False
    if noise is not None:
        cfg.env.noise.enabled = noise
    for item in overrides:
        if not item.startswith("env."):
            raise ConfigError(f"evaluation overrides address the environment (env.field=value), got {item!r}")
    apply_overrides(cfg, list(overrides))
    if cfg.env.legged.enabled and not cfg.env.legged.locomotion_policy and not legs_from_outside:
        raise ConfigError("env.legged.locomotion_policy must name a locomotion.onnx in legged mode (without one the legs"
                          " hold their default targets), e.g. the shipped dynpush/shipped/locomotion/locomotion.onnx")
    return cfg.env.validate()
