"""The tiny push training the training tests share: 8 worlds, 6 steps per iteration, small networks and a checkpoint
after every iteration, so that a run takes seconds; and what a test's two gloo processes need to meet, as torchrun
would set it up."""

import os
import socket

from dynpush.policies.train import TrainConfig, apply_overrides

TINY = ["env.num_envs=8", "num_steps_per_env=6", "save_interval=1", "network.actor_hidden=(32, 32)",
        "network.critic_hidden=(32, 32)"]


def tiny(iterations: int = 2, *overrides: str) -> TrainConfig:
    """The cpu preset at the tiny size, ``iterations`` long, with ``overrides`` on top."""
    return apply_overrides(TrainConfig.preset_config("cpu"), [*TINY, f"iterations={iterations}", *overrides])


def free_tcp_port() -> int:
    """A loopback TCP port that is free now (the process group's rendezvous)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def join_as_rank(rank: int, world_size: int, port: int) -> None:
    """Sets the environment that torchrun gives rank ``rank`` of ``world_size`` processes meeting at ``port``."""
    os.environ.update(RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE=str(world_size),
                      MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port))
