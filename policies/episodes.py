"""The evaluation episode loop: every world's first episode under a policy, watched step by step by observers.

All worlds start together (``PushEnv.reset()`` without randomized episode steps) and are stepped for exactly one
episode length; a world that ends early is auto-reset by the environment and its later steps are masked, so every
world contributes exactly its first episode. Success is the success flag at the episode's last step (as in
training logs); the first step with the success flag is kept too.

A policy maps actor observations to actions as ``dynpush eval`` runs an exported one: an ONNX file run by
onnxruntime (:class:`~dynpush.policies.onnx_policy.OnnxPolicy`) or the deterministic mean of an in-memory actor
(:class:`ActorPolicy`), both on numpy arrays.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import torch
from tqdm import tqdm

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel

    from dynpush.sim.push_env import PushEnv

Policy = Callable[[np.ndarray], np.ndarray]
"""Actions [B, 11] (float32) for actor observations [B, 54] (float32): an ``OnnxPolicy`` or an :class:`ActorPolicy`."""


class ActorPolicy:
    """The deterministic mean of an in-memory actor (rsl_rl ``MLPModel``), so that training evaluates its current actor
    as ``dynpush eval`` evaluates an exported one: a copy of its observation normaliser and MLP (rsl_rl's export
    module, the graph ``dynpush export`` writes to ONNX), on the CPU, which later updates of the actor leave alone."""

    def __init__(self, actor: MLPModel):
        self.module = actor.as_jit().to("cpu").eval()

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return self.module(torch.from_numpy(obs)).numpy()


class StepObserver(Protocol):
    """Receives every control step of a first-episode rollout."""

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        """Called after ``env.step`` number ``step`` (0-based).

        ``in_episode``: worlds whose first episode contained this step; values the step computes before
        its auto-reset (``constraints_t``, ``success_t``) are theirs. ``continuing``: the subset whose first
        episode goes on, whose post-step state and observations (``critic_obs_t``,
        :class:`~dynpush.policies.env_probe.EnvProbe`) are still that episode's.
        """


@dataclass
class FirstEpisodes:
    """Outcome of every world's first episode (arrays over worlds)."""

    length: np.ndarray  # control steps in the episode
    success: np.ndarray  # bool: success flag at the last step
    toppled: np.ndarray  # bool: ended by the object toppling
    fallen: np.ndarray  # bool: ended by the robot falling (base tilt or height, TerminationConfig)
    first_success_step: np.ndarray  # 1-based step of the first success flag, 0 if never
    shape: np.ndarray  # 0 cuboid, 1 cylinder

    @property
    def fell(self) -> np.ndarray:
        """bool: ended by the robot falling, neither a success nor with the object toppled."""
        return self.fallen & ~self.success & ~self.toppled

    @property
    def failed(self) -> np.ndarray:
        """bool: neither a success nor toppled nor fallen (the episode ran out of time or diverged)."""
        return ~self.success & ~self.toppled & ~self.fallen

    @staticmethod
    def concatenate(parts: list[FirstEpisodes], count: int) -> FirstEpisodes:
        """The first ``count`` worlds of several rounds."""
        return FirstEpisodes(**{f.name: np.concatenate([getattr(p, f.name) for p in parts])[:count]
                                for f in dataclasses.fields(FirstEpisodes)})


def run_first_episodes(env: PushEnv, policy: Policy, observers: Sequence[StepObserver] = (),
                       progress: tqdm | None = None, started: bool = False) -> FirstEpisodes:
    """Resets all worlds together and runs the policy for one episode length; see the module docstring.

    ``started``: the caller has just called ``env.reset(randomize_episode_step=False)`` itself (to read
    the episodes before creating its observers).
    """
    n = env.num_envs
    if not started:
        env.reset(randomize_episode_step=False)
    obs = env.get_observations()["policy"]
    shape = env.task.object_shape.numpy().copy()
    in_episode = torch.ones(n, dtype=torch.bool, device=env.device)
    length = torch.zeros(n, dtype=torch.long, device=env.device)
    first_success = torch.zeros(n, dtype=torch.long, device=env.device)
    success = torch.zeros(n, dtype=torch.bool, device=env.device)
    toppled = torch.zeros(n, dtype=torch.bool, device=env.device)
    fallen = torch.zeros(n, dtype=torch.bool, device=env.device)
    for step in range(env.max_episode_length):
        actions = policy(obs.cpu().numpy())
        obs = env.step(torch.from_numpy(actions).to(env.device))[0]["policy"]
        ended = in_episode & (env.reset_t != 0)
        continuing = in_episode & ~ended
        length += in_episode
        reached = in_episode & (env.success_t != 0) & (first_success == 0)
        first_success[reached] = step + 1
        success[ended] = env.episode_success_t[ended] == 1
        toppled[ended] = env.episode_toppled_t[ended] == 1
        fallen[ended] = env.episode_fallen_t[ended] == 1
        for observer in observers:
            observer.observe(step, in_episode, continuing)
        in_episode = continuing
        if progress is not None:
            progress.update(n)
    if bool(in_episode.any()):
        raise RuntimeError("a world's first episode outlasted the episode length (environment time-out broken)")
    return FirstEpisodes(length=length.cpu().numpy(), success=success.cpu().numpy(), toppled=toppled.cpu().numpy(),
                         fallen=fallen.cpu().numpy(), first_success_step=first_success.cpu().numpy(), shape=shape)
