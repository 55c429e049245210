"""The processes of a training launch: ``--procs N`` re-runs ``dynpush train`` under torchrun, a rank's place in it
(:class:`ProcessGroup`), and the signals that stop it (the launcher forwards them; a rank saves its last iteration
boundary)."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import subprocess
from dataclasses import dataclass
from typing import TYPE_CHECKING

from dynpush.sim.config import ConfigError

if TYPE_CHECKING:
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.locomotion_config import LocomotionEnvConfig


@dataclass
class ProcessGroup:
    """This process's place in a torchrun launch (``RANK``, ``WORLD_SIZE``); one process otherwise."""

    rank: int = 0
    world_size: int = 1

    @staticmethod
    def from_environment() -> ProcessGroup:
        return ProcessGroup(rank=int(os.getenv("RANK", "0")), world_size=int(os.getenv("WORLD_SIZE", "1")))

    def shard(self, env: PushEnvConfig | LocomotionEnvConfig) -> PushEnvConfig | LocomotionEnvConfig:
        """This rank's environment: ``env.num_envs`` worlds in all, split evenly; a seed per rank."""
        if env.num_envs % self.world_size:
            raise ConfigError(f"env.num_envs ({env.num_envs}) must be divisible by the number of processes"
                              f" ({self.world_size})")
        return dataclasses.replace(env, num_envs=env.num_envs // self.world_size, seed=env.seed + self.rank)


@contextlib.contextmanager
def sigterm_as_keyboard_interrupt():
    """Within the block SIGTERM raises KeyboardInterrupt, so a long job stopped by ``kill`` (or by a shell that
    ignores SIGINT in background jobs) saves its progress as after Ctrl-C."""

    def on_sigterm(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


FORWARDED_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)  # what stops a launcher: kill, Ctrl-C, hang-up


def launch_processes(procs: int, argv: list[str]) -> int:
    """Re-runs ``dynpush train`` under torchrun with ``procs`` processes on this machine; returns torchrun's exit
    status.

    torchrun runs in a session of its own, so that a stop reaches it through this process only: SIGTERM, SIGINT or
    SIGHUP to this process (unless it ignores that signal, as under ``nohup``) is sent on to torchrun as SIGTERM,
    which torchrun sends to the ranks, which save their last iteration boundary; this process waits for torchrun and
    returns its (non-zero) status. Left to their defaults, a signal ended this process alone and torchrun and the
    ranks trained on.
    """
    import sys

    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc_per_node={procs}",
               "-m", "dynpush", "train", *argv]
    torchrun = subprocess.Popen(command, start_new_session=True)
    with forward_signals_as_sigterm(torchrun):
        return torchrun.wait()


@contextlib.contextmanager
def forward_signals_as_sigterm(process: subprocess.Popen):
    """Within the block, each of ``FORWARDED_SIGNALS`` that this process does not ignore is sent to ``process`` as
    SIGTERM instead of acting here."""

    def forward(signum, frame):
        process.send_signal(signal.SIGTERM)

    # A handler that is not Python's (None) is left alone, as are ignored signals.
    handled = [sig for sig in FORWARDED_SIGNALS if signal.getsignal(sig) not in (signal.SIG_IGN, None)]
    previous = {sig: signal.signal(sig, forward) for sig in handled}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
