"""The fine-tuning knobs of a push training run (``TrainConfig.fine_tune``, ours, not in the paper).

They matter only when a run starts from another policy (``dynpush train --init-from``: a ``dynpush imitate``
checkpoint, another run's ``model_K.pt`` or an exported ``policy.onnx``) or is anchored to the scripted pusher by an
imitation term in PPO's loss (policies/expert_regularization.py). Their defaults are plain CaT-PPO: no critic
warm-up, no imitation term. On the command line they are ``--set fine_tune.FIELD=VALUE``, e.g.
``--set fine_tune.critic_warmup_iterations=60 "fine_tune.imitation_weight=(1.0, 1.0)"``.

Runs written before this section existed hold these fields at the top level of their ``config.json``
(``critic_warmup_iterations``, ...); ``TrainConfig.from_dict`` reads them into this section (``MOVED_FIELDS``).

What the numbers did in this project's runs: docs/experiments/expert_guided_initialisation.md and
docs/ppo_fine_tuning.md. The other knob of a run that starts from another policy,
``network.hold_actor_normalizer``, is part of the network (every task has it).
"""

from __future__ import annotations

from dataclasses import dataclass

from dynpush.sim.config import ConfigError

from .scripted import ScriptedPusherConfig, check_object_size
from .overrides import apply_overrides

SECTION = "fine_tune"  # the TrainConfig field that holds a FineTuneConfig

# Fields of FineTuneConfig that were TrainConfig fields before it existed: old config.json key -> its path now.
MOVED_FIELDS = {name: f"{SECTION}.{name}" for name in (
    "critic_warmup_iterations", "critic_warmup_learning_rate", "imitation_weight", "expert_object_size",
    "expert_overrides")}


@dataclass
class FineTuneConfig:
    """Critic warm-up and expert imitation term of a run that starts from another policy or follows the scripted
    pusher (see the module docstring)."""

    critic_warmup_iterations: int = 0
    """[iterations] At the start of the run, in which only the critic learns and the actor (its weights and action
    std) is held; 0: none. For runs that start from a ``dynpush imitate`` checkpoint, whose critic has not learnt the
    returns yet, and required (> 0) for a run that starts from an exported ``policy.onnx``, which holds no critic."""

    critic_warmup_learning_rate: float | None = None
    """[Adam step size] of the warm-up iterations, in (0, 0.01]; None: ``ppo.learning_rate``. The run's own takes
    over with the first actor update. A critic that starts fresh learns the returns' scale far faster at 1e-3 than
    at the small learning rates of a fine-tune (docs/experiments/expert_guided_initialisation.md, "Where the
    fine-tunings lose it")."""

    imitation_weight: tuple[float, float] = (0.0, 0.0)
    """(first, last iteration) weight, both >= 0, of the scripted pusher's imitation term in PPO's loss (per unit of
    mean squared action error, policy action units), linear in between (policies/expert_regularization.py);
    (0, 0): plain CaT-PPO, and the environment computes no expert actions."""

    expert_object_size: float | None = None
    """[m] The imitation term's expert: None reads the true object size, shape and centre of mass; an edge in
    (0, 2] m makes it treat every object as a centred cuboid of that edge (ScriptedPusherConfig.object_size), the
    teacher of a ``dynpush imitate --expert-object-size`` student."""

    expert_overrides: tuple[str, ...] = ()
    """More of that expert's gains, FIELD=VALUE of ScriptedPusherConfig applied after ``expert_object_size``
    (e.g. ``"push_speed=1.0"``), the teacher of a ``dynpush imitate --expert-set`` student."""

    def validate(self) -> FineTuneConfig:
        """Raises a ConfigError naming the first field (``fine_tune.NAME``) out of its range."""
        if not isinstance(self.critic_warmup_iterations, int) or self.critic_warmup_iterations < 0:
            raise ConfigError(f"{SECTION}.critic_warmup_iterations must be an integer >= 0, got"
                              f" {self.critic_warmup_iterations!r}")
        if self.critic_warmup_learning_rate is not None and not 0.0 < self.critic_warmup_learning_rate <= 1e-2:
            raise ConfigError(f"{SECTION}.critic_warmup_learning_rate must be None or in (0, 0.01], got"
                              f" {self.critic_warmup_learning_rate!r}")
        if len(self.imitation_weight) != 2 or not all(w >= 0.0 for w in self.imitation_weight):
            raise ConfigError(f"{SECTION}.imitation_weight must be (first, last) with both >= 0, got"
                              f" {self.imitation_weight!r}")
        check_object_size(f"{SECTION}.expert_object_size", self.expert_object_size)
        self.expert()
        return self

    @property
    def imitates(self) -> bool:
        """Whether the run has the imitation term (its environment labels each observation with the expert's action)."""
        return max(self.imitation_weight) > 0

    def expert(self) -> ScriptedPusherConfig:
        """The imitation term's expert: the scripted pusher with ``expert_object_size`` and ``expert_overrides``."""
        return scripted_expert(self.expert_object_size, self.expert_overrides, f"{SECTION}.expert_overrides")


def scripted_expert(object_size: float | None, overrides: tuple[str, ...], name: str) -> ScriptedPusherConfig:
    """The scripted pusher's config for imitation: ``object_size`` (None: the true size) and then ``overrides``
    (FIELD=VALUE of ScriptedPusherConfig) on its defaults, checked; errors name the config field ``name``."""
    try:
        cfg = apply_overrides(ScriptedPusherConfig(object_size=object_size), list(overrides))
        cfg.validate()
    except ConfigError as error:
        raise ConfigError(f"{name}: {error}") from None
    return cfg
