"""Constraints as Terminations (CaT) as a small subclass of rsl_rl's PPO.

Reference:
    - Chane-Sane et al. "CaT: Constraints as Terminations for Legged Locomotion Learning." IROS 2024.

The environment returns raw constraint values ``c`` of shape ``[num_envs, C]`` in ``extras["constraints"]`` (violated
where ``c > 0``) and names their column groups in ``env.constraint_groups``. Every step, per column ``i``::

    c_max_i <- tau * c_max_i + (1 - tau) * max(max_envs(c_i), 1e-6)     (seeded with the first batch)
    p_i      = p_max_i * clip(c_i / c_max_i, 0, 1)   where c_i > 0, else 0
    delta    = max_i p_i                                                 (per env, in [0, 1])

``delta`` is a soft termination: the stored reward becomes ``r * (1 - delta)`` and GAE discounts with
``gamma * (1 - delta_t)`` on top of the environment's dones. rsl_rl's storage keeps dones as bytes, so ``delta`` has
its own float buffer (:attr:`CaTPPO.deltas`).

With ``returns_per_step`` (the default) PPO stores every reward multiplied by ``1 - gamma``, so that the critic learns
values in units of reward per step (a discounted average of the rewards to come) instead of discounted sums. The task's
rewards are a few per step; their discounted sums reach ``r / (1 - gamma)``, about 2000 at gamma 0.998, while rsl_rl's
value loss clips every update of a value to ``clip_param`` (0.2) around the value it had: a critic that starts at 0
then needs hundreds of iterations to reach the scale of the returns and, until it has, discounts whatever ends an
episode or a CaT termination as if the future were worth a few per cent of its worth. In reward-per-step units the
same clip is 0.2 of a reward. The actor's loss is unchanged (advantages are normalised), and the logged rewards stay
the environment's. Everything else (models, storage, update, normalisation) is rsl_rl's.
"""

from __future__ import annotations

import torch
from collections.abc import Callable, Sequence
from tensordict import TensorDict

from rsl_rl.algorithms import PPO
from rsl_rl.env import VecEnv
from rsl_rl.models import MLPModel
from rsl_rl.storage import RolloutStorage

from .expert_regularization import ExpertImitationLoss


class CaTPPO(PPO):
    """PPO with Constraints as Terminations."""

    def __init__(
        self,
        actor: MLPModel,
        critic: MLPModel,
        storage: RolloutStorage,
        constraint_groups: Sequence[tuple[str, int]],
        tau: float = 0.95,
        c_max_floor: float = 1e-6,
        returns_per_step: bool = True,
        **kwargs,
    ) -> None:
        """Initialize PPO and the CaT state.

        Args:
            actor: Actor model.
            critic: Critic model.
            storage: rsl_rl rollout storage.
            constraint_groups: ``(name, dim)`` per constraint group, in column order of ``extras["constraints"]``.
            tau: Polyak factor of the running maximum violation ``c_max`` (CaT paper: 0.95).
            c_max_floor: Lower bound of the per-column batch maximum, keeps ``c / c_max`` finite (CaT paper: 1e-6).
            returns_per_step: Store rewards multiplied by ``1 - gamma`` (values in reward-per-step units).
            **kwargs: Arguments of :class:`rsl_rl.algorithms.PPO`.
        """
        super().__init__(actor, critic, storage, **kwargs)
        self.constraint_groups = [(str(name), int(dim)) for name, dim in constraint_groups]
        self.tau = tau
        self.c_max_floor = c_max_floor
        self.reward_scale = 1.0 - self.gamma if returns_per_step else 1.0
        """Factor of the rewards PPO stores and learns values of (``1 - gamma`` with ``returns_per_step``)."""

        num_constraints = sum(dim for _, dim in self.constraint_groups)
        self.c_max = torch.zeros(num_constraints, device=self.device)
        """Running maximum violation per column; 0 until the first batch seeds it. Saved in checkpoints."""

        self.p_max: torch.Tensor | None = None
        """Maximum termination probability per column, set by :meth:`set_p_max` (the runner's curriculum)."""

        self.deltas = torch.zeros(storage.num_transitions_per_env, storage.num_envs, 1, device=self.device)
        """Termination probability of every stored transition, aligned with ``storage.dones``."""

        self.on_rollout_start: Callable[[], None] | None = None
        """Called before the first action of every rollout (the runner applies its schedules here)."""

        self.value_explained_variance = float("nan")
        """``explained_variance`` of the last rollout's returns by the values stored with it (set by compute_returns)."""

    def set_p_max(self, p_max: torch.Tensor) -> None:
        """Set the per-column maximum termination probability ``[C]``."""
        if p_max.shape != self.c_max.shape:
            raise ValueError(f"p_max has shape {tuple(p_max.shape)}, expected {tuple(self.c_max.shape)}.")
        self.p_max = p_max.to(self.device, torch.float)

    def reduce_batch_max(self, batch_max: torch.Tensor) -> torch.Tensor:
        """Combine the per-column batch maxima of all processes (all-reduce MAX), so ``c_max`` stays
        identical on every rank of a distributed run; unchanged in a single process."""
        if self.is_multi_gpu:
            torch.distributed.all_reduce(batch_max, op=torch.distributed.ReduceOp.MAX)
        return batch_max

    def termination_probabilities(self, constraints: torch.Tensor) -> torch.Tensor:
        """Update ``c_max`` with a batch of raw constraints ``[num_envs, C]`` and return each column's termination
        probability ``p_i`` ``[num_envs, C]``."""
        if self.p_max is None:
            raise RuntimeError("p_max is not set: call set_p_max() (CaTOnPolicyRunner does at every iteration).")
        batch_max = self.reduce_batch_max(constraints.amax(dim=0)).clamp(min=self.c_max_floor)
        self.c_max.copy_(torch.where(self.c_max > 0, self.tau * self.c_max + (1.0 - self.tau) * batch_max, batch_max))
        ratio = (constraints / self.c_max).clamp(0.0, 1.0)
        return torch.where(constraints > 0, self.p_max * ratio, torch.zeros_like(ratio))

    def termination_probability(self, constraints: torch.Tensor) -> torch.Tensor:
        """Update ``c_max`` with a batch of raw constraints ``[num_envs, C]`` and return ``delta`` ``[num_envs]``."""
        return self.termination_probabilities(constraints).amax(dim=1)

    def act(self, obs: TensorDict) -> torch.Tensor:
        """Sample actions and store transition data; starts a rollout with :attr:`on_rollout_start`."""
        if self.storage.step == 0 and self.on_rollout_start is not None:
            self.on_rollout_start()
        return super().act(obs)

    def process_env_step(
        self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict[str, torch.Tensor]
    ) -> None:
        """Record one environment step with its termination probability.

        The stored reward is the environment's times :attr:`reward_scale`; it is then, rsl_rl's time-out bootstrap
        ``gamma * V`` included, scaled by ``1 - delta``: a terminated transition has no continuation value either.
        CaT statistics of the step are added to the extras dict that rsl_rl's logger averages over the iteration
        (``"episode"`` if present, else ``"log"``).
        """
        constraints = extras["constraints"].to(self.device, torch.float)
        probabilities = self.termination_probabilities(constraints)
        delta = probabilities.amax(dim=1)
        step = self.storage.step
        self.deltas[step].copy_(delta.unsqueeze(1))
        super().process_env_step(obs, rewards * self.reward_scale, dones, extras)
        self.storage.rewards[step].mul_(1.0 - self.deltas[step])

        log_key = "episode" if "episode" in extras else "log"
        extras[log_key] = {**extras.get(log_key, {}), **self._step_log(constraints, probabilities, delta)}

    def compute_returns(self, obs: TensorDict) -> None:
        """Compute GAE returns and advantages with the per-step discount ``gamma * (1 - delta_t)``."""
        st = self.storage
        # Compute values for the last step
        critic_hidden_state = self.critic.get_hidden_state()
        last_values = self.critic(obs).detach()
        # Restore the critic's hidden state so the next rollout is not affected by the forward pass
        self.critic.reset(hidden_state=critic_hidden_state)
        advantage = 0
        for step in reversed(range(st.num_transitions_per_env)):
            next_values = last_values if step == st.num_transitions_per_env - 1 else st.values[step + 1]
            # Probability that the episode continues after this step: real dones and CaT terminations
            next_is_not_terminal = (1.0 - st.dones[step].float()) * (1.0 - self.deltas[step])
            # TD error: r_t + gamma * (1 - delta_t) * V(s_{t+1}) - V(s_t)
            delta = st.rewards[step] + next_is_not_terminal * self.gamma * next_values - st.values[step]
            # Advantage: A_t = TD_t + gamma * (1 - delta_t) * lambda * A_{t+1}
            advantage = delta + next_is_not_terminal * self.gamma * self.lam * advantage
            st.returns[step] = advantage + st.values[step]
        st.advantages = st.returns - st.values
        self.value_explained_variance = explained_variance(st.values, st.returns)
        if not self.normalize_advantage_per_mini_batch:
            st.advantages = (st.advantages - st.advantages.mean()) / (st.advantages.std() + 1e-8)

    def update(self) -> dict[str, float]:
        """rsl_rl's PPO update; the expert-imitation term, which rides on rsl_rl's symmetry-loss hook
        (:mod:`dynpush.policies.expert_regularization`), is reported as ``imitation``, and the explained variance
        of the rollout's returns by the critic's values before the update as ``value_explained_variance``."""
        losses = super().update()
        if isinstance(self.symmetry, ExpertImitationLoss):
            losses["imitation"] = losses.pop("symmetry")
        losses["value_explained_variance"] = self.value_explained_variance
        return losses

    def save(self) -> dict:
        """Return PPO's saved dict plus the CaT state (``c_max``)."""
        saved_dict = super().save()
        saved_dict["cat_state_dict"] = {"c_max": self.c_max.clone()}
        return saved_dict

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        """Load PPO's models and states, and ``c_max`` unless ``load_cfg`` is given without ``"cat": True``."""
        load_iteration = super().load(loaded_dict, load_cfg, strict)
        if load_cfg is None or load_cfg.get("cat"):
            self.c_max.copy_(loaded_dict["cat_state_dict"]["c_max"])
        return load_iteration

    @staticmethod
    def construct_algorithm(obs: TensorDict, env: VecEnv, cfg: dict, device: str) -> CaTPPO:
        """Construct CaT-PPO as rsl_rl constructs PPO, with the constraint layout of ``env.constraint_groups``.

        The layout is recorded in ``cfg["algorithm"]["constraint_groups"]``, next to the other algorithm arguments.
        """
        cfg["algorithm"]["constraint_groups"] = [(name, dim) for name, dim in env.constraint_groups]  # type: ignore
        return PPO.construct_algorithm(obs, env, cfg, device)  # type: ignore

    def _step_log(self, constraints: torch.Tensor, probabilities: torch.Tensor, delta: torch.Tensor
                  ) -> dict[str, torch.Tensor]:
        """Mean ``delta`` and, per group, the fraction of envs with any column violated and the mean of the group's
        termination probability (its largest column's): which constraints the pressure comes from."""
        sizes = [dim for _, dim in self.constraint_groups]
        log = {"CaT/mean_delta": delta.mean()}
        for (name, _), violated, group_probabilities in zip(
                self.constraint_groups, (constraints > 0).split(sizes, dim=1), probabilities.split(sizes, dim=1)):
            log[f"CaT/violation_rate/{name}"] = violated.any(dim=1).float().mean()
            log[f"CaT/delta/{name}"] = group_probabilities.amax(dim=1).mean()
        return log


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """``1 - Var(returns - values) / Var(returns)`` over all transitions: 1 for a critic that predicts the GAE
    returns exactly, 0 for one that predicts their mean, negative for worse; NaN when the returns are constant."""
    variance = returns.var()
    if variance == 0:
        return float("nan")
    return float(1.0 - (returns - values).var() / variance)
