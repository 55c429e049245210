"""The tiny push training the training tests share: 8 worlds, 6 steps per iteration, small networks and a checkpoint
after every iteration, so that a run takes seconds."""

from dynpush.policies.train import TrainConfig, apply_overrides

TINY = ["env.num_envs=8", "num_steps_per_env=6", "save_interval=1", "network.actor_hidden=(32, 32)",
        "network.critic_hidden=(32, 32)"]


def tiny(iterations: int = 2, *overrides: str) -> TrainConfig:
    """The cpu preset at the tiny size, ``iterations`` long, with ``overrides`` on top."""
    return apply_overrides(TrainConfig.preset_config("cpu"), [*TINY, f"iterations={iterations}", *overrides])
