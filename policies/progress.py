"""rsl_rl's logger with a progress bar and a one-line summary per iteration instead of its console block."""

from __future__ import annotations

import contextlib
import io
import json
import os
import time

import torch
from rsl_rl.utils.logger import Logger
from tqdm import tqdm

GROUP_ABBREVIATIONS = {
    "base_command": "base", "arm_command": "arm", "arm_action_rate": "rate", "arm_joint_position": "q",
    "arm_joint_velocity": "qd", "arm_joint_torque": "tau", "leg_joint_torque": "leg", "collision": "coll",
    "object_balance": "bal",
}


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

    def log(self, it: int, start_it: int, total_it: int, collect_time: float, learn_time: float, **kwargs) -> None:
        if self.writer is None:  # non-zero ranks of a distributed run
            super().log(it, start_it, total_it, collect_time, learn_time, **kwargs)
            return
        summary = {**iteration_summary(self.ep_extras), **self.run_state}
        for key, value in self.run_state.items():
            self.writer.add_scalar(key.lstrip("/"), value, it)
        with contextlib.redirect_stdout(io.StringIO()):
            super().log(it, start_it, total_it, collect_time, learn_time, **kwargs)
        record = {"iteration": it, "time": time.time(), "collect_s": collect_time, "learn_s": learn_time, **summary}
        with open(os.path.join(self.log_dir, "progress.jsonl"), "a") as f:
            f.write(json.dumps(record) + "\n")
        if self.bar is None:
            self.bar = tqdm(total=total_it, initial=start_it, unit="it", dynamic_ncols=True)
        steps = self.cfg["num_steps_per_env"] * self.num_envs * self.gpu_world_size
        violations = " ".join(
            f"{abbr} {summary.get(f'CaT/violation_rate/{name}', float('nan')):.3f}"
            for name, abbr in GROUP_ABBREVIATIONS.items()
        )
        episode_reward = sum(self.rewbuffer) / len(self.rewbuffer) if len(self.rewbuffer) else float("nan")
        self.bar.write(
            f"it {it:5d} | {steps / collect_time:7.0f} world-steps/s | sim {collect_time:5.2f}s update {learn_time:5.2f}s"
            f" | episode reward {episode_reward:8.2f} task {summary.get('/reward/task', float('nan')):.3f}"
            f" reach {summary.get('/reward/reach', float('nan')):.3f}"
            f" | success {summary.get('/episode/success', float('nan')):.3f}"
            f" toppled {summary.get('/episode/toppled', float('nan')):.3f}"
            f" | delta {summary.get('CaT/mean_delta', float('nan')):.4f} | violated: {violations}"
            + "".join(f" | {key.rsplit('/', 1)[-1]} {value:.3f}" for key, value in self.run_state.items())
        )
        self.bar.update(1)
        if it + 1 >= total_it:
            self.bar.close()
            self.bar = None
