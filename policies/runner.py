"""On-policy runner for CaT-PPO: rsl_rl's OnPolicyRunner plus the push task's iteration schedules.

rsl_rl's learning loop is used unchanged. :class:`~dynpush.policies.cat_ppo.CaTPPO` reads ``extras["constraints"]`` in
its ``process_env_step`` and adds its statistics to the extras that rsl_rl's logger averages per iteration
(``CaT/mean_delta``, ``CaT/violation_rate/<group>``, ``CaT/delta/<group>``). This runner builds CaT-PPO and, at the
start of every iteration, applies the ``p_max`` curricula and the reach-reward weight
(:mod:`dynpush.policies.schedules`) and keeps a snapshot of the training state, so that an interrupted run saves the
last iteration boundary. Checkpoints also hold every process's environment state and RNG state, so a resumed run
continues exactly as an uninterrupted one. At an iteration boundary it also evaluates the actor when an evaluation is due
(``evaluation``), and a launch with a :class:`TimeBudget` ends there, with a checkpoint, when the next iteration would
not end in time.
"""

from __future__ import annotations

import copy
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner

from dynpush.policies.cat_ppo import CaTPPO
from dynpush.policies.checkpoint_file import CheckpointError, read_checkpoint
from dynpush.policies.curriculum import (
    BehindStartConfig, GoalCurriculumConfig, GoalDistanceCurriculumConfig, NearGoalStartConfig,
    ObjectMassCurriculumConfig, SuccessGatedLevel,
)
from dynpush.policies.progress import ProgressLogger
from dynpush.policies.expert_regularization import ExpertImitationLoss
from dynpush.policies.run_folder import save_checkpoint
from dynpush.policies.schedules import (
    ScheduleConfig, disturbance_scale_at, imitation_weight_at, p_max_at, p_max_at_progress, reach_weight_at,
)


@dataclass
class TimeBudget:
    """The wall-clock time one launch may train (``dynpush train --hours``).

    The launch ends at the first iteration boundary at which the next iteration, predicted to last as long as the
    last one (plus the last evaluation's time when one is due), would end after ``deadline``. A launch runs at least
    one iteration: before it, nothing predicts how long one takes.
    """

    deadline: float  # [s since the epoch, time.time()] when the launch's time is up
    iteration_s: float = 0.0  # [s] the last iteration: rollout, update, logging and saving
    evaluation_s: float = 0.0  # [s] the last evaluation of this launch (0 before the first)

    @staticmethod
    def of_hours(hours: float, started: float) -> TimeBudget:
        """``hours`` from ``started`` [s since the epoch]."""
        return TimeBudget(deadline=started + 3600.0 * hours)

    def next_iteration_fits(self, now: float, evaluating: bool) -> bool:
        """Whether the next iteration (with an evaluation before it if ``evaluating``) ends before the deadline."""
        return now + self.iteration_s + (self.evaluation_s if evaluating else 0.0) <= self.deadline


class TimeBudgetSpent(Exception):
    """Raised at the iteration boundary where a launch's :class:`TimeBudget` ends it."""


class Evaluation(Protocol):
    """Evaluates the actor at some iteration boundaries (policies/training_eval.py: PeriodicEvaluation)."""

    def due(self, iteration: int) -> bool:
        """Whether the actor is evaluated before ``iteration``."""

    def __call__(self, iteration: int, actor: torch.nn.Module) -> dict:
        """Evaluates ``actor`` after ``iteration`` iterations."""


def check_shapes(path: str, model: str, expected: dict[str, torch.Tensor], saved: dict[str, torch.Tensor]) -> None:
    """Raises a CheckpointError naming the first tensor of ``model`` whose shape in the checkpoint ``path`` differs
    from this run's (before anything is loaded): another network size, or another observation layout."""
    for name, tensor in expected.items():
        if name in saved and tuple(saved[name].shape) != tuple(tensor.shape):
            raise CheckpointError(
                f"checkpoint {path}: {model} {name} has shape {tuple(saved[name].shape)}, this run's "
                f"{tuple(tensor.shape)}: the networks' sizes and inputs must match (network.actor_hidden, "
                f"network.critic_hidden; a push run's env.critic_reads_object_at_goal)")


class CaTOnPolicyRunner(OnPolicyRunner):
    """On-policy runner for CaT-PPO with per-iteration schedules and exact resume.

    The environment must provide ``env.constraint_groups`` (``(name, dim)`` in column order), ``extras["constraints"]``
    every step, ``env.set_reward_weight(name, weight)`` (unless the schedule has no reach weight),
    ``env.set_disturbance_scale(scale)`` (if it has a disturbance ramp) and ``env.state_dict()`` / ``env.load_state_dict()``.
    ``train_cfg`` is rsl_rl's runner config; its optional ``"schedule"`` entry holds
    :class:`~dynpush.policies.schedules.ScheduleConfig` fields as a nested dict, and ``train_cfg["algorithm"]["class_name"]``
    defaults to :class:`CaTPPO`.
    """

    alg: CaTPPO
    """The CaT-PPO algorithm."""

    def __init__(self, env: VecEnv, train_cfg: dict, log_dir: str | None = None, device: str = "cpu") -> None:
        """Construct the runner, CaT-PPO and the schedules."""
        train_cfg["algorithm"].setdefault("class_name", f"{CaTPPO.__module__}:{CaTPPO.__name__}")
        super().__init__(env, train_cfg, log_dir, device)
        if not isinstance(self.alg, CaTPPO):
            raise TypeError(f"CaTOnPolicyRunner needs a CaTPPO algorithm, got {type(self.alg).__name__}.")
        self.schedule_cfg = ScheduleConfig.from_dict(train_cfg.get("schedule", {}))
        self.curriculum = GoalCurriculumConfig(**train_cfg.get("curriculum", {}))
        self.mass_curriculum = ObjectMassCurriculumConfig(**train_cfg.get("mass_curriculum", {}))
        self.mass_difficulty = self.mass_curriculum.initial  # saved in checkpoints: the environment keeps no level
        self.distance_curriculum = GoalDistanceCurriculumConfig(**train_cfg.get("distance_curriculum", {}))
        self.distance_difficulty = self.distance_curriculum.initial  # saved in checkpoints, as the mass level
        self.near_goal_starts = NearGoalStartConfig(**train_cfg.get("near_goal_starts", {}))
        self.behind_starts = BehindStartConfig(**train_cfg.get("behind_starts", {}))
        self.behind_difficulty = self.behind_starts.initial  # saved in checkpoints, as the mass level
        self.curriculum_window_episodes = train_cfg.get("curriculum_window_episodes", 1)
        self._episode_tally = torch.zeros(2, dtype=torch.float64)  # (ended, succeeded) since the levels last moved
        # Iterations of one full episode: the levels' success counts episodes ending at least that long after a move.
        self.episode_iterations = math.ceil(env.max_episode_length / train_cfg["num_steps_per_env"])
        self._count_episodes_from = 0  # the first iteration whose ended episodes count (saved in checkpoints)
        self.critic_warmup_iterations = train_cfg.get("critic_warmup_iterations", 0)
        self.critic_warmup_learning_rate = train_cfg.get("critic_warmup_learning_rate")
        self.learning_rate = self.alg.learning_rate  # the configured one, restored after the warm-up
        self.imitation_weight = tuple(train_cfg.get("imitation_weight", (0.0, 0.0)))
        if max(self.imitation_weight) > 0:  # the environment labels its observations (ExpertLabelledEnv)
            self.alg.symmetry = ExpertImitationLoss()
        self.logger.__class__ = ProgressLogger  # rsl_rl's logger plus a progress bar and a one-line summary
        self.logger.run_state = {}
        self.keep_checkpoints = train_cfg.get("keep_checkpoints", 0)  # newest model_K.pt kept (0: all)
        self.evaluation: Evaluation | None = None  # set on rank 0 by a run that evaluates during training
        self._snapshot: dict | None = None
        self._due_saves: list[tuple[str, dict | None]] = []  # (path, infos) that save() put off to a boundary

    def learn(
        self, num_learning_iterations: int, init_at_random_ep_len: bool = False, total_iterations: int | None = None,
        time_budget: TimeBudget | None = None,
    ) -> None:
        """Run rsl_rl's learning loop for ``num_learning_iterations`` from the current iteration.

        ``total_iterations`` is the length of the whole run the schedules refer to (default: this call's end).
        ``time_budget``: the launch ends at the boundary where the next iteration would overrun it, with a checkpoint
        (rank 0 decides for all processes).
        """
        start_it = self.current_learning_iteration
        total_it = total_iterations or start_it + num_learning_iterations
        iterations = iter(range(start_it, start_it + num_learning_iterations))
        iteration_start = time.time()  # [s] the last boundary, plus the evaluation there

        def on_rollout_start() -> None:
            nonlocal iteration_start
            it = next(iterations)
            evaluating = self.evaluation is not None and self.evaluation.due(it)
            if time_budget is not None and it > start_it:
                time_budget.iteration_s = time.time() - iteration_start
                if self.out_of_time(time_budget, evaluating):
                    raise TimeBudgetSpent
            iteration_start = time.time()
            if any(cfg.enabled for cfg in self.success_gated_curricula()):
                self.apply_curricula(it, fresh_run=it == 0)
            # The snapshot follows this boundary's curricula (their episode counts taken): resumed here, they find no
            # new episodes and hold, as they did.
            self._snapshot = copy.deepcopy(self.training_state(next_iteration=it))
            self.write_due_saves(self._snapshot)
            if evaluating:  # after the snapshot: an interrupted evaluation loses no iteration
                seconds = self.evaluate(it)
                iteration_start += seconds
                if time_budget is not None:
                    time_budget.evaluation_s = seconds
            self.apply_schedules(it, total_it)
            # Critic warm-up: without gradients the actor (and its std) stays as it is, its KL is 0, and the
            # adaptive learning rate is left unchanged.
            self.alg.actor.requires_grad_(it >= self.critic_warmup_iterations)
            if self.critic_warmup_learning_rate is not None and it <= self.critic_warmup_iterations:
                self.set_learning_rate(self.critic_warmup_learning_rate if it < self.critic_warmup_iterations
                                       else self.learning_rate)

        self.alg.on_rollout_start = on_rollout_start
        if self.near_goal_starts.share > 0:
            self.apply_near_goal_starts()
        if self.behind_starts.share > 0:
            self.apply_behind_starts()
        try:
            super().learn(num_learning_iterations, init_at_random_ep_len)
        except TimeBudgetSpent:
            self.stop_early()
            return
        self.write_last_checkpoint()

    def write_last_checkpoint(self) -> None:
        """Writes the launch's last checkpoint where rank 0's :meth:`save` put it off (several processes: every
        process calls this, as every process gathers)."""
        if self.is_distributed:
            self.write_due_saves(self.training_state(next_iteration=self.current_learning_iteration + 1))

    def evaluate(self, iteration: int) -> float:
        """Runs the evaluation due before ``iteration``; returns its wall-clock [s], which the logger leaves out of the
        iteration's rollout time."""
        started = time.time()
        self.evaluation(iteration, self.alg.actor)
        self.logger.evaluation_s = time.time() - started
        return self.logger.evaluation_s

    def out_of_time(self, budget: TimeBudget, evaluating: bool) -> bool:
        """Whether the next iteration would overrun ``budget``: rank 0's prediction, which every process follows."""
        stop = torch.tensor([not budget.next_iteration_fits(time.time(), evaluating)], dtype=torch.int32)
        if self.is_distributed:
            torch.distributed.broadcast(stop, src=0)
        return bool(stop.item())

    def stop_early(self) -> None:
        """Ends the launch at this iteration boundary as rsl_rl ends a run: rank 0 saves a checkpoint that ``--resume``
        continues from, and stops its writer."""
        writing = self.logger.writer is not None  # rank 0
        path = os.path.join(self.logger.log_dir or ".", f"model_{self.current_learning_iteration}.pt")
        if writing:
            self.save(path)
        self.write_last_checkpoint()
        if writing:
            self.logger.stop_logging_writer()
            print(f"time budget: stopped before iteration {self.current_learning_iteration + 1}; saved {path}; continue"
                  " with --resume")

    def set_learning_rate(self, learning_rate: float) -> None:
        """Sets PPO's learning rate (which the adaptive schedule starts from) and the optimizer's."""
        self.alg.learning_rate = learning_rate
        for group in self.alg.optimizer.param_groups:
            group["lr"] = learning_rate

    def apply_schedules(self, iteration: int, total_iterations: int) -> None:
        """Set ``p_max``, the reach-reward weight, the imitation weight and the disturbance scale for ``iteration``
        of a run of ``total_iterations``."""
        if self.schedule_cfg.constraints.follow_curricula:
            progress = self.curricula_progress()
            self.alg.set_p_max(p_max_at_progress(progress, self.schedule_cfg, self.env.constraint_groups))
            self.logger.run_state["/curriculum/p_max_progress"] = progress
        else:
            self.alg.set_p_max(p_max_at(iteration, total_iterations, self.schedule_cfg, self.env.constraint_groups))
        if self.schedule_cfg.reach is not None:
            self.env.set_reward_weight("reach", reach_weight_at(iteration, total_iterations, self.schedule_cfg))
        if isinstance(self.alg.symmetry, ExpertImitationLoss):
            weight = imitation_weight_at(iteration, total_iterations, self.imitation_weight)
            self.alg.symmetry.mirror_loss_coeff = weight
            self.logger.run_state["/imitation/weight"] = weight
        if self.schedule_cfg.disturbance is not None:
            scale = disturbance_scale_at(iteration, self.schedule_cfg.disturbance)
            self.env.set_disturbance_scale(scale)
            self.logger.run_state["/curriculum/disturbance_scale"] = scale

    def apply_curricula(self, iteration: int, fresh_run: bool) -> None:
        """Sets the goal difficulty (and success angle), the object mass range, the goal distance range and the spread
        of the starts behind the object from :meth:`training_success_rate` (over all processes: every process then draws
        its episodes at the same levels); the levels hold while it is None."""
        success_rate = self.training_success_rate(iteration)
        before = self.curriculum_levels()

        def next_level(cfg: SuccessGatedLevel, level: float) -> float:
            return cfg.initial if fresh_run else cfg.next_difficulty(level, success_rate)

        if self.curriculum.enabled:
            difficulty = next_level(self.curriculum, self.env.goal_difficulty_value)
            self.env.set_goal_difficulty(difficulty)
            self.logger.run_state["/curriculum/goal_difficulty"] = difficulty
            if self.curriculum.initial_success_angle_deg is not None:
                angle = self.curriculum.success_angle_deg(difficulty, self.env.cfg.rewards.success_angle_deg)
                self.env.set_success_angle(angle)
                self.logger.run_state["/curriculum/success_angle_deg"] = angle
        if self.mass_curriculum.enabled:
            self.mass_difficulty = next_level(self.mass_curriculum, self.mass_difficulty)
            low, high = self.mass_curriculum.mass_range(self.mass_difficulty, self.env.cfg.randomization.mass)
            self.env.set_object_mass_range(low, high)
            self.logger.run_state["/curriculum/object_mass_max"] = high
        if self.distance_curriculum.enabled:
            self.distance_difficulty = next_level(self.distance_curriculum, self.distance_difficulty)
            configured = self.env.cfg.sampling.goal_radius
            low, high = self.distance_curriculum.radius_range(self.distance_difficulty, configured)
            self.env.set_goal_radius_range(low, high)
            self.logger.run_state["/curriculum/goal_radius_max"] = high
        if self.behind_starts.enabled:
            self.behind_difficulty = next_level(self.behind_starts, self.behind_difficulty)
            self.apply_behind_starts()
        if self.curriculum_levels() != before:
            # An episode ending within one episode length of the move may have started before it: the next judgement
            # counts only episodes drawn at the new levels.
            self._episode_tally.zero_()
            self._count_episodes_from = iteration + self.episode_iterations

    def success_gated_curricula(self) -> tuple[SuccessGatedLevel, ...]:
        """The configurations of the success-gated curricula: goal, mass, distance, spread of the starts."""
        return self.curriculum, self.mass_curriculum, self.distance_curriculum, self.behind_starts

    def curriculum_levels(self) -> tuple[float, float, float, float]:
        """The levels of :meth:`success_gated_curricula`, in that order (the goal's 0 while it is off)."""
        goal = self.env.goal_difficulty_value if self.curriculum.enabled else 0.0
        return goal, self.mass_difficulty, self.distance_difficulty, self.behind_difficulty

    def curricula_progress(self) -> float:
        """Mean progress of the enabled success-gated curricula from their initial levels (0) to the paper's task (1)."""
        enabled = [cfg.progress(level) for cfg, level in zip(self.success_gated_curricula(), self.curriculum_levels())
                   if cfg.enabled]
        if not enabled:
            raise ValueError("p_max follows the curricula, but none is enabled")
        return sum(enabled) / len(enabled)

    def training_success_rate(self, iteration: int) -> float | None:
        """Success rate of the training episodes that ended, over all processes, since the last call that returned
        one: None until at least ``curriculum_window_episodes`` have ended (the levels hold). Episodes that end before
        iteration ``_count_episodes_from`` (one episode length after the levels last moved) are not counted."""
        counts = torch.tensor(self.env.take_episode_counts(), dtype=torch.float64)
        if self.is_distributed:
            torch.distributed.all_reduce(counts)
        if iteration < self._count_episodes_from:
            return None
        self._episode_tally += counts
        ended, succeeded = self._episode_tally.tolist()
        if ended < self.curriculum_window_episodes:
            return None
        self._episode_tally.zero_()
        return succeeded / ended

    def apply_near_goal_starts(self) -> None:
        """Sets the training environment's near-goal starts (at every launch: a resumed run's environment starts with
        none) and logs their share (the logger keeps it for every iteration)."""
        cfg = self.near_goal_starts
        self.env.set_near_goal_starts(cfg.share, cfg.goal_radius, cfg.max_yaw)
        self.logger.run_state["/curriculum/near_goal_share"] = cfg.share

    def apply_behind_starts(self) -> None:
        """Sets the training environment's starts behind the object at the current spread (at every launch: a resumed
        run's environment starts with none) and logs share and spread (the logger keeps them for every iteration)."""
        cfg = self.behind_starts
        spread = cfg.spread_at(self.behind_difficulty) if cfg.enabled else cfg.spread
        self.env.set_behind_starts(cfg.share, spread)
        self.logger.run_state["/curriculum/behind_share"] = cfg.share
        self.logger.run_state["/curriculum/behind_spread"] = spread

    def training_state(self, next_iteration: int) -> dict:
        """What a checkpoint holds: the algorithm's state, the iteration a resumed run starts at, the environment's
        state and torch's random state. In a run of several processes every process calls it (it gathers): rank 0's
        also holds the other processes' environment and random states (``other_processes``, in rank order)."""
        saved = self.alg.save()
        saved["iter"] = next_iteration
        own = {"env_state": self.env.state_dict(), "torch_rng": torch.get_rng_state()}
        saved["infos"] = {**own, "mass_difficulty": self.mass_difficulty,
                          "distance_difficulty": self.distance_difficulty, "behind_difficulty": self.behind_difficulty,
                          "curriculum_tally": self._episode_tally.tolist(),
                          "count_episodes_from": self._count_episodes_from}
        if self.is_distributed:
            gathered = [None] * self.gpu_world_size if self.gpu_global_rank == 0 else None
            torch.distributed.gather_object(own, gathered, dst=0)
            if gathered is not None:
                saved["infos"]["other_processes"] = gathered[1:]
        return saved

    def save(self, path: str, infos: dict | None = None) -> None:
        """Save models, optimiser, CaT state, environment state and RNG; ``iter`` is the next iteration to run.

        rsl_rl calls it on rank 0 only; in a run of several processes the checkpoint is written at the next iteration
        boundary (or at the end of the launch), where every process's state is gathered."""
        if self.is_distributed:
            self._due_saves.append((path, infos))
            return
        self.write_checkpoint(path, self.training_state(next_iteration=self.current_learning_iteration + 1), infos)

    def write_checkpoint(self, path: str, state: dict, infos: dict | None = None) -> None:
        """Writes ``state`` (:meth:`training_state`) with ``infos`` added to its infos."""
        state["infos"].update(infos or {})
        save_checkpoint(state, Path(path), self.keep_checkpoints)
        self.logger.save_model(path, state["iter"] - 1)

    def write_due_saves(self, state: dict) -> None:
        """Writes the checkpoints :meth:`save` put off with ``state``, the boundary they were due at."""
        while self._due_saves:
            path, infos = self._due_saves.pop(0)
            self.write_checkpoint(path, copy.deepcopy(state), infos)

    def save_interrupted(self) -> str:
        """Save the snapshot of the last iteration boundary (the interrupted iteration is re-run on resume)."""
        if self._snapshot is None:
            raise RuntimeError("nothing to save: training had not started")
        path = os.path.join(self.logger.log_dir or ".", f"model_{self._snapshot['iter']}.pt")
        save_checkpoint(self._snapshot, Path(path), self.keep_checkpoints)
        return path

    def _configure_multi_gpu(self) -> None:
        """rsl_rl's multi-GPU set-up (NCCL), extended to CPU processes with the gloo backend."""
        if int(os.getenv("WORLD_SIZE", "1")) == 1 or str(self.device).startswith("cuda"):
            super()._configure_multi_gpu()
            return
        self.gpu_world_size = int(os.environ["WORLD_SIZE"])
        self.gpu_local_rank = int(os.getenv("LOCAL_RANK", "0"))
        self.gpu_global_rank = int(os.getenv("RANK", "0"))
        self.is_distributed = True
        self.cfg["multi_gpu"] = {"global_rank": self.gpu_global_rank, "local_rank": self.gpu_local_rank,
                                 "world_size": self.gpu_world_size}
        if not torch.distributed.is_initialized():
            torch.distributed.init_process_group(backend="gloo", rank=self.gpu_global_rank, world_size=self.gpu_world_size)

    def load(
        self, path: str, load_cfg: dict | None = None, strict: bool = True, map_location: str | None = None,
        restore_env: bool = True,
    ) -> dict:
        """Load a checkpoint and the curricula's levels; restores the environments and the RNG unless ``restore_env`` is
        False (:meth:`restore_processes`)."""
        loaded = read_checkpoint(path, map_location)
        for key in ("actor_state_dict", "critic_state_dict", "iter"):
            if key not in loaded:
                raise CheckpointError(f"checkpoint {path} is not a dynpush training checkpoint (missing {key!r})")
        for model in ("actor", "critic"):
            if load_cfg is None or load_cfg.get(model):
                check_shapes(path, model, getattr(self.alg, model).state_dict(), loaded[f"{model}_state_dict"])
        if self.alg.load(loaded, load_cfg, strict):
            self.current_learning_iteration = loaded["iter"]
        infos = loaded.get("infos") or {}
        self.mass_difficulty = infos.get("mass_difficulty", self.mass_curriculum.initial)
        self.distance_difficulty = infos.get("distance_difficulty", self.distance_curriculum.initial)
        self.behind_difficulty = infos.get("behind_difficulty", self.behind_starts.initial)
        self._episode_tally = torch.tensor(infos.get("curriculum_tally", (0.0, 0.0)), dtype=torch.float64)
        self._count_episodes_from = infos.get("count_episodes_from", 0)
        if restore_env and "env_state" in infos:
            self.restore_processes(path, infos, loaded["iter"])
        return infos

    def restore_processes(self, path: str, infos: dict, next_iteration: int) -> None:
        """Every process continues its own saved episodes and random state when the checkpoint holds one state per
        process and they fit its environment. Otherwise (another number of processes or of worlds, or a checkpoint of
        several processes that saved rank 0's only) every process starts fresh episodes at the saved goal difficulty,
        with its own seed, and the curricula count only episodes that end one episode length after ``next_iteration``:
        fresh episodes all start at once and end together."""
        rank_0 = {"env_state": infos["env_state"], "torch_rng": infos.get("torch_rng")}
        states = [rank_0, *infos.get("other_processes", ())]
        world_size, rank = (self.gpu_world_size, self.gpu_global_rank) if self.is_distributed else (1, 0)
        if len(states) != world_size:
            mismatch = f"saved by {len(states)} process(es), resumed by {world_size}"
        else:
            mismatch = self.env.state_mismatch(states[rank]["env_state"])
        if mismatch is None:
            self.env.load_state_dict(states[rank]["env_state"])
            if states[rank]["torch_rng"] is not None:
                torch.set_rng_state(states[rank]["torch_rng"])
            return
        if rank == 0:
            print(f"{path}: fresh episodes, the saved environment state does not fit ({mismatch})")
        self.env.set_goal_difficulty(float(infos["env_state"]["goal_difficulty"][0]))  # the curriculum goes on
        self._episode_tally.zero_()
        self._count_episodes_from = next_iteration + self.episode_iterations
