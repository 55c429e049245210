"""Expert-regularised CaT-PPO: an imitation term of the scripted pusher inside PPO's loss (ours, not in the paper).

CaT-PPO fine-tuning of a ``dynpush imitate`` actor lost the pushing every time (docs/training_on_cpu.md,
"Expert-guided initialisation"; docs/experiments/expert_guided_initialisation.md), and a behaviour-cloning pass with its own optimizer step did not hold the actor either. Here
the expert's action for every stored transition is regressed in the same loss, the same mini-batch and the same
Adam step as PPO's (as DAPG, Rajeswaran et al. 2018, adds demonstrations to the policy gradient)::

    loss = L_surrogate + c_v L_value - c_e H + w_imitation * mean_batch ||mu(o) - a_expert(s)||^2

``mu(o)`` is the actor's mean action for the (noisy) observation and ``a_expert(s)`` the scripted pusher's
action for the true state of the same step (:class:`~dynpush.policies.scripted.ScriptedPusher`); the squared
norm sums over the 11 action components (policy action units). ``w_imitation`` follows a linear schedule over
the run (``TrainConfig.fine_tune.imitation_weight``), so PPO can move away from the expert where the returns say so.

Two adapters keep rsl_rl's PPO unchanged:

- :class:`ExpertLabelledEnv` adds the expert's action to every observation as the group ``"expert_action"``,
  so rsl_rl's rollout storage keeps it beside the observation it labels (the actor and critic read only their
  own groups);
- :class:`ExpertImitationLoss` plugs into the extra-loss hook rsl_rl's PPO has for its symmetry extension
  (``augment_batch`` / ``compute_loss`` / ``mirror_loss_coeff``) and reads the actor's mean of PPO's own forward
  pass of the mini-batch. :meth:`CaTPPO.update <dynpush.policies.cat_ppo.CaTPPO.update>` logs it as
  ``Loss/imitation``.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict

from .scripted import ScriptedPusher, ScriptedPusherConfig

EXPERT_ACTION_GROUP = "expert_action"


class ExpertLabelledEnv:
    """A push environment whose observations also hold the scripted pusher's action for the same state.

    Everything but :meth:`get_observations` and :meth:`step` is the wrapped environment's.
    """

    def __init__(self, env, expert: ScriptedPusherConfig | None = None):
        self.env = env
        self.expert = ScriptedPusher(env, expert)

    def __getattr__(self, name: str):
        return getattr(self.env, name)

    def label(self, observations: TensorDict) -> TensorDict:
        """``observations`` with the expert's action ``[num_envs, num_actions]`` for the environment's current state."""
        observations[EXPERT_ACTION_GROUP] = torch.from_numpy(self.expert(None)).to(observations.device, torch.float)
        return observations

    def get_observations(self) -> TensorDict:
        return self.label(self.env.get_observations())

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        observations, rewards, dones, extras = self.env.step(actions)
        return self.label(observations), rewards, dones, extras


class ExpertImitationLoss:
    """rsl_rl PPO's extra-loss hook (the interface of ``rsl_rl.extensions.Symmetry``) with the imitation term.

    PPO adds ``mirror_loss_coeff * compute_loss(...)`` to its loss; the runner sets ``mirror_loss_coeff`` to the
    scheduled imitation weight at every iteration.
    """

    use_mirror_loss = True
    mirror_loss_coeff = 0.0

    def augment_batch(self, batch, original_batch_size: int) -> None:
        """No augmentation: the mini-batch is used as stored."""

    def compute_loss(self, actor, batch, original_batch_size: int) -> torch.Tensor:
        """Mean over the mini-batch of ``||mu(o) - a_expert||^2``; ``actor`` has just run PPO's forward pass on it."""
        expert_actions = batch.observations[EXPERT_ACTION_GROUP][:original_batch_size]
        return (actor.output_mean[:original_batch_size] - expert_actions).pow(2).sum(dim=-1).mean()
