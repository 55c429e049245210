"""Training configuration, presets and the ``dynpush train`` job.

The paper gives no PPO hyper-parameters; the defaults are rsl_rl's own (those of legged_gym /
Isaac Lab locomotion tasks). The ``paper`` preset is the paper's scale (4096 environments, 20000
iterations, III-A) on a GPU; the ``cpu`` preset is sized for a 2-core laptop-class machine.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import json
import os
import signal
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import torch

from dynpush.sim.config import ConfigError, PushEnvConfig

from dynpush.kernels.constraints import CONSTRAINT_GROUPS

from .curriculum import GoalCurriculumConfig
from .runner import CaTOnPolicyRunner
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
        if self.ppo.schedule not in ("adaptive", "fixed"):
            raise ConfigError(f"ppo.schedule must be 'adaptive' or 'fixed', got {self.ppo.schedule!r}")
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
        setattr(target, leaf, value)
    return cfg


def scripted_expert(object_size: float | None, overrides: tuple[str, ...], name: str) -> ScriptedPusherConfig:
    """The scripted pusher's config for imitation: ``object_size`` (None: the true size) and then ``overrides``
    (FIELD=VALUE of ScriptedPusherConfig) on its defaults, checked; errors name the config field ``name``."""
    try:
        cfg = apply_overrides(ScriptedPusherConfig(object_size=object_size), list(overrides))
        cfg.validate()
    except ConfigError as error:
        raise ConfigError(f"{name}: {error}") from None
    return cfg


IMITATION_CHECKPOINT = "imitation.pt"  # written by dynpush imitate; CaT-PPO starts from it


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The run's ``model_K.pt`` with the largest K; before the first one, its imitation checkpoint (if any)."""
    checkpoints = sorted(run_dir.glob("model_*.pt"), key=lambda p: int(p.stem.split("_")[1]))
    if checkpoints:
        return checkpoints[-1]
    return run_dir / IMITATION_CHECKPOINT if (run_dir / IMITATION_CHECKPOINT).exists() else None


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
          extend_to: int | None = None, init_from: Path | None = None) -> CaTOnPolicyRunner:
    """Trains (or resumes) a push or locomotion policy (the task of ``cfg``'s type) into ``run_dir``; saves on
    Ctrl-C / SIGTERM.

    A resumed run uses its own ``config.json``; ``extend_to`` changes its length to that many
    iterations in all (schedules that scale with the run length follow the new length). A new run with
    ``init_from`` (a checkpoint of another run with the same networks, e.g. its ``imitation.pt``) starts from
    that run's actor and critic with their normalisers; its optimizer (learning rate of ``cfg``), action noise
    (``cfg.network.init_noise_std``), CaT state, iteration count and episodes are its own. ``init_from`` may also be
    an exported push ``policy.onnx`` (e.g. the shipped one): the actor and its normaliser come from the file, the
    critic starts fresh and learns during ``critic_warmup_iterations`` (required) while the actor is held.

    Under torchrun every process runs one shard of ``cfg.env.num_envs`` worlds; gradients and
    normaliser statistics are averaged across processes (rsl_rl), rank 0 logs and saves.
    """
    group = ProcessGroup.from_environment()
    config_path = run_dir / "config.json"
    if resume:
        if not config_path.exists():
            raise FileNotFoundError(f"--resume: no {config_path}; start the run without --resume first")
        cfg = type(cfg).from_dict(json.loads(config_path.read_text()))
        if extend_to is not None:
            cfg.iterations = extend_to
    cfg.validate()
    if init_from is not None and init_from.suffix == ".onnx" and not isinstance(cfg, TrainConfig):
        raise ConfigError(f"--init-from {init_from}: an ONNX file can start a push run only; a locomotion run starts"
                          " from a checkpoint (model_K.pt)")
    if init_from is not None and init_from.suffix == ".onnx" and not cfg.critic_warmup_iterations:
        raise ConfigError(f"--init-from {init_from}: an ONNX file holds the actor only; set critic_warmup_iterations > 0"
                          " (e.g. 60) so that the new critic learns the returns before the actor is trained")
    onnx_actor = None
    if init_from is not None and init_from.suffix == ".onnx":  # read before anything is written: a mismatch loses nothing
        from .export import build_actor, load_onnx_actor

        onnx_actor = build_actor(cfg)
        load_onnx_actor(onnx_actor, init_from)
    if cfg.network.hold_actor_normalizer is None:
        cfg.network.hold_actor_normalizer = init_from is not None
    if group.rank == 0:
        run_dir.mkdir(parents=True, exist_ok=True)
        config_path.write_text(json.dumps(cfg.to_dict(), indent=2))
        record_launch(run_dir, command, group.world_size, resume, init_from)
    if cfg.env.device == "cpu":
        torch.set_num_threads(1)  # one core per process: Warp launches already use one

    torch.manual_seed(cfg.env.seed + group.rank)
    env = cfg.make_env(group.shard(cfg.env))
    log_dir = str(run_dir) if group.rank == 0 else None
    runner = CaTOnPolicyRunner(env, cfg.runner_cfg(), log_dir=log_dir, device=env.device)
    if resume:
        checkpoint = latest_checkpoint(run_dir)
        if checkpoint is None:
            raise FileNotFoundError(f"--resume: no model_*.pt in {run_dir}")
        runner.load(str(checkpoint), restore_env=group.world_size == 1)
    elif onnx_actor is not None:
        runner.alg.actor.load_state_dict(onnx_actor.state_dict())
        set_action_std(runner.alg.actor, cfg.network.init_noise_std)
    elif init_from is not None:
        runner.load(str(init_from), load_cfg={"actor": True, "critic": True}, restore_env=False)
        set_action_std(runner.alg.actor, cfg.network.init_noise_std)
    if cfg.network.hold_actor_normalizer:
        hold_normalizer(runner.alg.actor)
    remaining = cfg.iterations - runner.current_learning_iteration
    if remaining <= 0:
        print(f"{run_dir}: all {cfg.iterations} iterations done")
        return runner

    try:
        with sigterm_as_keyboard_interrupt():
            runner.learn(remaining, total_iterations=cfg.iterations)
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


def source_commit() -> str | None:
    """The git commit of the dynpush sources (with ``-dirty`` when they have uncommitted changes), or None."""
    import subprocess

    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root, capture_output=True,
                               text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return commit + ("-dirty" if dirty else "")


def set_action_std(actor: torch.nn.Module, std: float) -> None:
    """Sets the standard deviation of ``actor``'s Gaussian action distribution (every action) to ``std``; the
    distribution is rsl_rl's with a scalar std parameter (``rsl_rl_runner_cfg``)."""
    with torch.no_grad():
        actor.distribution.std_param.fill_(std)


def hold_normalizer(model: torch.nn.Module) -> None:
    """Stops the updates of ``model``'s empirical observation normaliser (rsl_rl's ``until`` count), so its
    statistics stay those it has now."""
    model.obs_normalizer.until = 0


def record_launch(run_dir: Path, command: str | None, procs: int, resume: bool, init_from: Path | None = None) -> None:
    """Appends this launch (the ``dynpush train`` command line, processes, commit, time and the checkpoint a new
    run started from) to ``launches.jsonl``."""
    import time

    record = {"command": command, "processes": procs, "resume": resume, "commit": source_commit(),
              "torch": torch.__version__, "time": time.time()}
    if init_from is not None:
        record["init_from"] = str(Path(init_from).resolve())
    with open(run_dir / "launches.jsonl", "a") as f:
        f.write(json.dumps(record) + "\n")


def launch_processes(procs: int, argv: list[str]) -> int:
    """Re-runs ``dynpush train`` under torchrun with ``procs`` processes on this machine."""
    import subprocess
    import sys

    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc_per_node={procs}",
               "-m", "dynpush", "train", *argv]
    return subprocess.call(command)
