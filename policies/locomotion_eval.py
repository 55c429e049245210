"""Evaluation of a locomotion policy (``dynpush eval-locomotion locomotion.onnx``): command tracking per component.

Every world draws one command of the training distribution (``LocomotionEnvConfig.commands``) and holds it
for ``seconds``; the random arm motions, base pushes, end-effector forces and base masses of training go on (at
their full size, past any training ramp; ``overrides`` changes them). After ``settle_s``
the tracking error ``command - measured`` of each component (vx, vy in the heading frame [m/s], yaw rate
[rad/s], roll, pitch [rad], height [m]; ``LocomotionEnv.tracking_error_t``) is collected in every step of
the worlds that have not fallen. Writes ``locomotion_eval.json`` (RMS and mean absolute error per
component, fall rate, share of steps with each constraint group violated, and percentiles of each group's
largest excess over its limit, which show how far a CaT limit sits from the gait) and ``locomotion_eval.png``
(commanded vs achieved per component, one dot per world).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from dynpush.sim.config import ConfigError
from dynpush.sim.locomotion_env import COMMAND_NAMES, CONSTRAINT_GROUPS, LocomotionEnv

from .locomotion_train import LocomotionTrainConfig
from .overrides import apply_overrides

UNITS = ("m/s", "m/s", "rad/s", "rad", "rad", "m")
# Units of the constraint values (value - limit) of each group of CONSTRAINT_GROUPS.
CONSTRAINT_UNITS = {"leg_joint_torque": "N m", "leg_joint_velocity": "rad/s", "leg_joint_acceleration": "rad/s^2",
                    "leg_action_rate": "1/s", "collision": "m", "foot_air_time": "s", "foot_contact_force": "N"}
EXCESS_PERCENTILES = (50, 90, 99)


@dataclass
class LocomotionEvalConfig:
    num_envs: int = 256  # worlds, one held command each
    seconds: float = 10.0  # per command
    settle_s: float = 2.0  # excluded after the command is given
    seed: int = 0
    noise: bool | None = None  # observation noise (None: as in training)
    # ``env.*`` overrides of the training config (``--set``), e.g. the task's full disturbances for a run that
    # trained with fewer: "env.randomization.arm_amplitude=(0.2, 0.6, 0.9, 0.2, 0.5)" env.randomization.push_velocity=0.5
    overrides: tuple[str, ...] = ()


def evaluate_locomotion(path: Path, cfg: LocomotionEvalConfig, out_dir: Path) -> dict:
    """Runs the evaluation of ``path`` (a ``locomotion.onnx``) and writes its JSON and PNG into ``out_dir``."""
    from dynpush.sim.legged_push_env import LocomotionNetwork

    if not 0.0 <= cfg.settle_s < cfg.seconds:
        raise ValueError(f"settle_s must lie in [0, seconds), got {cfg.settle_s} with seconds {cfg.seconds}")
    network = LocomotionNetwork(str(path))
    for item in cfg.overrides:
        if not item.startswith("env."):
            raise ConfigError(f"a locomotion evaluation takes env.* overrides only, got {item!r}")
    trained = LocomotionTrainConfig.from_dict(network.contract.values["training_config"])
    env_cfg = apply_overrides(trained, list(cfg.overrides)).env
    env_cfg.num_envs, env_cfg.seed, env_cfg.randomize_first_episode_length = cfg.num_envs, cfg.seed, False
    env_cfg.episode_length_s = cfg.seconds + env_cfg.control_dt  # no time-out inside the evaluation
    if cfg.noise is not None:
        env_cfg.noise.enabled = cfg.noise
    env = LocomotionEnv(env_cfg)
    commands = env.task.command.numpy().copy()
    obs = env.set_commands(commands, hold=True)["policy"]
    steps, settle = int(round(cfg.seconds / env_cfg.control_dt)), int(round(cfg.settle_s / env_cfg.control_dt))
    alive = np.ones(cfg.num_envs, dtype=bool)
    errors = np.zeros((steps - settle, cfg.num_envs, len(COMMAND_NAMES)))
    counted = np.zeros((steps - settle, cfg.num_envs), dtype=bool)
    violated = np.zeros(len(CONSTRAINT_GROUPS))
    excess = np.zeros((steps - settle, cfg.num_envs, len(CONSTRAINT_GROUPS)))
    group_starts = np.cumsum([0] + [size for _, size in CONSTRAINT_GROUPS])[:-1]
    with torch.inference_mode():
        for t in tqdm(range(steps), desc="locomotion eval", unit="step", dynamic_ncols=True):
            actions = torch.from_numpy(network(obs.numpy()))
            obs_td, _, dones, extras = env.step(actions)
            obs = obs_td["policy"]
            alive &= ~(dones.numpy().astype(bool) & ~extras["time_outs"].numpy())
            if t >= settle:
                errors[t - settle] = env.tracking_error_t.numpy()
                counted[t - settle] = alive
                violated += env.violated_groups_t.numpy()[alive].sum(axis=0)
                excess[t - settle] = np.maximum.reduceat(env.constraints_t.numpy(), group_starts, axis=1)
    summary = _summary(path, cfg, env_cfg, commands, errors, counted, alive, violated, excess)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "locomotion_eval.json").write_text(json.dumps(summary, indent=1))
    _plot(commands, errors, counted, summary, out_dir / "locomotion_eval.png")
    return summary


def _summary(path, cfg, env_cfg, commands, errors, counted, alive, violated, excess) -> dict:
    """``excess``: (steps, worlds, groups) largest constraint value (value - limit) of each group per step."""
    e, x = errors[counted], excess[counted]  # (samples, 6), (samples, groups)
    samples = max(int(counted.sum()), 1)
    return {
        "policy": str(path),
        "worlds": cfg.num_envs, "seconds_per_command": cfg.seconds, "settle_s": cfg.settle_s, "seed": cfg.seed,
        "overrides": list(cfg.overrides),
        "arm_amplitude_rad": list(env_cfg.randomization.arm_amplitude), "push_velocity_m_s": env_cfg.randomization.push_velocity,
        "fell_percent": 100.0 * float((~alive).mean()),
        "tracking_rms": {name: float(np.sqrt(np.mean(e[:, i] ** 2))) for i, name in enumerate(COMMAND_NAMES)},
        "tracking_mean_abs": {name: float(np.mean(np.abs(e[:, i]))) for i, name in enumerate(COMMAND_NAMES)},
        "command_std": {name: float(commands[:, i].std()) for i, name in enumerate(COMMAND_NAMES)},
        "units": dict(zip(COMMAND_NAMES, UNITS)),
        "violated_percent_of_steps": {name: 100.0 * float(v) / samples for (name, _), v in zip(CONSTRAINT_GROUPS, violated)},
        "largest_excess_percentiles": {name: {f"p{q}": float(np.percentile(x[:, g], q)) for q in EXCESS_PERCENTILES}
                                       for g, (name, _) in enumerate(CONSTRAINT_GROUPS)},
        "constraint_units": {name: CONSTRAINT_UNITS[name] for name, _ in CONSTRAINT_GROUPS},
        "samples": int(counted.sum()),
    }


def _plot(commands, errors, counted, summary, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 8))
    steps = counted.sum(axis=0)
    shown = steps > 0
    mean_error = np.where(shown[:, None], (errors * counted[..., None]).sum(axis=0) / np.maximum(steps, 1)[:, None], np.nan)
    for i, (ax, name, unit) in enumerate(zip(axes.flat, COMMAND_NAMES, UNITS)):
        commanded = commands[shown, i]
        achieved = commanded - mean_error[shown, i]
        ax.scatter(commanded, achieved, s=8, alpha=0.6)
        lo, hi = float(commands[:, i].min()), float(commands[:, i].max())
        ax.plot([lo, hi], [lo, hi], "k--", lw=1, label="perfect tracking")
        ax.set_title(f"{name}: RMS error {summary['tracking_rms'][name]:.3f} {unit}")
        ax.set_xlabel(f"commanded [{unit}]")
        ax.set_ylabel(f"achieved, mean over the held command [{unit}]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper left")
    fig.suptitle(f"Locomotion tracking: {summary['worlds']} worlds, {summary['seconds_per_command']:.0f} s per command,"
                 f" arm motions up to +-{max(summary['arm_amplitude_rad']):.2f} rad, pushes {summary['push_velocity_m_s']:.2f} m/s,"
                 f" {summary['fell_percent']:.1f} % fell ({Path(summary['policy']).name})")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
