"""The push task's training configuration and presets (``dynpush train``).

The ``paper`` preset is the paper's scale (4096 environments, 20000 iterations, III-A) on a GPU; the ``cpu``
preset is sized for a 2-core laptop-class machine. What every task's training shares (PPO and network configs, the
``train`` job itself) is in ``policies/training.py``, ``--set`` overrides in ``policies/overrides.py``; the names
imported below from both are re-exported here for the callers that import them from this module. The knobs of a run that starts from another policy or
follows the scripted pusher are in ``policies/fine_tune.py`` (``TrainConfig.fine_tune``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS
from dynpush.sim.config import ConfigError, PushEnvConfig

from .curriculum import (
    BehindStartConfig, GoalCurriculumConfig, GoalDistanceCurriculumConfig, NearGoalStartConfig,
    ObjectMassCurriculumConfig,
)
from .expert_regularization import ExpertLabelledEnv
from .fine_tune import MOVED_FIELDS, FineTuneConfig
from .overrides import apply_overrides, config_from_dict  # noqa: F401  (apply_overrides: re-exported)
from .schedules import ConstraintCurriculumConfig
from .training import (  # noqa: F401  (re-exported: the CLI, tests and benchmarks import them from here)
    PRESETS,
    NetworkConfig,
    PPOConfig,
    rsl_rl_runner_cfg,
    train,
)


def with_default(data: dict, path: list[str], value: object) -> dict:
    """``data`` with ``value`` at ``path`` where the field's section is present and the field is missing (copies only
    the dicts on the way)."""
    head, rest = path[0], path[1:]
    if not rest:
        return data if head in data else {**data, head: value}
    if not isinstance(data.get(head), dict):
        return data
    return {**data, head: with_default(data[head], rest, value)}


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
    # CaT p_max curricula replacing the paper's (Table "Rewards and constraints") for some groups: group ->
    # (initial, final) maximum termination probability, each in [0, 1], ramped like the others (schedules.py);
    # e.g. {'collision': (0.1, 1.0)}. With disabled_constraint_groups, the run's CaT curriculum
    # (runner_cfg()["schedule"]["constraints"]); runs from scratch set it too (configs/recipes/long_run.txt).
    p_max_overrides: dict[str, tuple[float, float]] = field(default_factory=dict)
    # True: p_max goes from initial to final with the success-gated curricula's mean level, not the iteration count
    # (ours, policies/schedules.py); needs at least one curriculum enabled.
    p_max_follows_curricula: bool = False
    curriculum: GoalCurriculumConfig = field(default_factory=GoalCurriculumConfig)
    # Training objects from light to the configured masses (ours, policies/curriculum.py); evaluation draws from
    # env.randomization.mass.
    mass_curriculum: ObjectMassCurriculumConfig = field(default_factory=ObjectMassCurriculumConfig)
    # Goals first 0.4-0.6 m away, then as far as env.sampling.goal_radius (ours, policies/curriculum.py).
    distance_curriculum: GoalDistanceCurriculumConfig = field(default_factory=GoalDistanceCurriculumConfig)
    # The success-gated curricula move on the success of at least this many ended training episodes (ours): 256
    # worlds end about six 20 s episodes per iteration, too few to judge a level by.
    curriculum_window_episodes: int = 100
    # Training resets that start near the goal with the yaw off (ours, policies/curriculum.py); evaluation never
    # uses them: the evaluation environment is built from ``env`` alone (policies/trained_env.py).
    near_goal_starts: NearGoalStartConfig = field(default_factory=NearGoalStartConfig)
    # Training resets with the robot behind the object, facing it and the goal (ours, policies/curriculum.py).
    behind_starts: BehindStartConfig = field(default_factory=BehindStartConfig)
    # Critic warm-up and the scripted pusher's imitation term: what matters only when a run starts from another
    # policy (--init-from) or is anchored to the expert (policies/fine_tune.py); the defaults are plain CaT-PPO.
    fine_tune: FineTuneConfig = field(default_factory=FineTuneConfig)
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

    # Not a field: the flat names of fields that moved into a section; apply_overrides names the new path.
    MOVED_FIELDS = MOVED_FIELDS
    # Not a field: fields added since the first runs, with the value that reproduces what a run written before them
    # trained with (``from_dict`` gives it to a config that lacks the field).
    ADDED_FIELDS = {"env.critic_reads_object_at_goal": False, "env.constraints.contacts_at_step_end": False}

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
        self.curriculum.validate(configured_angle_deg=self.env.rewards.success_angle_deg)
        self.mass_curriculum.validate(configured=self.env.randomization.mass)
        self.distance_curriculum.validate(configured=self.env.sampling.goal_radius)
        self.near_goal_starts.validate()
        self.behind_starts.validate()
        if self.env.legged.enabled and not self.env.legged.locomotion_policy:
            raise ConfigError("env.legged.locomotion_policy must name a locomotion.onnx to train in legged mode"
                              " (without one the legs hold their default targets)")
        self.fine_tune.validate()
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
        if self.p_max_follows_curricula and not any(
                level.enabled for level in (self.curriculum, self.mass_curriculum, self.distance_curriculum,
                                            self.behind_starts)):
            raise ConfigError("p_max_follows_curricula needs an enabled curriculum (curriculum, mass_curriculum,"
                              " distance_curriculum or behind_starts .enabled=True)")
        self.ppo.validate()
        self.network.validate()
        for name, low in (("eval_interval", 0), ("eval_episodes", 1), ("keep_checkpoints", 0),
                          ("curriculum_window_episodes", 1)):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < low:
                raise ConfigError(f"{name} must be an integer >= {low}, got {getattr(self, name)!r}")
        return self

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def check_onnx_start(self, init_from: Path) -> None:
        """A run may start from an exported actor when its new critic learns the returns first: raises a ConfigError
        unless ``fine_tune.critic_warmup_iterations`` > 0."""
        if not self.fine_tune.critic_warmup_iterations:
            raise ConfigError(f"--init-from {init_from}: an ONNX file holds the actor only; set"
                              " fine_tune.critic_warmup_iterations > 0 (e.g. 60) so that the new critic learns the"
                              " returns before the actor is trained")

    def make_env(self, env: PushEnvConfig):
        """The push environment of ``env`` (tracked base, or the legged robot with ``env.legged.enabled``)."""
        from dynpush.sim.envs import make_push_env

        if not self.fine_tune.imitates:
            return make_push_env(env)
        return ExpertLabelledEnv(make_push_env(env), self.fine_tune.expert())

    @staticmethod
    def from_dict(data: dict) -> TrainConfig:
        """The config of a ``config.json`` (or an exported policy's ``training_config``). Runs written before the
        ``fine_tune`` section existed hold its fields at the top level (``MOVED_FIELDS``): they are read into it, with
        the same values; a field added since the run was written (``ADDED_FIELDS``) reads as the value the run trained
        with, wherever its section is present. The caller's dict is left unchanged."""
        data = dict(data)
        for path, value in TrainConfig.ADDED_FIELDS.items():
            data = with_default(data, path.split("."), value)
        moved = {name: data.pop(name) for name in MOVED_FIELDS if name in data}
        if moved:
            section = dict(data.get("fine_tune", {}))
            both = sorted(set(moved) & set(section))
            if both:
                raise ConfigError(f"config holds both {both[0]} and {MOVED_FIELDS[both[0]]}; keep one")
            data["fine_tune"] = {**section, **moved}
        return config_from_dict(TrainConfig, data)

    def runner_cfg(self) -> dict:
        """The rsl_rl runner configuration."""
        return {
            **rsl_rl_runner_cfg(self.num_steps_per_env, self.save_interval, self.ppo, self.network),
            "schedule": {
                "scale_with_run_length": self.scale_schedules_with_run_length,
                "constraints": {"p_max": {**ConstraintCurriculumConfig().p_max,
                                          **{name: tuple(pair) for name, pair in self.p_max_overrides.items()},
                                          **{name: (0.0, 0.0) for name in self.disabled_constraint_groups}},
                                "follow_curricula": self.p_max_follows_curricula},
                # The schedule starts from the environment's w2, so that env.rewards.reach_weight is the weight trained.
                "reach": {"weight": self.env.rewards.reach_weight},
            },
            "curriculum": dataclasses.asdict(self.curriculum),
            "mass_curriculum": dataclasses.asdict(self.mass_curriculum),
            "distance_curriculum": dataclasses.asdict(self.distance_curriculum),
            "curriculum_window_episodes": self.curriculum_window_episodes,
            "near_goal_starts": dataclasses.asdict(self.near_goal_starts),
            "behind_starts": dataclasses.asdict(self.behind_starts),
            "critic_warmup_iterations": self.fine_tune.critic_warmup_iterations,
            "critic_warmup_learning_rate": self.fine_tune.critic_warmup_learning_rate,
            "imitation_weight": tuple(self.fine_tune.imitation_weight),
            "keep_checkpoints": self.keep_checkpoints,
        }

