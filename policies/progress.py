"""Training progress: rsl_rl's logger with a progress bar and a one-line summary per iteration instead
of its console block, writing ``progress.jsonl``; and the learning curve drawn from that file."""

from __future__ import annotations

import contextlib
import io
import json
import os
import time
from pathlib import Path

import numpy as np
import torch
from rsl_rl.utils.logger import Logger
from tqdm import tqdm

from dynpush.errors import CorruptFileError, MissingFileError

EVALUATIONS = "evaluations.jsonl"  # a run folder's evaluations during training
BREAK_FACTOR = 5.0  # learning curve: a gap this many times an iteration's own time is a pause between sittings
SMOOTHING = 25  # learning curve: iterations averaged per point

GROUP_ABBREVIATIONS = {
    "base_command": "base", "arm_command": "arm", "arm_action_rate": "rate", "arm_joint_position": "q",
    "arm_joint_velocity": "qd", "arm_joint_torque": "tau", "leg_joint_torque": "leg", "collision": "coll",
    "object_balance": "bal", "leg_joint_velocity": "legqd", "leg_joint_acceleration": "legqdd",
    "leg_action_rate": "legrate", "foot_air_time": "air", "foot_contact_force": "force",
}
# Reward terms on the progress line: the push task's task and reach, every locomotion tracking term.
LINE_REWARDS = ("task", "reach", "linear_velocity", "yaw_rate", "attitude", "height", "feet_air_time")


def iteration_summary(ep_extras: list[dict]) -> dict[str, float]:
    """Means over an iteration of the step extras (tensors are concatenated, so episodes weigh equally)."""
    summary: dict[str, float] = {}
    for key in dict.fromkeys(k for step in ep_extras for k in step):
        values = [torch.as_tensor(step[key], dtype=torch.float).reshape(-1) for step in ep_extras if key in step]
        summary[key] = float(torch.cat(values).mean())
    return summary


class ProgressLogger(Logger):
    """Writes tensorboard exactly as rsl_rl does, prints one line per iteration under a tqdm bar, and
    appends the iteration's summary to ``progress.jsonl`` in the run folder (the learning curve)."""

    bar: tqdm | None = None
    run_state: dict[str, float]  # values set by the runner for this iteration (e.g. the curriculum)
    # [s] the evaluation the runner ran at this iteration's start (TrainConfig.eval_interval): rsl_rl's rollout clock
    # includes it, the iteration's collect time does not.
    evaluation_s: float = 0.0

    def log(self, it: int, start_it: int, total_it: int, collect_time: float, learn_time: float, **kwargs) -> None:
        evaluation_s, self.evaluation_s = self.evaluation_s, 0.0
        collect_time -= evaluation_s
        if self.writer is None:  # non-zero ranks of a distributed run
            super().log(it, start_it, total_it, collect_time, learn_time, **kwargs)
            return
        summary = {**iteration_summary(self.ep_extras), **self.run_state}
        for key, value in self.run_state.items():
            self.writer.add_scalar(key.lstrip("/"), value, it)
        with contextlib.redirect_stdout(io.StringIO()):
            super().log(it, start_it, total_it, collect_time, learn_time, **kwargs)
        record = {"iteration": it, "time": time.time(), "collect_s": collect_time, "learn_s": learn_time,
                  "eval_s": evaluation_s, **summary,
                  "action_std": float(kwargs["action_std"].detach().mean()), "learning_rate": float(kwargs["learning_rate"]),
                  **{f"loss/{key}": float(value) for key, value in kwargs["loss_dict"].items()}}
        with open(os.path.join(self.log_dir, "progress.jsonl"), "a") as f:
            f.write(json.dumps(record) + "\n")
        if self.bar is None:
            self.bar = tqdm(total=total_it, initial=start_it, unit="it", dynamic_ncols=True)
        steps = self.cfg["num_steps_per_env"] * self.num_envs * self.gpu_world_size
        rewards = " ".join(f"{key.rsplit('/', 1)[-1]} {value:.3f}" for key, value in summary.items()
                           if key.startswith("/reward/") and key.rsplit("/", 1)[-1] in LINE_REWARDS)
        episodes = " ".join(f"{key.rsplit('/', 1)[-1]} {value:.3f}" for key, value in summary.items()
                            if key.startswith("/episode/") and key.count("/") == 2)
        violations = " ".join(f"{GROUP_ABBREVIATIONS.get(key.rsplit('/', 1)[-1], key.rsplit('/', 1)[-1])} {value:.3f}"
                              for key, value in summary.items() if key.startswith("CaT/violation_rate/"))
        episode_reward = sum(self.rewbuffer) / len(self.rewbuffer) if len(self.rewbuffer) else float("nan")
        self.bar.write(
            f"it {it:5d} | {steps / collect_time:7.0f} world-steps/s | sim {collect_time:5.2f}s update {learn_time:5.2f}s"
            f" | episode reward {episode_reward:8.2f} {rewards} | {episodes}"
            f" | delta {summary.get('CaT/mean_delta', float('nan')):.4f} | std {record['action_std']:.3f}"
            f" | value ev {record.get('loss/value_explained_variance', float('nan')):.2f} | violated: {violations}"
            + "".join(f" | {key.rsplit('/', 1)[-1]} {value:.3f}" for key, value in self.run_state.items())
        )
        self.bar.update(1)
        if it + 1 >= total_it:
            self.close_bar()

    def close_bar(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def stop_logging_writer(self) -> None:
        """Closes the progress bar (also of a launch that stops before its last iteration) and the writer."""
        self.close_bar()
        super().stop_logging_writer()


def read_progress(run_dir: Path) -> list[dict]:
    """The records of ``progress.jsonl``, one per iteration (a re-run iteration after a resume keeps its last)."""
    path = Path(run_dir) / "progress.jsonl"
    if not path.exists():
        raise MissingFileError(f"{path} not found: not a training run folder (dynpush train writes it)")
    return read_iteration_records(path)


def read_evaluations(run_dir: Path) -> list[dict]:
    """The evaluations during training of ``evaluations.jsonl`` (policies/training_eval.py), one per iteration (an
    evaluation repeated after a resume keeps its last); empty for a run without them."""
    path = Path(run_dir) / EVALUATIONS
    return read_iteration_records(path) if path.exists() else []


def read_iteration_records(path: Path) -> list[dict]:
    """The JSON lines of ``path`` by their ``iteration``, in order; a later line of an iteration replaces an earlier."""
    records = {}
    for number, line in enumerate(path.read_text().splitlines(), 1):
        try:
            record = json.loads(line)
            records[record["iteration"]] = record
        except (json.JSONDecodeError, TypeError, KeyError) as error:
            raise CorruptFileError(f"{path}:{number}: not a JSON record with an iteration ({error!r})") from error
    return [records[it] for it in sorted(records)]


def imitation_rounds(run_dir: Path) -> list[dict]:
    """The DAgger rounds of a run started by ``dynpush imitate`` (``imitation.jsonl``); empty for a run
    trained from scratch."""
    path = Path(run_dir) / "imitation.jsonl"
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def training_records(run_dir: Path) -> list[dict]:
    """The CaT-PPO iterations of a run (``read_progress``); empty for a run that has only its DAgger rounds."""
    run_dir = Path(run_dir)
    if (run_dir / "imitation.jsonl").exists() and not (run_dir / "progress.jsonl").exists():
        return []
    return read_progress(run_dir)


def imitation_summary(run_dir: Path) -> dict | None:
    """Rounds, world-steps and wall-clock [h] of the DAgger phase of a run started by ``dynpush imitate``;
    None for a run trained from scratch."""
    rounds = imitation_rounds(run_dir)
    if not rounds:
        return None
    return {"rounds": len(rounds), "world_steps": sum(r["world_steps"] for r in rounds),
            "wall_clock_h": sum(r["seconds"] for r in rounds) / 3600.0}


def wall_clock_hours(records: list[dict]) -> np.ndarray:
    """Training wall-clock [h] at the end of each record's iteration.

    An iteration lasts the time between consecutive records; across a pause between sittings (a gap
    longer than ``BREAK_FACTOR`` times the iteration's own rollout + update + evaluation time) it counts that time
    only. So the hours of a run resumed in several launches are the sum of the launches' iterations.
    """

    def own(record: dict) -> float:
        return record["collect_s"] + record["learn_s"] + record.get("eval_s", 0.0)

    seconds = [own(records[0])] if records else []
    for previous, record in zip(records, records[1:]):
        gap = record["time"] - previous["time"]
        seconds.append(gap if 0.0 < gap < BREAK_FACTOR * own(record) else own(record))
    return np.cumsum(seconds) / 3600.0


def plot_evaluations(ax, x: np.ndarray, evaluations: list[dict]) -> None:
    """The evaluations during training (``evaluations.jsonl``) at ``x``: success and toppled rate [% of episodes], the
    episodes that end at the goal with the rotation off and those that end with the robot fallen (where recorded)
    and, on a right-hand axis, the time the most violated constraint group is violated [% of an episode]."""
    ax.plot(x, [e["success_rate"] for e in evaluations], "o-", color="tab:green", ms=3,
            label=f"evaluation: success ({evaluations[-1]['episodes']} episodes)")
    ax.plot(x, [e["toppled_rate"] for e in evaluations], "o-", color="tab:red", ms=3, label="evaluation: toppled")
    rotation_off = [e.get("outcome_percent", {}).get("at_goal_rotation_off", np.nan) for e in evaluations]
    if not np.isnan(rotation_off).all():  # evaluations before this figure was recorded have none
        ax.plot(x, rotation_off, "o:", color="tab:orange", ms=3, label="evaluation: at the goal, rotation off")
    fallen = np.array([e.get("fallen_rate", np.nan) for e in evaluations], dtype=float)
    if np.nanmax(fallen, initial=0.0) > 0.0:  # recorded later; a tracked base that never falls draws no line
        ax.plot(x, fallen, "o:", color="tab:brown", ms=3, label="evaluation: robot fell")
    ax.set_ylabel("% of episodes")
    ax.set_ylim(-2, 102)
    ax.legend(fontsize=8, loc="upper left")
    worst = ax.twinx()
    worst.plot(x, [max(e["constraint_violation_percent"].values()) for e in evaluations], "s--", color="tab:purple",
               ms=3, label="evaluation: most violated constraint group")
    worst.set_ylabel("% of episode violated", color="tab:purple")
    worst.set_ylim(bottom=0.0)
    worst.legend(fontsize=8, loc="upper right")


def plot_learning_curve(run_dir: Path, out: Path, paper_success_percent: float | None = None,
                        marked_iteration: int | None = None, imitation_run: Path | None = None) -> dict:
    """Success, topple and reward curves of a run against training wall-clock hours; writes the PNG ``out``.
    A run that evaluates during training (``evaluations.jsonl``) gets two more panels: its evaluations against the
    hours and against the world-steps.

    Episode rates are of the episodes that ended in each iteration (smoothed over ``SMOOTHING`` iterations).
    ``marked_iteration``: a vertical line where a checkpoint of that many iterations was saved (the shipped
    one). ``imitation_run``: the run whose DAgger rounds come first (the one a ``--init-from`` run started from;
    default ``run_dir``'s own). Returns the final smoothed figures.
    """
    from matplotlib.figure import Figure

    records, rounds = training_records(run_dir), imitation_rounds(imitation_run or run_dir)
    if not records and not rounds:
        raise ValueError(f"{run_dir}/progress.jsonl has no iterations yet")
    round_hours = np.cumsum([r["seconds"] for r in rounds]) / 3600.0
    imitation_hours = float(round_hours[-1]) if rounds else 0.0  # CaT-PPO starts after DAgger
    hours = imitation_hours + wall_clock_hours(records)

    def series(key: str) -> np.ndarray:
        return np.array([r.get(key, np.nan) for r in records], dtype=float)

    def smooth(values: np.ndarray) -> np.ndarray:
        out = np.empty_like(values)
        for i in range(len(values)):
            window = values[max(0, i - SMOOTHING + 1): i + 1]
            out[i] = np.nanmean(window) if np.isfinite(window).any() else np.nan
        return out

    episode_keys = [k for k in dict.fromkeys(k for r in records for k in r) if k.startswith("/episode/") and k.count("/") == 2]
    rates = {k.rsplit("/", 1)[-1]: smooth(100.0 * series(k)) for k in episode_keys}  # success, toppled; locomotion: fell
    colors = {"success": "tab:green", "toppled": "tab:red", "fell": "tab:brown"}
    difficulty = series("/curriculum/goal_difficulty")
    mass_max = series("/curriculum/object_mass_max")
    behind_spread = series("/curriculum/behind_spread")
    goal_radius_max = series("/curriculum/goal_radius_max")
    success_angle = series("/curriculum/success_angle_deg")
    p_max_progress = series("/curriculum/p_max_progress")
    evaluations = read_evaluations(run_dir)
    rows = (4 if records else 1) + (2 if evaluations else 0)  # a DAgger-only run: rates only
    fig = Figure(figsize=(8.0, (9.5 if records else 3.5) + (4.5 if evaluations else 0.0)), layout="constrained")
    all_axes = list(np.atleast_1d(fig.subplots(rows, 1)))
    axes = all_axes[:-1] if evaluations else all_axes  # against training hours; the last: evaluations by world-steps
    for ax in axes[1:]:
        ax.sharex(axes[0])
    ax_rate = axes[0]
    for name, values in rates.items():
        ax_rate.plot(hours, values, color=colors.get(name), label=f"{name} (episodes ended in the iteration)")
    if paper_success_percent is not None:
        ax_rate.axhline(paper_success_percent, color="tab:green", ls=":", label=f"paper success {paper_success_percent} %")
    if np.isfinite(difficulty).any():
        ax_rate.plot(hours, 100.0 * difficulty, color="gray", ls="--", label="curriculum goal difficulty x 100")
    if np.isfinite(mass_max).any():
        ax_rate.plot(hours, 10.0 * mass_max, color="tab:orange", ls="--", label="curriculum heaviest object [kg] x 10")
    if np.isfinite(goal_radius_max).any():
        ax_rate.plot(hours, 10.0 * goal_radius_max, color="tab:purple", ls="--", label="curriculum farthest goal [m] x 10")
    if np.isfinite(success_angle).any():
        ax_rate.plot(hours, 100.0 * success_angle / 180.0, color="tab:olive", ls="--",
                     label="curriculum success angle [% of 180 deg]")
    if np.isfinite(behind_spread).any():
        ax_rate.plot(hours, 100.0 * behind_spread / np.pi, color="tab:blue", ls="--",
                     label="starts behind the object: spread [% of pi]")
    if np.isfinite(p_max_progress).any():
        ax_rate.plot(hours, 100.0 * p_max_progress, color="k", ls="--",
                     label="CaT p_max [% of the way from initial to final values]")
    if rounds:
        ax_rate.plot(round_hours, [100.0 * r["success_rate"] for r in rounds], "o-", color="tab:green", ms=3, alpha=0.6,
                     label="DAgger round: success (noisy rollouts, expert share 0.5^round)")
        ax_rate.plot(round_hours, [100.0 * r["toppled_rate"] for r in rounds], "o-", color="tab:red", ms=3, alpha=0.6,
                     label="DAgger round: toppled")
    ax_rate.set_ylabel("% of ended episodes")
    ax_rate.set_ylim(-2, 102)
    if ax_rate.get_legend_handles_labels()[0]:  # runs too short to end an episode have none
        ax_rate.legend(fontsize=8, loc="upper left")
    if records:
        ax_reward, ax_delta, ax_policy = axes[1:4]
        for key in dict.fromkeys(k for r in records for k in r if k.startswith("/reward/")):
            ax_reward.plot(hours, smooth(series(key)), label=key.rsplit("/", 1)[-1] + " reward term (mean over worlds)")
        ax_reward.set_ylabel("reward")
        if ax_reward.get_legend_handles_labels()[0]:  # runs that logged reward terms
            ax_reward.legend(fontsize=8, loc="upper left")
        ax_delta.plot(hours, smooth(series("CaT/mean_delta")), color="k", label="CaT mean termination probability delta")
        for key in dict.fromkeys(k for r in records for k in r if k.startswith("CaT/delta/")):
            ax_delta.plot(hours, smooth(series(key)), lw=0.8, label=f"{key.rsplit('/', 1)[-1]} (its columns' largest)")
        ax_delta.set_ylabel("delta")
        ax_delta.legend(fontsize=8, loc="upper left")
        ax_policy.plot(hours, smooth(series("action_std")), color="tab:blue", label="action std (mean over actions)")
        ax_policy.plot(hours, smooth(series("loss/value_explained_variance")), color="tab:purple",
                       label="critic: explained variance of the rollout's returns")
        ax_policy.set_ylabel("std / explained variance")
        ax_policy.legend(fontsize=8, loc="upper left")
    if evaluations:
        plot_evaluations(axes[-1], imitation_hours + np.array([e["training_hours"] for e in evaluations]), evaluations)
        plot_evaluations(all_axes[-1], np.array([e["world_steps"] for e in evaluations], dtype=float), evaluations)
        all_axes[-1].set_xlabel("CaT-PPO world-steps (all processes)")
        all_axes[-1].grid(alpha=0.3)
    for ax in axes[:-1]:
        ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel("training wall-clock [h] (summed over launches)")
    for ax in axes:
        ax.grid(alpha=0.3)
        if imitation_hours > 0.0:
            ax.axvspan(0.0, imitation_hours, color="gold", alpha=0.25, lw=0)
    if marked_iteration is not None:
        done = [h for r, h in zip(records, hours) if r["iteration"] < marked_iteration]
        marked_hours = done[-1] if done else imitation_hours
        for ax in axes:
            ax.axvline(marked_hours, color="k", ls=":", lw=1.0)
        ax_rate.text(marked_hours, 95.0, f" shipped checkpoint: {marked_iteration} CaT-PPO iterations", fontsize=8, va="top")
    if imitation_hours > 0.0:
        ax_rate.text(0.5 * imitation_hours, 50.0, "DAgger from the\nscripted pusher", ha="center", va="center", fontsize=8)
    total_hours = float(hours[-1]) if records else imitation_hours
    source = f" ({Path(imitation_run).name})" if imitation_run else ""
    dagger = f"{len(rounds)} DAgger rounds{source}, " if rounds else ""
    fig.suptitle(f"{Path(run_dir).name}: {dagger}{len(records)} CaT-PPO iterations in {total_hours:.2f} h"
                 f" (iterations smoothed over {SMOOTHING})")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    last = rounds[-1] if not records else None  # a DAgger-only run ends with its last round
    final = {f"{name}_percent": float(values[-1]) for name, values in rates.items()}
    if last:
        final |= {"success_percent": 100.0 * last["success_rate"], "toppled_percent": 100.0 * last["toppled_rate"]}
    return {"iterations": len(records), "hours": total_hours, **final}
