"""Training configuration, presets and the ``dynpush train`` job.

The paper gives no PPO hyper-parameters; the defaults are rsl_rl's own (those of legged_gym /
Isaac Lab locomotion tasks). The ``paper`` preset is the paper's scale (4096 environments, 20000
iterations, III-A) on a GPU; the ``cpu`` preset is sized for a 2-core laptop-class machine.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import os
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import torch

from dynpush.errors import MissingFileError
from dynpush.sim.config import ConfigError, PushEnvConfig

from dynpush.kernels.constraints import CONSTRAINT_GROUPS

from .curriculum import GoalCurriculumConfig
from .run_folder import CONFIG, check_new_run, load_newest_readable, record_launch, write_config
from .runner import CaTOnPolicyRunner, TimeBudget
from .scripted import ScriptedPusherConfig, check_object_size
from .schedules import ConstraintCurriculumConfig

if TYPE_CHECKING:
    from dynpush.sim.locomotion_config import LocomotionEnvConfig

    from .locomotion_train import LocomotionTrainConfig

PRESETS = ("cpu", "paper")
T = TypeVar("T")  # a config dataclass


@dataclass
class PPOConfig:
    """rsl_rl PPO arguments (rsl_rl defaults; the paper gives none)."""

    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    clip_param: float = 0.2
    gamma: float = 0.99
    lam: float = 0.95
    value_loss_coef: float = 1.0
    entropy_coef: float = 0.005
    learning_rate: float = 1.0e-3
    max_grad_norm: float = 1.0
    schedule: str = "adaptive"
    desired_kl: float = 0.01
    # Ours: the critic learns values in reward-per-step units (rewards stored times 1 - gamma), which keeps the
    # returns within reach of rsl_rl's value clip (policies/cat_ppo.py).
    returns_per_step: bool = True

    def validate(self) -> PPOConfig:
        """Raises a ConfigError naming the first field out of its range."""
        for name, low, high in (("learning_rate", 0.0, 1.0), ("gamma", 0.0, 1.0), ("lam", 0.0, 1.0)):
            if not low < getattr(self, name) <= high:
                raise ConfigError(f"ppo.{name} must lie in ({low:g}, {high:g}], got {getattr(self, name)!r}")
        for name in ("clip_param", "desired_kl"):
            if not getattr(self, name) > 0.0:
                raise ConfigError(f"ppo.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("num_learning_epochs", "num_mini_batches"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(f"ppo.{name} must be an integer >= 1, got {getattr(self, name)!r}")
        if not self.entropy_coef >= 0.0:
            raise ConfigError(f"ppo.entropy_coef must be >= 0, got {self.entropy_coef!r}")
        if self.schedule not in ("adaptive", "fixed"):
            raise ConfigError(f"ppo.schedule must be 'adaptive' or 'fixed', got {self.schedule!r}")
        return self


@dataclass
class NetworkConfig:
    """Asymmetric actor-critic MLPs (paper III-C) with ELU and empirical observation normalisation."""

    actor_hidden: tuple[int, ...] = (256, 128, 64)
    critic_hidden: tuple[int, ...] = (256, 128, 64)
    init_noise_std: float = 1.0
    # Whether the actor's observation normaliser keeps its statistics (ours). None: held in a run that starts from
    # another policy (--init-from), whose weights were fitted to those statistics; re-normalising the inputs under
    # them changes what the actor does before any update (docs/ppo_fine_tuning.md). Fixed when the run is created.
    hold_actor_normalizer: bool | None = None


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
    # Iterations at the start of the run in which only the critic learns and the actor is held (ours): for
    # runs that start from a ``dynpush imitate`` checkpoint, whose critic has not learnt the returns yet.
    critic_warmup_iterations: int = 0
    # Learning rate of those warm-up iterations (ours; None: ppo.learning_rate); the run's takes over with the actor.
    # From bc9 at 1e-4 the critic explained 7-14 % of the variance of the returns after 30 iterations, at 1e-3 52-64 %
    # after 40-74 (README, "Where the fine-tunings lose it").
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
        from dynpush.sim.push_env import make_push_env

        from .expert_regularization import ExpertLabelledEnv

        if max(self.imitation_weight) == 0:
            return make_push_env(env)
        return ExpertLabelledEnv(make_push_env(env), scripted_expert(self.expert_object_size, self.expert_overrides,
                                                                    "expert_overrides"))

    @staticmethod
    def from_dict(data: dict) -> TrainConfig:
        return _from_dict(TrainConfig, data)

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
            "critic_warmup_iterations": self.critic_warmup_iterations,
            "critic_warmup_learning_rate": self.critic_warmup_learning_rate,
            "imitation_weight": tuple(self.imitation_weight),
            "keep_checkpoints": self.keep_checkpoints,
        }


def rsl_rl_runner_cfg(num_steps_per_env: int, save_interval: int, ppo: PPOConfig, network: NetworkConfig) -> dict:
    """What every task's rsl_rl runner configuration has: rollout length, PPO, asymmetric actor-critic MLPs with
    ELU and empirical normalisation, tensorboard, NaN checks."""
    mlp = {"class_name": "MLPModel", "activation": "elu", "obs_normalization": True}
    return {
        "num_steps_per_env": num_steps_per_env,
        "save_interval": save_interval,
        "obs_groups": {"actor": ["policy"], "critic": ["critic"]},
        "algorithm": dataclasses.asdict(ppo),
        "actor": {**mlp, "hidden_dims": list(network.actor_hidden),
                  "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": network.init_noise_std}},
        "critic": {**mlp, "hidden_dims": list(network.critic_hidden)},
        "logger": "tensorboard",
        "check_for_nan": True,
    }


def _from_dict(cls, data: dict):
    kwargs = {}
    names = {f.name: f for f in dataclasses.fields(cls)}
    for key, value in data.items():
        if key not in names:
            raise ConfigError(f"unknown config field {cls.__name__}.{key}; allowed: {sorted(names)}")
        default = getattr(cls(), key)
        if dataclasses.is_dataclass(default):
            value = _from_dict(type(default), value)
        elif isinstance(default, tuple):
            value = tuple(value)
        kwargs[key] = value
    return cls(**kwargs)


def apply_overrides(cfg: T, overrides: list[str]) -> T:
    """Applies ``dotted.field=value`` overrides to a config dataclass (values parsed as Python literals, else strings)."""
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override must look like field.path=value, got {item!r}")
        path, text = item.split("=", 1)
        target = cfg
        keys = path.split(".")
        for key in keys[:-1]:
            if not hasattr(target, key) or not dataclasses.is_dataclass(getattr(target, key)):
                raise ConfigError(f"unknown config section {path!r}")
            target = getattr(target, key)
        leaf = keys[-1]
        if not dataclasses.is_dataclass(target) or leaf not in {f.name for f in dataclasses.fields(target)}:
            raise ConfigError(f"unknown config field {path!r}")
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            value = text
        current = getattr(target, leaf)
        expected = f"of type {type(current).__name__}"
        allowed = [type(current).__name__]
        if current is None or value is None:  # an optional field, e.g. ``float | None``: its annotation's types
            annotation = str(next(f.type for f in dataclasses.fields(target) if f.name == leaf))
            allowed = [name.strip() for name in annotation.split("|")]
            expected = annotation if current is None else expected
        if "float" in allowed and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(current, tuple) and isinstance(value, list):
            value = tuple(value)
        if ("None" if value is None else type(value).__name__) not in allowed:
            raise ConfigError(f"{path} must be {expected}, got {text!r}")
        if isinstance(current, tuple) and current:
            value = tuple_like(path, current, value, text)
        setattr(target, leaf, value)
    return cfg


def tuple_like(path: str, current: tuple, value: tuple, text: str) -> tuple:
    """``value`` with the element type of the default ``current`` (ints become floats in a tuple of floats); a
    ConfigError naming ``path`` when an element has another type."""
    kind = type(current[0])
    if kind is float:
        value = tuple(float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value)
    if not all(type(v) is kind for v in value):
        raise ConfigError(f"{path} must be a tuple of {kind.__name__}, got {text!r}")
    return value


def scripted_expert(object_size: float | None, overrides: tuple[str, ...], name: str) -> ScriptedPusherConfig:
    """The scripted pusher's config for imitation: ``object_size`` (None: the true size) and then ``overrides``
    (FIELD=VALUE of ScriptedPusherConfig) on its defaults, checked; errors name the config field ``name``."""
    try:
        cfg = apply_overrides(ScriptedPusherConfig(object_size=object_size), list(overrides))
        cfg.validate()
    except ConfigError as error:
        raise ConfigError(f"{name}: {error}") from None
    return cfg


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
            raise ConfigError(f"env.num_envs ({env.num_envs}) must be divisible by the number of processes ({self.world_size})")
        return dataclasses.replace(env, num_envs=env.num_envs // self.world_size, seed=env.seed + self.rank)


def train(cfg: TrainConfig | LocomotionTrainConfig, run_dir: Path, resume: bool = False, command: str | None = None,
          extend_to: int | None = None, init_from: Path | None = None, hours: float | None = None,
          started: float | None = None) -> CaTOnPolicyRunner:
    """Trains (or resumes) a push or locomotion policy (the task of ``cfg``'s type) into ``run_dir``; saves on
    Ctrl-C / SIGTERM.

    A new run needs a folder without a run in it; a resumed run uses its own ``config.json`` and its newest readable
    checkpoint; ``extend_to`` changes its length to that many iterations in all (schedules that scale with the run
    length follow the new length). A new run with ``init_from`` (a checkpoint of another run with the same networks,
    e.g. its ``imitation.pt``) starts from that run's actor and critic with their normalisers; its optimizer
    (learning rate of ``cfg``), action noise (``cfg.network.init_noise_std``), CaT state, iteration count and
    episodes are its own. ``init_from`` may also be an exported push ``policy.onnx`` (e.g. the shipped one): the
    actor and its normaliser come from the file, the critic starts fresh and learns during
    ``critic_warmup_iterations`` (required) while the actor is held. Nothing is written into ``run_dir`` before all
    of these inputs have been read and checked (policies/run_folder.py).

    ``hours``: this launch ends at the last iteration boundary before ``hours`` from ``started`` (``time.time()``
    of the launch; default: now), with a checkpoint that ``--resume`` continues.

    Under torchrun every process runs one shard of ``cfg.env.num_envs`` worlds; gradients and
    normaliser statistics are averaged across processes (rsl_rl), rank 0 logs, evaluates and saves.
    """
    time_budget = None if hours is None else TimeBudget.of_hours(hours, time.time() if started is None else started)
    group = ProcessGroup.from_environment()
    cfg = run_config(cfg, run_dir, resume, extend_to)
    onnx_actor = read_onnx_actor(cfg, init_from)
    if cfg.network.hold_actor_normalizer is None:
        cfg.network.hold_actor_normalizer = init_from is not None
    if cfg.env.device == "cpu":
        torch.set_num_threads(1)  # one core per process: Warp launches already use one

    torch.manual_seed(cfg.env.seed + group.rank)
    env = cfg.make_env(group.shard(cfg.env))
    log_dir = str(run_dir) if group.rank == 0 else None
    runner = CaTOnPolicyRunner(env, cfg.runner_cfg(), log_dir=log_dir, device=env.device)
    start_from(runner, cfg, run_dir, resume, init_from, onnx_actor, group)
    if group.rank == 0 and isinstance(cfg, TrainConfig) and cfg.eval_interval:
        from .training_eval import PeriodicEvaluation

        runner.evaluation = PeriodicEvaluation(cfg, run_dir)
    if group.rank == 0:
        write_config(run_dir, cfg.to_dict())
        record_launch(run_dir, command, group.world_size, resume, init_from)
    remaining = cfg.iterations - runner.current_learning_iteration
    if remaining <= 0:
        print(f"{run_dir}: all {cfg.iterations} iterations done")
        return runner

    try:
        with sigterm_as_keyboard_interrupt():
            runner.learn(remaining, total_iterations=cfg.iterations, time_budget=time_budget)
    except KeyboardInterrupt:
        if group.rank == 0:
            path = runner.save_interrupted()
            print(f"\ninterrupted: saved {path}; continue with --resume")
    finally:
        # gloo's threads must stop before the interpreter exits: left running, a process of a finished run
        # aborted at exit ("terminate called without an active exception") and torchrun reported the run failed.
        if torch.distributed.is_initialized():
            torch.distributed.destroy_process_group()
    return runner


def run_config(cfg: T, run_dir: Path, resume: bool, extend_to: int | None) -> T:
    """The config a launch trains with, checked: ``cfg`` for a new run (whose folder must not hold a run), the run's
    own ``config.json`` for a resumed one (``extend_to``: its new length in iterations)."""
    if not resume:
        check_new_run(run_dir)
        return cfg.validate()
    from .export import read_json

    config_path = run_dir / CONFIG
    if not config_path.exists():
        raise MissingFileError(f"--resume: no {config_path}; start the run without --resume first")
    cfg = type(cfg).from_dict(read_json(config_path))
    if extend_to is not None:
        cfg.iterations = extend_to
    return cfg.validate()


def read_onnx_actor(cfg: TrainConfig | LocomotionTrainConfig, init_from: Path | None) -> torch.nn.Module | None:
    """The actor of an exported ``policy.onnx`` that a new run starts from (``init_from``), checked against ``cfg``;
    None when ``init_from`` is not an ONNX file."""
    if init_from is None or init_from.suffix != ".onnx":
        return None
    if not isinstance(cfg, TrainConfig):
        raise ConfigError(f"--init-from {init_from}: an ONNX file can start a push run only; a locomotion run starts"
                          " from a checkpoint (model_K.pt)")
    if not cfg.critic_warmup_iterations:
        raise ConfigError(f"--init-from {init_from}: an ONNX file holds the actor only; set critic_warmup_iterations > 0"
                          " (e.g. 60) so that the new critic learns the returns before the actor is trained")
    from .export import build_actor, load_onnx_actor

    actor = build_actor(cfg)
    load_onnx_actor(actor, init_from)
    return actor


def start_from(runner: CaTOnPolicyRunner, cfg: TrainConfig | LocomotionTrainConfig, run_dir: Path, resume: bool,
               init_from: Path | None, onnx_actor: torch.nn.Module | None, group: ProcessGroup) -> None:
    """Loads what the run starts from into ``runner``: its newest readable checkpoint (``resume``; one line says
    which newer ones were unreadable), another run's actor and critic (``init_from`` checkpoint) or an exported
    actor (``onnx_actor``); then holds the actor's normaliser if the config says so."""
    if resume:
        # A run resumed with another number of processes cannot restore the saved shard: fresh episodes.
        checkpoint, skipped = load_newest_readable(
            run_dir, lambda path: runner.load(str(path), restore_env=group.world_size == 1))
        if skipped and group.rank == 0:
            print(f"--resume: skipped unreadable {', '.join(skipped)}; resuming from {checkpoint.name}")
    elif onnx_actor is not None:
        runner.alg.actor.load_state_dict(onnx_actor.state_dict())
        set_action_std(runner.alg.actor, cfg.network.init_noise_std)
    elif init_from is not None:
        runner.load(str(init_from), load_cfg={"actor": True, "critic": True}, restore_env=False)
        set_action_std(runner.alg.actor, cfg.network.init_noise_std)
    if cfg.network.hold_actor_normalizer:
        hold_normalizer(runner.alg.actor)


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


def set_action_std(actor: torch.nn.Module, std: float) -> None:
    """Sets the standard deviation of ``actor``'s Gaussian action distribution (every action) to ``std``; the
    distribution is rsl_rl's with a scalar std parameter (``rsl_rl_runner_cfg``)."""
    with torch.no_grad():
        actor.distribution.std_param.fill_(std)


def hold_normalizer(model: torch.nn.Module) -> None:
    """Stops the updates of ``model``'s empirical observation normaliser (rsl_rl's ``until`` count), so its
    statistics stay those it has now."""
    model.obs_normalizer.until = 0


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
