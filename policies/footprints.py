"""``dynpush footprints policy.onnx``: the study of the paper's Fig. "EE height boxplot" (IV-D).

Cuboids with six square xy-footprints across the training range, fixed height, mass, CoM and friction, observation
noise off, N successful episodes per footprint; the end-effector height (world z, m) while it touches the object.
Writes ``footprints.json`` and ``footprints.png``.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from tqdm import tqdm

from dynpush.sim.config import ConfigError
from dynpush.sim.envs import make_push_env

from .env_probe import EE_CONTACT_COLUMN, EnvProbe
from .episodes import run_first_episodes
from .onnx_policy import OnnxPolicy
from .sample_stats import describe
from .trained_env import env_config_for

if TYPE_CHECKING:
    from dynpush.sim.push_env import PushEnv


@dataclass
class FootprintConfig:
    """The object-footprint study (paper IV-D, Fig. "EE height boxplot").

    Square xy-footprints equally spaced across the training range of ``randomization.size_x/size_y``;
    height, mass, CoM and friction fixed at mid-range values; cuboids only; no observation noise.
    """

    sides: tuple[float, ...] = (0.25, 0.35, 0.45, 0.55, 0.65, 0.75)  # m: six footprints over [0.25, 0.75]
    height: float = 0.7  # m (mid-range of [0.4, 1.0])
    mass: float = 5.0  # kg
    friction: float = 0.8  # combined object-floor coefficient
    successful_episodes: int = 1000  # per footprint (IV-D)
    max_rounds: int = 50  # per footprint; stops a policy that rarely succeeds
    num_envs: int = 512
    device: str = "cpu"
    seed: int = 0
    overrides: tuple[str, ...] = ()  # env.field=value, applied before the study's own settings

    def validate(self) -> FootprintConfig:
        if not self.sides or not all(0.05 <= s <= 2.0 for s in self.sides):
            raise ConfigError(f"footprints.sides must be lengths in [0.05, 2.0] m, got {self.sides!r}")
        for name in ("successful_episodes", "max_rounds", "num_envs"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(f"footprints.{name} must be an integer >= 1, got {getattr(self, name)!r}")
        return self

    def env_overrides(self, side: float) -> list[str]:
        """``env.*`` overrides that pin the object to one footprint."""
        fixed = {"size_x": (side, side), "size_y": (side, side), "size_z": (self.height, self.height),
                 "mass": (self.mass, self.mass), "friction": (self.friction, self.friction),
                 "com_fraction_x": (0.0, 0.0), "com_fraction_y": (0.0, 0.0), "com_fraction_z": (0.0, 0.0),
                 "cylinder_probability": 0.0}
        return [*self.overrides, *(f"env.randomization.{k}={v!r}" for k, v in fixed.items()), "env.noise.enabled=False"]


class ContactHeightObserver:
    """Collects, per world, the end-effector height (world z, m) at every step it touches the object."""

    def __init__(self, env: PushEnv):
        self.env = env
        self.probe = EnvProbe(env)
        self.heights: list[list[float]] = [[] for _ in range(env.num_envs)]

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        touching = (continuing & (self.env.critic_obs_t[:, EE_CONTACT_COLUMN] > 0.5)).cpu().numpy()
        if touching.any():
            z = self.probe.ee_position()[:, 2]
            for w in np.flatnonzero(touching):
                self.heights[w].append(float(z[w]))


def footprint_study(policy_path: Path, cfg: FootprintConfig, out_dir: Path) -> dict:
    """Runs the footprint study; writes ``footprints.json`` and ``footprints.png`` into ``out_dir``."""
    cfg.validate()
    policy = OnnxPolicy(policy_path, batched=True)
    rows, heights = [], []
    for side in cfg.sides:
        env = make_push_env(env_config_for(policy, cfg.num_envs, None, cfg.device, cfg.seed, cfg.env_overrides(side)))
        samples: list[float] = []
        attempted = successful = 0
        with tqdm(total=cfg.successful_episodes, desc=f"footprint {side:.2f} m", unit="success") as bar:
            for _ in range(cfg.max_rounds):
                observer = ContactHeightObserver(env)
                episodes = run_first_episodes(env, policy, [observer])
                attempted += env.num_envs
                for w in np.flatnonzero(episodes.success)[: cfg.successful_episodes - successful]:
                    samples.extend(observer.heights[w])
                    successful += 1
                    bar.update(1)
                if successful >= cfg.successful_episodes:
                    break
        values = np.asarray(samples)
        heights.append(values)
        rows.append({"side_m": side, "episodes": attempted, "successful_episodes": successful,
                     "ee_height_in_contact_m": describe(values)})
    result = {"policy": str(policy_path), "footprints": rows,
              "config": dataclasses.asdict(cfg) | {"training_config_sha256": policy.contract.training_config_sha256}}
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "footprints.json").write_text(json.dumps(result, indent=2, allow_nan=False))
    plot_footprints(result, heights, out_dir / "footprints.png")
    return result


def plot_footprints(result: dict, heights: list[np.ndarray], path: Path) -> None:
    """Box plot of the EE height in contact per footprint (the paper's Fig. "EE height boxplot")."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4.5), layout="constrained")
    ax = fig.subplots()
    rows = result["footprints"]
    labels = [f"{r['side_m']:.2f}x{r['side_m']:.2f}\n({r['successful_episodes']} ep.)" for r in rows]
    ax.boxplot([h if h.size else [np.nan] for h in heights], tick_labels=labels, showfliers=False)
    ax.axhline(result["config"]["height"], color="gray", ls=":", label="object top")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_xlabel("object xy-footprint [m] (successful episodes)")
    ax.set_ylabel("EE height in contact, world z [m]")
    ax.set_title(f"EE height while pushing, object height {result['config']['height']} m")
    ax.grid(axis="y", alpha=0.3)
    fig.savefig(path, dpi=110)
