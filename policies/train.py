"""The push task's training configuration and presets (``dynpush train``).

The ``paper`` preset is the paper's scale (4096 environments, 20000 iterations, III-A) on a GPU; the ``cpu``
preset is sized for a 2-core laptop-class machine. What every task's training shares (PPO and network configs,
``--set`` overrides, the ``train`` job itself) is in ``policies/training.py``; its names below are re-exported
here for the callers that import them from this module.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from dynpush.kernels.constraints import CONSTRAINT_GROUPS
from dynpush.sim.config import ConfigError, PushEnvConfig

from .curriculum import GoalCurriculumConfig, NearGoalStartConfig
from .expert_regularization import ExpertLabelledEnv
from .schedules import ConstraintCurriculumConfig
from .scripted import ScriptedPusherConfig, check_object_size
from .training import (  # noqa: F401  (re-exported: the CLI, tests and benchmarks import them from here)
    PRESETS,
    NetworkConfig,
    PPOConfig,
    ProcessGroup,
    apply_overrides,
    config_from_dict,
    launch_processes,
    rsl_rl_runner_cfg,
    run_config,
    sigterm_as_keyboard_interrupt,
    train,
    tuple_like,
)


@dataclass
class TrainConfig:
    preset: str = "cpu"
    env: PushEnvConfig = field(default_factory=PushEnvConfig)
    iterations: int = 1500
    num_steps_per_env: int = 24
    save_interval: int = 50
    ppo: PPOConfig = field(default_factory=PPOConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    # Schedules (p_max curricula, w2) scale with the run length unless this is False (policies/schedules.py).
    scale_schedules_with_run_length: bool = True
    # Constraint groups whose p_max is held at 0 (Table I ablation: "w/o object balance constraint").
    disabled_constraint_groups: tuple[str, ...] = ()
    # CaT p_max curricula replacing the paper's (Table "Rewards and constraints") for some groups:
    # group -> (initial, final), ramped like the others; e.g. {'collision': (0.1, 1.0)}.
    p_max_overrides: dict[str, tuple[float, float]] = field(default_factory=dict)
    curriculum: GoalCurriculumConfig = field(default_factory=GoalCurriculumConfig)
    # Training resets that start near the goal with the yaw off (ours, policies/curriculum.py); evaluation never
    # uses them: the evaluation environment is built from ``env`` alone (policies/trained_env.py).
    near_goal_starts: NearGoalStartConfig = field(default_factory=NearGoalStartConfig)
    # Iterations at the start of the run in which only the critic learns and the actor is held (ours): for
    # runs that start from a ``dynpush imitate`` checkpoint, whose critic has not learnt the returns yet.
    critic_warmup_iterations: int = 0
    # Learning rate of those warm-up iterations (ours; None: ppo.learning_rate); the run's takes over with the actor.
    # Fine-tuning a ``dynpush imitate`` actor, the critic explained 7-14 % of the variance of the returns after 30
    # iterations at 1e-4, 52-64 % after 40-74 at 1e-3 (docs/experiments/expert_guided_initialisation.md, "Where the
    # fine-tunings lose it").
    critic_warmup_learning_rate: float | None = None
    # Weight of the scripted pusher's imitation term in PPO's loss, (first, last iteration), linear in between
    # (ours, policies/expert_regularization.py); (0, 0) is plain CaT-PPO.
    imitation_weight: tuple[float, float] = (0.0, 0.0)
    # The imitation term's expert: None reads the true object size, shape and centre of mass; an edge [m] makes it
    # treat every object as a centred cuboid of that edge (ScriptedPusherConfig.object_size), the teacher of a
    # ``dynpush imitate --expert-object-size`` student.
    expert_object_size: float | None = None
    # More of that expert's gains, FIELD=VALUE of ScriptedPusherConfig (e.g. "push_speed=1.0"), the teacher of a
    # ``dynpush imitate --expert-set`` student.
    expert_overrides: tuple[str, ...] = ()
    # Iterations between evaluations during training (ours; 0: none). Rank 0 runs the deterministic mean of the
    # current actor for one episode in each of eval_episodes worlds of the paper's task (the run's environment with
    # PushEnvConfig's default sampling), the loop of ``dynpush eval``, and appends the result to evaluations.jsonl.
    # 256 episodes of 20 s are 256 k world-steps on one process while the others wait, the simulation of ~40
    # iterations of the cpu preset under --procs 2 (6144 world-steps per process): an interval of 500 keeps the
    # evaluations under ~8 % of the run.
    eval_interval: int = 0
    eval_episodes: int = 256  # worlds of the evaluation, one episode each
    eval_seed: int = 0  # the evaluation environment's seed; every evaluation of a run starts the same episodes
    # The newest model_K.pt kept after each save (0: all): a run folder under version control keeps a few.
    keep_checkpoints: int = 0

    @staticmethod
    def preset_config(name: str) -> TrainConfig:
        if name == "paper":  # III-A: 4096 environments, 20000 iterations
            env = PushEnvConfig(num_envs=4096, device="cuda:0", randomize_first_episode_length=True)
            return TrainConfig(preset=name, env=env, iterations=20000)
        if name == "cpu":
            env = PushEnvConfig(num_envs=512, device="cpu", randomize_first_episode_length=True)
            # Ours: half rsl_rl's initial action noise; with std 1 the exploration alone violates the
            # base-command and arm-rate limits in most steps, which short runs cannot afford.
            return TrainConfig(preset=name, env=env, iterations=3000, network=NetworkConfig(init_noise_std=0.5))
        raise ConfigError(f"preset must be one of {PRESETS}, got {name!r}")

    def validate(self) -> TrainConfig:
        self.env.validate()
        self.curriculum.validate()
        self.near_goal_starts.validate()
        if self.env.legged.enabled and not self.env.legged.locomotion_policy:
            raise ConfigError("env.legged.locomotion_policy must name a locomotion.onnx to train in legged mode"
                              " (without one the legs hold their default targets)")
        if not isinstance(self.critic_warmup_iterations, int) or self.critic_warmup_iterations < 0:
            raise ConfigError(f"critic_warmup_iterations must be an integer >= 0, got {self.critic_warmup_iterations!r}")
        if self.critic_warmup_learning_rate is not None and not 0.0 < self.critic_warmup_learning_rate <= 1e-2:
            raise ConfigError("critic_warmup_learning_rate must be None or in (0, 0.01], got"
                              f" {self.critic_warmup_learning_rate!r}")
        for name in ("iterations", "num_steps_per_env", "save_interval"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(f"{name} must be an integer >= 1, got {getattr(self, name)!r}")
        groups = [name for name, _ in CONSTRAINT_GROUPS]
        for field_name in ("disabled_constraint_groups", "p_max_overrides"):
            unknown = set(getattr(self, field_name)) - set(groups)
            if unknown:
                raise ConfigError(f"{field_name}: unknown {sorted(unknown)}; allowed: {groups}")
        for name, pair in self.p_max_overrides.items():
            if len(pair) != 2 or not all(0.0 <= p <= 1.0 for p in pair):
                raise ConfigError(f"p_max_overrides[{name!r}] must be (initial, final) within [0, 1], got {pair!r}")
        if len(self.imitation_weight) != 2 or not all(w >= 0.0 for w in self.imitation_weight):
            raise ConfigError(f"imitation_weight must be (first, last) with both >= 0, got {self.imitation_weight!r}")
        check_object_size("expert_object_size", self.expert_object_size)
        scripted_expert(self.expert_object_size, self.expert_overrides, "expert_overrides")
        self.ppo.validate()
        for name, low in (("eval_interval", 0), ("eval_episodes", 1), ("keep_checkpoints", 0)):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < low:
                raise ConfigError(f"{name} must be an integer >= {low}, got {getattr(self, name)!r}")
        return self

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def make_env(self, env: PushEnvConfig):
        """The push environment of ``env`` (tracked base, or the legged robot with ``env.legged.enabled``)."""
        from dynpush.sim.envs import make_push_env

        if max(self.imitation_weight) == 0:
            return make_push_env(env)
        return ExpertLabelledEnv(make_push_env(env), scripted_expert(self.expert_object_size, self.expert_overrides,
                                                                    "expert_overrides"))

    @staticmethod
    def from_dict(data: dict) -> TrainConfig:
        return config_from_dict(TrainConfig, data)

    def runner_cfg(self) -> dict:
        """The rsl_rl runner configuration."""
        return {
            **rsl_rl_runner_cfg(self.num_steps_per_env, self.save_interval, self.ppo, self.network),
            "schedule": {
                "scale_with_run_length": self.scale_schedules_with_run_length,
                "constraints": {"p_max": {**ConstraintCurriculumConfig().p_max,
                                          **{name: tuple(pair) for name, pair in self.p_max_overrides.items()},
                                          **{name: (0.0, 0.0) for name in self.disabled_constraint_groups}}},
            },
            "curriculum": dataclasses.asdict(self.curriculum),
            "near_goal_starts": dataclasses.asdict(self.near_goal_starts),
            "critic_warmup_iterations": self.critic_warmup_iterations,
            "critic_warmup_learning_rate": self.critic_warmup_learning_rate,
            "imitation_weight": tuple(self.imitation_weight),
            "keep_checkpoints": self.keep_checkpoints,
        }


def scripted_expert(object_size: float | None, overrides: tuple[str, ...], name: str) -> ScriptedPusherConfig:
    """The scripted pusher's config for imitation: ``object_size`` (None: the true size) and then ``overrides``
    (FIELD=VALUE of ScriptedPusherConfig) on its defaults, checked; errors name the config field ``name``."""
    try:
        cfg = apply_overrides(ScriptedPusherConfig(object_size=object_size), list(overrides))
        cfg.validate()
    except ConfigError as error:
        raise ConfigError(f"{name}: {error}") from None
    return cfg
