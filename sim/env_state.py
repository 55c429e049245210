"""What the push and locomotion environments share beyond their kernels: reward weights, per-episode constraint
statistics and the snapshot of their simulation state (checkpoints, exact resume)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
import warp as wp
from tensordict import TensorDict


@wp.kernel
def articulation_reset_mask(
    reset: wp.array(dtype=int), articulation_world: wp.array(dtype=int), mask: wp.array(dtype=bool)
):
    """Per articulation, whether its world is reset (``reset[world] != 0``); articulations of no world stay."""
    a = wp.tid()
    w = articulation_world[a]
    mask[a] = w >= 0 and reset[w] != 0


class ConstraintEpisodeStats:
    """Per world, the steps of the running episode in which a column of each constraint group is violated
    (> 0); the share of an ended episode's steps per group is the paper's Table II measure."""

    def __init__(self, groups: Sequence[tuple[str, int]], num_envs: int, device: torch.device):
        self.names = [name for name, _ in groups]
        self.sizes = [size for _, size in groups]
        self.violated_steps = torch.zeros(num_envs, len(self.sizes), device=device)
        self.steps = torch.zeros(num_envs, device=device)

    def violated_groups(self, constraints: torch.Tensor) -> torch.Tensor:
        """(num_envs, groups) bool: a column of the group is violated."""
        return torch.stack([g.any(dim=1) for g in torch.split(constraints > 0.0, self.sizes, dim=1)], dim=1)

    def record(self, constraints: torch.Tensor) -> None:
        self.violated_steps += self.violated_groups(constraints)
        self.steps += 1.0

    def take(self, ended: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per group, the share of violated steps of the episodes that ``ended`` (bool per world); restarts them."""
        fraction = self.violated_steps[ended] / self.steps[ended, None]
        self.clear(ended)
        return {f"/episode/violated/{name}": fraction[:, i] for i, name in enumerate(self.names)}

    def clear(self, worlds: torch.Tensor | slice = slice(None)) -> None:
        self.violated_steps[worlds] = 0.0
        self.steps[worlds] = 0.0


class EnvBase:
    """Shared methods of the environments. A subclass sets ``reward_names``, ``_reward_weights`` (a Warp array in
    that order), ``constraints_t``, ``_constraint_stats``, the observation views ``policy_obs_t`` and
    ``critic_obs_t``, and implements ``_state_arrays()``."""

    reward_names: tuple[str, ...] = ()
    _reward_weights: wp.array
    _constraint_stats: ConstraintEpisodeStats
    constraints_t: torch.Tensor
    policy_obs_t: torch.Tensor
    critic_obs_t: torch.Tensor
    num_envs: int
    critic_input_columns: torch.Tensor | None = None
    """Columns of ``critic_obs_t`` the critic reads (None: all of them)."""

    def get_observations(self) -> TensorDict:
        """Copies of the observation buffers: the actor's, and the critic's input columns.

        The Warp buffers are zero-copy torch views that the next step overwrites in place; rsl_rl keeps
        a reference to the observation it acted on until the step is stored, so it gets a copy.
        """
        critic = (self.critic_obs_t.clone() if self.critic_input_columns is None
                  else self.critic_obs_t.index_select(1, self.critic_input_columns))
        return TensorDict({"policy": self.policy_obs_t.clone(), "critic": critic}, batch_size=[self.num_envs])

    def set_reward_weight(self, name: str, value: float) -> None:
        """Changes one reward weight (a name of ``reward_names``)."""
        if name not in self.reward_names:
            raise KeyError(f"reward weight name must be one of {self.reward_names}, got {name!r}")
        weights = self._reward_weights.numpy()
        weights[self.reward_names.index(name)] = value
        self._reward_weights.assign(weights)

    @property
    def violated_groups_t(self) -> torch.Tensor:
        """(num_envs, constraint groups) bool: a column of the group is violated (> 0) this step (Table II)."""
        return self._constraint_stats.violated_groups(self.constraints_t)

    def _state_arrays(self) -> dict[str, wp.array]:
        raise NotImplementedError

    def state_dict(self) -> dict[str, np.ndarray]:
        """Everything needed to continue the simulation exactly (numpy copies)."""
        return {name: array.numpy().copy() for name, array in self._state_arrays().items()}

    def state_mismatch(self, state: dict[str, np.ndarray]) -> str | None:
        """Why ``load_state_dict`` cannot restore ``state`` here (missing arrays, other shapes), or None."""
        arrays = self._state_arrays()
        missing = set(arrays) - set(state)
        if missing:
            return f"environment state lacks {sorted(missing)}"
        for name, array in arrays.items():
            shape = array.numpy().shape
            if tuple(state[name].shape) != shape:
                return f"environment state {name!r} has shape {state[name].shape}, expected {shape} (same num_envs required)"
        return None
