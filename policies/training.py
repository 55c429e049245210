"""What every task's training shares: PPO and network configs, the rsl_rl runner configuration, and the ``dynpush
train`` job (new run, resume, start from another run, SIGTERM). Config files and overrides live in
:mod:`~dynpush.policies.overrides`, the torchrun launch and its signals in :mod:`~dynpush.policies.processes`.

A task's training config (``train.TrainConfig`` for the push task, ``locomotion_train.LocomotionTrainConfig``)
holds its environment config and these shared parts, and says how to build its environment and its runner
configuration (:class:`TaskTrainConfig`); :func:`train` runs either. The paper gives no PPO hyper-parameters; the
defaults are rsl_rl's own (those of legged_gym / Isaac Lab locomotion tasks).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TypeVar

import torch

from dynpush.errors import MissingFileError
from dynpush.sim.config import ConfigError

from .actor import build_actor, load_onnx_actor
from .processes import ProcessGroup, sigterm_as_keyboard_interrupt
from .overrides import apply_overrides
from .run_folder import CONFIG, check_new_run, load_newest_readable, read_json, record_launch, write_config
from .runner import CaTOnPolicyRunner, TimeBudget
from .training_eval import PeriodicEvaluation

PRESETS = ("cpu", "paper")
T = TypeVar("T")  # a task's training config dataclass


class TaskTrainConfig(Protocol):
    """What :func:`train` needs of a task's training config (``TrainConfig``, ``LocomotionTrainConfig``)."""

    env: Any  # the task's environment config (num_envs, seed, device)
    iterations: int
    ppo: PPOConfig
    network: NetworkConfig

    def validate(self) -> TaskTrainConfig: ...

    def to_dict(self) -> dict: ...

    @staticmethod
    def from_dict(data: dict) -> TaskTrainConfig: ...

    def make_env(self, env: Any) -> Any: ...

    def runner_cfg(self) -> dict: ...

    def check_onnx_start(self, init_from: Path) -> None:
        """Raises a ConfigError when a new run of this config cannot start from the exported actor ``init_from``
        (``--init-from policy.onnx``), which holds no critic."""


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
    # A floor under the action noise (ours; 0: none). CaT prices constraint violations that the noise itself causes
    # (the arm's command and joint limits from the first iteration), so a learnt std can shrink before the task is
    # found (docs/ppo_fine_tuning.md); rsl_rl clamps the std parameter to it.
    min_noise_std: float = 0.0
    # Whether the actor's observation normaliser keeps its statistics (ours). None: held in a run that starts from
    # another policy (--init-from), whose weights were fitted to those statistics; re-normalising the inputs under
    # them changes what the actor does before any update (docs/ppo_fine_tuning.md). Fixed when the run is created.
    hold_actor_normalizer: bool | None = None

    def validate(self, prefix: str = "network") -> NetworkConfig:
        """Raises a ConfigError naming the first field out of its range."""
        if not self.init_noise_std > 0.0:
            raise ConfigError(f"{prefix}.init_noise_std must be > 0, got {self.init_noise_std!r}")
        if not 0.0 <= self.min_noise_std <= self.init_noise_std:
            raise ConfigError(f"{prefix}.min_noise_std must lie in [0, {prefix}.init_noise_std ="
                              f" {self.init_noise_std:g}], got {self.min_noise_std!r}")
        return self


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
                  "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": network.init_noise_std,
                                       "std_range": (network.min_noise_std, 1e6)}},
        "critic": {**mlp, "hidden_dims": list(network.critic_hidden)},
        "logger": "tensorboard",
        "check_for_nan": True,
    }


def train(cfg: TaskTrainConfig, run_dir: Path, resume: bool = False, command: str | None = None,
          resume_overrides: list[str] | tuple[str, ...] = (), init_from: Path | None = None, hours: float | None = None,
          started: float | None = None) -> CaTOnPolicyRunner:
    """Trains (or resumes) a push or locomotion policy (the task of ``cfg``'s type) into ``run_dir``; saves on
    Ctrl-C / SIGTERM.

    A new run needs a folder without a run in it; a resumed run uses its own ``config.json`` and its newest readable
    checkpoint; ``resume_overrides`` may change its length (``iterations=N`` in all; schedules that scale with the run
    length follow it), the PPO update's settings (``ppo.FIELD=VALUE``) and the curricula's thresholds
    (:func:`is_resumable`), written into its ``config.json`` and recorded with the launch's command. A new run with
    ``init_from`` (a checkpoint of another run with the same networks, e.g. its ``imitation.pt``) starts from that
    run's actor and critic with their normalisers; its optimizer (learning rate of ``cfg``), action noise
    (``cfg.network.init_noise_std``), CaT state, iteration count and episodes are its own. ``init_from`` may also
    be an exported push ``policy.onnx`` (e.g. the shipped one): the actor and its normaliser come from the file, the
    critic starts fresh and learns during ``fine_tune.critic_warmup_iterations`` (required) while the actor is held.
    Nothing is written into ``run_dir`` before all of these inputs have been read and checked
    (policies/run_folder.py).

    ``hours``: this launch ends at the last iteration boundary before ``hours`` from ``started`` (``time.time()``
    of the launch; default: now), with a checkpoint that ``--resume`` continues.

    Under torchrun every process runs one shard of ``cfg.env.num_envs`` worlds; gradients and
    normaliser statistics are averaged across processes (rsl_rl), rank 0 logs, evaluates and saves.
    """
    time_budget = None if hours is None else TimeBudget.of_hours(hours, time.time() if started is None else started)
    group = ProcessGroup.from_environment()
    cfg = run_config(cfg, run_dir, resume, resume_overrides)
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
    if group.rank == 0 and getattr(cfg, "eval_interval", 0):  # the push task's periodic evaluation
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


def run_config(cfg: T, run_dir: Path, resume: bool, resume_overrides: list[str] | tuple[str, ...] = ()) -> T:
    """The config a launch trains with, checked: ``cfg`` for a new run (whose folder must not hold a run), the run's
    own ``config.json`` with ``resume_overrides`` (fields that :func:`is_resumable` allows) for a resumed one."""
    if not resume:
        check_new_run(run_dir)
        return cfg.validate()
    config_path = run_dir / CONFIG
    if not config_path.exists():
        raise MissingFileError(f"--resume: no {config_path}; start the run without --resume first")
    fields = sorted({item.split("=", 1)[0].strip() for item in resume_overrides})
    fixed = [field for field in fields if not is_resumable(field)]
    if fixed:
        raise ConfigError(f"--resume continues the run's own config; only iterations, ppo.* (not "
                          f"ppo.returns_per_step), {NOISE_FLOOR}, {CONTACT_RULE} and CURRICULUM.promote_above / "
                          f".demote_below (CURRICULUM one of {', '.join(CURRICULA)}) may be set, got {fixed}")
    return apply_overrides(type(cfg).from_dict(read_json(config_path)), list(resume_overrides)).validate()


CURRICULA = ("curriculum", "mass_curriculum", "distance_curriculum", "behind_starts")
"""The success-gated training levels of :class:`~dynpush.policies.train.TrainConfig`."""

CONTACT_RULE = "env.constraints.contacts_at_step_end"
"""Which states of a step its collisions are read from: the credit CaT gives, not the physics or an input's layout."""

NOISE_FLOOR = "network.min_noise_std"
"""The floor under the action noise: rsl_rl clamps the learnt std to it when it samples, the weights stay as saved."""


def is_resumable(field: str) -> bool:
    """Whether ``--resume --set`` may change ``field`` (a dotted config path): the run's length, the PPO update's
    settings, the floor under the action noise (:data:`NOISE_FLOOR`), the success rates at which the curricula move
    (``<curriculum>.promote_above`` and ``.demote_below``) and which states of a step its collisions are read from
    (:data:`CONTACT_RULE`), the learning loop; the environment, the networks' layout, the other constraints and the
    levels' steps stay as the run started.
    ``ppo.returns_per_step`` stays too: it changes the units of the values the critic has learnt."""
    section, _, name = field.partition(".")
    if section == "ppo":
        return name != "returns_per_step"
    return (field in ("iterations", NOISE_FLOOR, CONTACT_RULE)
            or (section in CURRICULA and name in ("promote_above", "demote_below")))


def read_onnx_actor(cfg: TaskTrainConfig, init_from: Path | None) -> torch.nn.Module | None:
    """The actor of an exported ``policy.onnx`` that a new run starts from (``init_from``), checked against ``cfg``;
    None when ``init_from`` is not an ONNX file."""
    if init_from is None or init_from.suffix != ".onnx":
        return None
    cfg.check_onnx_start(init_from)
    actor = build_actor(cfg)
    load_onnx_actor(actor, init_from)
    return actor


def start_from(runner: CaTOnPolicyRunner, cfg: TaskTrainConfig, run_dir: Path, resume: bool,
               init_from: Path | None, onnx_actor: torch.nn.Module | None, group: ProcessGroup) -> None:
    """Loads what the run starts from into ``runner``: its newest readable checkpoint (``resume``; one line says
    which newer ones were unreadable), another run's actor and critic (``init_from`` checkpoint) or an exported
    actor (``onnx_actor``); then holds the actor's normaliser if the config says so."""
    if resume:
        # Each process continues its own episodes where the checkpoint holds them (CaTOnPolicyRunner.restore_processes).
        checkpoint, skipped = load_newest_readable(run_dir, lambda path: runner.load(str(path)))
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


def set_action_std(actor: torch.nn.Module, std: float) -> None:
    """Sets the standard deviation of ``actor``'s Gaussian action distribution (every action) to ``std``; the
    distribution is rsl_rl's with a scalar std parameter (``rsl_rl_runner_cfg``)."""
    with torch.no_grad():
        actor.distribution.std_param.fill_(std)


def hold_normalizer(model: torch.nn.Module) -> None:
    """Stops the updates of ``model``'s empirical observation normaliser (rsl_rl's ``until`` count), so its
    statistics stay those it has now."""
    model.obs_normalizer.until = 0


