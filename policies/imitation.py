"""Expert-guided initialisation: DAgger from the scripted pusher into the training run's actor.

A lever for short CPU budgets (not in the paper, which trains from scratch): CaT-PPO from a random actor
does not discover goal-directed pushing within tens of millions of world-steps, while the scripted
pusher (:mod:`dynpush.policies.scripted`, which reads the true state) pushes from the first step. DAgger
(Ross et al., 2011) distils it into the policy the run trains:

- round ``r`` rolls out ``steps_per_round`` control steps of every world of the training environment
  (training distribution, observation noise on); a world is driven by the expert with probability
  ``expert_share ** r`` (drawn per world and round), otherwise by the actor's deterministic mean, and the
  executed actions get the Gaussian noise of the run's initial action std (``network.init_noise_std``;
  DART, Laskey et al., 2017): the data then covers the states the noisy CaT-PPO rollouts visit, and the
  observation normaliser the spread of, e.g., arm joints that the expert alone holds still; every visited
  state is labelled with the expert's (noise-free) action;
- the actor (the run's own MLP with its observation normaliser) is fitted to all labelled states so far
  (the newest ``max_samples``) by mean squared error of its mean action, ``epochs`` passes per round.

The result is the run's ``imitation.pt``, a training checkpoint at iteration 0 (the run's latest
checkpoint until CaT-PPO saves ``model_K.pt``), so ``dynpush export`` reads it as any checkpoint and
``dynpush train --resume`` fine-tunes it with CaT-PPO. Each round appends its figures (episodes that
ended, their success and toppled rates, the loss, world-steps and seconds) to ``imitation.jsonl``; an
interrupted job (Ctrl-C or SIGTERM) keeps the rounds it finished and ``--resume`` continues after them
(the aggregated data set is saved with each round).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import torch
from tqdm import tqdm

from dynpush.errors import MissingFileError
from dynpush.sim.config import ConfigError

from .checkpoint_file import read_checkpoint
from .scripted import ScriptedPusher, ScriptedPusherConfig, check_object_size
from .run_folder import IMITATION_CHECKPOINT, read_json, read_run_config, record_launch
from .fine_tune import scripted_expert
from .train import TrainConfig
from .processes import sigterm_as_keyboard_interrupt


@dataclass
class ImitationConfig:
    """DAgger settings (ours)."""

    rounds: int = 8
    steps_per_round: int = 250  # control steps of every world per round (5 s)
    expert_share: float = 0.5  # a world follows the expert with probability expert_share ** round
    epochs: int = 4  # passes over the aggregated data per round
    batch_size: int = 4096
    learning_rate: float = 1.0e-3
    max_samples: int = 3_000_000  # newest labelled states kept
    # m: None, the expert reads the object's true size, shape and centre of mass; a number, it assumes a cuboid
    # of that edge (ScriptedPusherConfig.object_size) and acts on what the student observes too
    expert_object_size: float | None = None
    expert_overrides: tuple[str, ...] = ()  # more expert gains, FIELD=VALUE of ScriptedPusherConfig, after the size

    def validate(self) -> ImitationConfig:
        for name in ("rounds", "steps_per_round", "epochs", "batch_size", "max_samples"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"imitation.{name} must be an integer >= 1, got {value!r}")
        if not 0.0 <= self.expert_share <= 1.0:
            raise ConfigError(f"imitation.expert_share must lie in [0, 1], got {self.expert_share!r}")
        if not self.learning_rate > 0.0:
            raise ConfigError(f"imitation.learning_rate must be > 0, got {self.learning_rate!r}")
        check_object_size("imitation.expert_object_size", self.expert_object_size)
        self.expert()
        return self

    def expert(self) -> ScriptedPusherConfig:
        """The DAgger expert's config: the scripted pusher with ``expert_object_size`` and ``expert_overrides``."""
        return scripted_expert(self.expert_object_size, self.expert_overrides, "imitation.expert_overrides")


class Dagger:
    """The DAgger loop of the module docstring on one environment and one runner's actor."""

    def __init__(self, env, actor: torch.nn.Module, cfg: ImitationConfig, action_noise_std: float, seed: int = 0):
        self.env, self.actor, self.cfg, self.action_noise_std = env, actor, cfg, action_noise_std
        self.expert = ScriptedPusher(env, cfg.expert())
        self.optimizer = torch.optim.Adam(actor.mlp.parameters(), lr=cfg.learning_rate)
        self.generator = torch.Generator().manual_seed(seed)
        self.observations = torch.zeros(0, env.policy_obs_t.shape[1])
        self.labels = torch.zeros(0, env.num_actions)

    def collect(self, round_index: int, progress: tqdm | None = None) -> dict:
        """Rolls out one round and adds its labelled states; returns the round's episode figures."""
        env, n = self.env, self.env.num_envs
        expert_drives = torch.rand(n, generator=self.generator) < self.cfg.expert_share**round_index
        observations = env.get_observations()
        new_obs, new_labels = [], []
        ended = succeeded = toppled = 0
        for _ in range(self.cfg.steps_per_round):
            expert_actions = torch.from_numpy(self.expert(None))
            with torch.no_grad():
                self.actor.update_normalization(observations)
                student_actions = self.actor(observations)
            new_obs.append(observations["policy"].clone())
            new_labels.append(expert_actions)
            actions = torch.where(expert_drives[:, None], expert_actions, student_actions)
            actions += self.action_noise_std * torch.randn(actions.shape, generator=self.generator)
            observations = env.step(actions)[0]
            done = env.reset_t != 0
            ended += int(done.sum())
            succeeded += int((env.episode_success_t[done] == 1).sum())
            toppled += int((env.episode_toppled_t[done] == 1).sum())
            if progress is not None:
                progress.update(n)
        self.observations = torch.cat([self.observations, *new_obs])[-self.cfg.max_samples:]
        self.labels = torch.cat([self.labels, *new_labels])[-self.cfg.max_samples:]
        return {"episodes_ended": ended, "success_rate": succeeded / max(ended, 1), "toppled_rate": toppled / max(ended, 1),
                "expert_worlds": int(expert_drives.sum()), "student_worlds": int((~expert_drives).sum())}

    def fit(self) -> float:
        """``epochs`` passes of mean-squared-error regression of the actor's mean on the labels; the last pass's loss."""
        count = self.observations.shape[0]
        for _ in range(self.cfg.epochs):
            order = torch.randperm(count, generator=self.generator)
            loss_sum, batches = 0.0, 0
            for start in range(0, count, self.cfg.batch_size):
                index = order[start:start + self.cfg.batch_size]
                predicted = self.actor.mlp(self.actor.obs_normalizer(self.observations[index]))
                loss = torch.nn.functional.mse_loss(predicted, self.labels[index])
                self.optimizer.zero_grad()
                loss.backward()
                self.optimizer.step()
                loss_sum, batches = loss_sum + loss.item(), batches + 1
            loss_sum /= batches
        return loss_sum

    def state_dict(self) -> dict:
        return {"observations": self.observations, "labels": self.labels, "optimizer": self.optimizer.state_dict(),
                "generator": self.generator.get_state()}

    def load_state_dict(self, state: dict) -> None:
        self.observations, self.labels = state["observations"], state["labels"]
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])


def imitate(cfg: TrainConfig, imitation: ImitationConfig, run_dir: Path, resume: bool = False,
            command: str | None = None) -> Path:
    """Runs DAgger into ``run_dir`` (see the module docstring); returns the path of ``imitation.pt``."""
    from dynpush.sim.push_env import PushEnv

    from .runner import CaTOnPolicyRunner

    imitation.validate()
    config_path, log_path, data_path = run_dir / "config.json", run_dir / "imitation.jsonl", run_dir / "imitation_data.pt"
    checkpoint = run_dir / IMITATION_CHECKPOINT
    if resume:
        if not data_path.exists():
            raise MissingFileError(f"--resume: no {data_path}; start without --resume first")
        cfg = TrainConfig.from_dict(read_run_config(run_dir))  # DAgger trains the push task only
        # The data set was labelled by the run's expert: keep it (configs older than the field had the true sizes).
        saved_imitation = read_json(run_dir / "imitation_config.json")
        imitation = replace(imitation, expert_object_size=saved_imitation.get("expert_object_size"),
                            expert_overrides=tuple(saved_imitation.get("expert_overrides", ())))
    elif config_path.exists():
        raise FileExistsError(f"{run_dir} holds a run already; choose another --name or pass --resume")
    cfg.validate()
    run_dir.mkdir(parents=True, exist_ok=True)
    config_path.write_text(json.dumps(cfg.to_dict(), indent=2))
    (run_dir / "imitation_config.json").write_text(json.dumps(asdict(imitation), indent=2))
    record_launch(run_dir, command, 1, resume)
    if cfg.env.device == "cpu":
        torch.set_num_threads(1)
    torch.manual_seed(cfg.env.seed)

    env = PushEnv(cfg.env)
    runner = CaTOnPolicyRunner(env, cfg.runner_cfg(), log_dir=None, device=env.device)
    dagger = Dagger(env, runner.alg.actor, imitation, cfg.network.init_noise_std, seed=cfg.env.seed)
    first_round = 0
    if resume:
        runner.load(str(checkpoint), restore_env=False)
        saved = read_checkpoint(data_path, map_location=None)
        dagger.load_state_dict(saved["dagger"])
        first_round = saved["rounds_done"]

    total = (imitation.rounds - first_round) * imitation.steps_per_round * env.num_envs
    try:
        with sigterm_as_keyboard_interrupt(), tqdm(total=total, unit="world-steps", desc="DAgger", smoothing=0.1) as progress:
            for round_index in range(first_round, imitation.rounds):
                start = time.perf_counter()
                figures = dagger.collect(round_index, progress)
                figures |= {"round": round_index, "samples": int(dagger.labels.shape[0]), "loss": dagger.fit(),
                            "world_steps": imitation.steps_per_round * env.num_envs,
                            "seconds": time.perf_counter() - start}
                tqdm.write(json.dumps(figures))
                with open(log_path, "a") as f:
                    f.write(json.dumps(figures) + "\n")
                torch.save(runner.training_state(next_iteration=0), checkpoint)
                torch.save({"dagger": dagger.state_dict(), "rounds_done": round_index + 1}, data_path)
    except KeyboardInterrupt:
        print(f"\ninterrupted: {checkpoint} holds the last finished round; continue with --resume")
    return checkpoint
