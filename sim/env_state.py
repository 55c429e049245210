"""What the push and locomotion environments share beyond their kernels: the environment skeleton
(:class:`EnvBase`: construction, graph capture, reset, step and step result, episode log, reward weights and the
snapshot of the simulation state for checkpoints and exact resume) and the per-episode constraint statistics."""

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
    """The skeleton of both environments (rsl_rl ``VecEnv`` over N worlds of one Newton model, one control step a
    captured Warp graph).

    It does, the same way for every environment: construction (config, device, then :meth:`_build` inside the Warp
    device, the per-episode constraint statistics, a first :meth:`reset` and :meth:`_capture` of the step graph),
    kernel launches over the worlds (:meth:`_launch`), :meth:`reset` (flag every world, :meth:`_reset_flagged`, optionally
    spread the episode counters, joint targets at the joint positions, :meth:`_observe`), :meth:`step` (copy the actions
    into ``actions_t``, :meth:`_launch_step`, then the step result: observations, rewards, dones and extras with
    ``time_outs``, ``constraints`` and the episode log), the episode log (constraint-group shares and
    :meth:`_ended_episode_log` per ended episode, the mean of each reward term per step), observation copies, reward
    weights, and the state snapshot over :meth:`_state_arrays` (``state_dict``, ``state_mismatch``,
    ``load_state_dict`` with its hooks).

    An environment supplies: the class attributes ``reward_names``, ``num_actions`` and ``_constraint_groups``;
    :meth:`_build` (scene, solver, buffers and parameters; it sets ``_reward_weights``, ``task``, ``state_0``, ``control``
    and calls :meth:`_make_step_buffers`), :meth:`_step_kernels`,
    :meth:`_reset_flagged`, :meth:`_observe`, :meth:`_ended_episodes`, :meth:`_ended_episode_log` and
    :meth:`_state_arrays`; it may override :meth:`_capture`, :meth:`_launch_step` and the state-loading hooks."""

    reward_names: tuple[str, ...] = ()
    _constraint_groups: Sequence[tuple[str, int]] = ()
    """(name, columns) of each constraint group, in the order of the constraint columns."""
    _reward_weights: wp.array
    _constraint_stats: ConstraintEpisodeStats
    constraints_t: torch.Tensor
    policy_obs_t: torch.Tensor
    critic_obs_t: torch.Tensor
    num_envs: int
    critic_input_columns: torch.Tensor | None = None
    """Columns of ``critic_obs_t`` the critic reads (None: all of them)."""

    def __init__(self, cfg):
        self.cfg = cfg.validate()
        self.num_envs = cfg.num_envs
        self.max_episode_length = cfg.max_episode_steps
        self.device = cfg.device
        self.wp_device = wp.get_device(cfg.device)
        self.constraint_groups = list(self._constraint_groups)
        with wp.ScopedDevice(self.wp_device):
            self._build()
            # Per-episode constraint statistics (torch glue): steps with any column of a group violated.
            self._constraint_stats = ConstraintEpisodeStats(self.constraint_groups, self.num_envs, self.constraints_t.device)
            self.reset(randomize_episode_step=cfg.randomize_first_episode_length)
            self._capture()

    def _build(self) -> None:
        """Scene, solver, buffers and parameters (inside the Warp device)."""
        raise NotImplementedError

    def _make_step_buffers(self, num_policy_obs: int, num_critic_obs: int, num_constraints: int) -> None:
        """The Warp buffers every step writes (actions, observations, reward and its terms, reset and time-out flags,
        constraints) and their zero-copy torch views; ``task.episode_step`` as ``episode_length_buf``."""
        n = self.num_envs
        self.raw_actions = wp.zeros((n, self.num_actions), dtype=float)
        self.policy_obs = wp.zeros((n, num_policy_obs), dtype=float)
        self.critic_obs = wp.zeros((n, num_critic_obs), dtype=float)
        self.reward = wp.zeros(n, dtype=float)
        self.reward_terms = wp.zeros((n, len(self.reward_names)), dtype=float)
        self.reset_flags = wp.zeros(n, dtype=int)
        self.time_out = wp.zeros(n, dtype=int)
        self.constraints = wp.zeros((n, num_constraints), dtype=float)
        t = wp.to_torch
        self.actions_t = t(self.raw_actions)
        self.policy_obs_t, self.critic_obs_t = t(self.policy_obs), t(self.critic_obs)
        self.reward_t, self.reward_terms_t = t(self.reward), t(self.reward_terms)
        self.reset_t, self.time_out_t = t(self.reset_flags), t(self.time_out)
        self.constraints_t = t(self.constraints)
        self.episode_length_buf = t(self.task.episode_step)

    # ------------------------------------------------------------------ the step
    def _capture(self) -> None:
        """Captures the control step into ``_graph``."""
        with wp.ScopedCapture() as capture:  # on the CPU device too: faster, same states (docs/simulator.md)
            self._step_kernels()
        self._graph = capture.graph

    def _step_kernels(self) -> None:
        """Everything of one control step; captured once into a graph."""
        raise NotImplementedError

    def _launch(self, kernel, inputs) -> None:
        wp.launch(kernel, dim=self.num_envs, inputs=inputs, device=self.wp_device)

    def _launch_step(self) -> None:
        """Runs one control step of the captured graph(s) on the actions in ``actions_t`` (inside the Warp device)."""
        wp.capture_launch(self._graph)

    def _reset_flagged(self) -> None:
        """Draws and starts new episodes in the worlds with ``reset_flags != 0``."""
        raise NotImplementedError

    def _observe(self) -> None:
        """Writes the observations ``policy_obs`` and ``critic_obs``."""
        raise NotImplementedError

    def _sync_targets_and_observe(self) -> None:
        self.control.joint_target_q.assign(self.state_0.joint_q)
        self._observe()

    # ------------------------------------------------------------------ VecEnv
    def reset(self, randomize_episode_step: bool = False) -> TensorDict:
        """Resets every world (outside the graph) and returns the first observations.

        With ``randomize_episode_step`` the episode counters start uniformly in [0, episode length).
        """
        with wp.ScopedDevice(self.wp_device):
            self.reset_flags.fill_(1)
            self._reset_flagged()
            if randomize_episode_step:
                # Spread the first episodes' ends over one episode length so that resets (and episode
                # statistics) do not come in synchronized waves.
                rng = np.random.default_rng(self.cfg.seed)
                self.task.episode_step.assign(rng.integers(0, self.max_episode_length, self.num_envs, dtype=np.int32))
            self._sync_targets_and_observe()
        self._constraint_stats.clear()
        return self.get_observations()

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        self.actions_t.copy_(actions)
        with wp.ScopedDevice(self.wp_device):
            self._launch_step()
        return self._step_result()

    def _step_result(self) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        dones = self.reset_t.to(torch.long)
        extras = {
            "time_outs": self.time_out_t.to(torch.bool),
            "constraints": self.constraints_t,
            "log": self._episode_log(),
        }
        return self.get_observations(), self.reward_t.clone(), dones, extras

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

    def _episode_log(self) -> dict[str, float | torch.Tensor]:
        """Metrics of the episodes that ended this step and the mean of each reward term.

        Episode metrics are per ended episode (tensors), so rsl_rl's logger, which concatenates
        them over an iteration, weighs every episode equally: per constraint group the fraction of the
        episode's steps with a violated column (Table II), then :meth:`_ended_episode_log`.
        """
        log: dict[str, float | torch.Tensor] = {}
        self._constraint_stats.record(self.constraints_t)
        ended = self._ended_episodes()
        if bool(ended.any()):
            log.update(self._constraint_stats.take(ended))
            log.update(self._ended_episode_log(ended))
        for i, name in enumerate(self.reward_names):
            log[f"/reward/{name}"] = float(self.reward_terms_t[:, i].mean())
        return log

    def _ended_episodes(self) -> torch.Tensor:
        """(num_envs,) bool: the world's episode ended this step."""
        raise NotImplementedError

    def _ended_episode_log(self, ended: torch.Tensor) -> dict[str, torch.Tensor]:
        """The environment's metrics of the episodes that ended (``ended`` from :meth:`_ended_episodes`), one per episode."""
        raise NotImplementedError

    # ------------------------------------------------------------------ checkpointing
    def _state_arrays(self) -> dict[str, wp.array]:
        """The Warp arrays of :meth:`state_dict` by name."""
        raise NotImplementedError

    def state_dict(self) -> dict[str, np.ndarray]:
        """Everything needed to continue the simulation exactly (numpy copies)."""
        return {name: array.numpy().copy() for name, array in self._state_arrays().items()}

    def state_mismatch(self, state: dict[str, np.ndarray]) -> str | None:
        """Why ``load_state_dict`` cannot restore ``state`` here (missing arrays, other shapes), or None."""
        return self._mismatch(self._upgraded_state(state), self._state_arrays())

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restores :meth:`state_dict`."""
        state, arrays = self._upgraded_state(state), self._state_arrays()
        mismatch = self._mismatch(state, arrays)
        if mismatch is not None:
            raise ValueError(mismatch)
        with wp.ScopedDevice(self.wp_device):
            self._before_state_load(arrays, state)
            for name, array in arrays.items():
                array.assign(state[name])
            self._after_state_load()

    @staticmethod
    def _mismatch(state: dict[str, np.ndarray], arrays: dict[str, wp.array]) -> str | None:
        """Why ``state`` (already upgraded) cannot be written into ``arrays``, or None."""
        missing = set(arrays) - set(state)
        if missing:
            return f"environment state lacks {sorted(missing)}"
        for name, array in arrays.items():
            shape = array.numpy().shape
            if tuple(state[name].shape) != shape:
                return f"environment state {name!r} has shape {state[name].shape}, expected {shape} (same num_envs required)"
        return None

    def _upgraded_state(self, state: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``state`` as this version saves it, from a checkpoint an older version wrote (unchanged by default)."""
        return state

    def _before_state_load(self, arrays: dict[str, wp.array], state: dict[str, np.ndarray]) -> None:
        """What has to happen before the saved ``state`` is written into ``arrays`` (nothing by default)."""

    def _after_state_load(self) -> None:
        """What has to follow the written state (nothing by default)."""
