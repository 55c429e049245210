"""``dynpush play``: roll out a few episodes of an exported policy and show them.

Writes a top-down picture (world frame, x right, y up, metres) with, per episode, the paths of the robot
base, the end-effector and the object centroid, the object's outline at the start (dashed) and at the
end (solid), and the goal outline (green). Optionally records the rollout as a USD animation with
Newton's USD viewer (``newton.viewer.ViewerUSD``, 50 frames per second, worlds laid out side by side,
goal outlines as green lines), which opens in usdview. Every world plays its first episode; a world whose
episode ends early stays frozen in its last pose in the animation.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from dynpush.sim.episode import SHAPES
from dynpush.sim.envs import make_push_env
from dynpush.sim.push_env import PushEnv

from .env_probe import EnvProbe, yaw_of
from .episodes import run_first_episodes
from .onnx_policy import OnnxPolicy
from .trained_env import env_config_for


def outline(shape: str, dims, center, yaw: float) -> np.ndarray:
    """(k, 2) closed outline in the xy-plane of an object (cuboid rectangle or cylinder circle), world frame."""
    if shape == "cylinder":
        t = np.linspace(0.0, 2.0 * math.pi, 49)
        local = 0.5 * dims[0] * np.stack([np.cos(t), np.sin(t)], axis=1)
    else:
        hx, hy = 0.5 * dims[0], 0.5 * dims[1]
        local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy], [hx, hy]])
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(center)[:2]


def draw_outline(ax, shape: str, dims, center, yaw: float, **style) -> None:
    """Draws :func:`outline` and a tick from the centre along the object's +x axis."""
    points = outline(shape, dims, center, yaw)
    ax.plot(points[:, 0], points[:, 1], **style)
    tip = np.asarray(center[:2]) + 0.5 * dims[0] * np.array([math.cos(yaw), math.sin(yaw)])
    ax.plot([center[0], tip[0]], [center[1], tip[1]], **style)


@dataclass
class Trajectories:
    """Per step and world, while the world is in its first episode (NaN afterwards); world frame, m, rad."""

    base: list[np.ndarray]  # (n, 3): x, y, yaw
    ee: list[np.ndarray]  # (n, 2)
    object: list[np.ndarray]  # (n, 3): x, y, yaw


class TrajectoryObserver:
    """Records base, end-effector and object paths (and optionally USD frames) during a rollout."""

    def __init__(self, env: PushEnv, usd_path: Path | None = None):
        self.env = env
        self.probe = EnvProbe(env)
        self.paths = Trajectories([], [], [])
        self._record(torch.ones(env.num_envs, dtype=torch.bool))
        self.viewer = None
        if usd_path is not None:
            self._open_usd(usd_path)

    def _record(self, continuing: torch.Tensor) -> None:
        keep = continuing.cpu().numpy()[:, None]
        base, obj = self.probe.base(), self.probe.object()
        self.paths.base.append(np.where(keep, np.column_stack([base[:, :2], yaw_of(base[:, 3:])]), np.nan))
        self.paths.ee.append(np.where(keep, self.probe.ee_position()[:, :2], np.nan))
        self.paths.object.append(np.where(keep, np.column_stack([obj[:, :2], yaw_of(obj[:, 3:])]), np.nan))

    def _open_usd(self, path: Path) -> None:
        import warp as wp
        from newton.viewer import ViewerUSD

        env = self.env
        fps = int(round(1.0 / env.cfg.control_dt))
        self.viewer = ViewerUSD(str(path), fps=fps, up_axis="Z", num_frames=None)
        self.viewer.set_model(env.scene.model)  # after the reset: the viewer takes the selected object variants
        self.viewer.set_world_offsets((6.0, 6.0, 0.0))
        model = env.scene.model
        # Shown state: a copy of the simulation's, whose bodies stop updating once their world's episode ended.
        self.shown = model.state()
        self.shown_q = wp.to_torch(self.shown.body_q)
        self.shown_q.copy_(self.probe.body_q)
        self.body_world = torch.as_tensor(model.body_world.numpy(), dtype=torch.long, device=self.shown_q.device)
        self._log_usd_frame(0, first=True)

    def _log_usd_frame(self, frame: int, first: bool = False) -> None:
        import warp as wp

        self.viewer.begin_frame(frame * self.env.cfg.control_dt)
        self.viewer.log_state(self.shown)
        if first:  # goal outlines, constant over the animation
            goal = self.env.task.goal_pos.numpy()
            yaw = yaw_of(self.env.task.goal_quat.numpy())
            dims, shape = self.env.task.object_dims.numpy(), self.env.task.object_shape.numpy()
            offsets = self.viewer.world_offsets.numpy()
            starts, ends = [], []
            for w in range(self.env.num_envs):
                points = outline(SHAPES[shape[w]], dims[w], goal[w], float(yaw[w])) + offsets[w, :2]
                z = np.full((len(points), 1), 0.005)
                line = np.hstack([points, z])
                starts.append(line[:-1])
                ends.append(line[1:])
            self.viewer.log_lines("/goals", wp.array(np.vstack(starts), dtype=wp.vec3),
                                  wp.array(np.vstack(ends), dtype=wp.vec3), (0.1, 0.8, 0.2))
        self.viewer.end_frame()

    def observe(self, step: int, in_episode: torch.Tensor, continuing: torch.Tensor) -> None:
        self._record(continuing)
        if self.viewer is not None:
            moving = continuing[self.body_world.clamp(min=0)] & (self.body_world >= 0)
            self.shown_q[moving] = self.probe.body_q[moving]
            self._log_usd_frame(step + 1)

    def close(self) -> None:
        if self.viewer is not None:
            self.viewer.close()


def episode_setup(env: PushEnv, world: int) -> dict:
    """The object and goal of ``world``'s current episode (read right after its reset)."""
    task = env.task
    return {"shape": SHAPES[int(task.object_shape.numpy()[world])], "dims_m": task.object_dims.numpy()[world].tolist(),
            "mass_kg": float(task.object_mass.numpy()[world]),
            "goal": [*task.goal_pos.numpy()[world, :2].tolist(), float(yaw_of(task.goal_quat.numpy()[world:world + 1])[0])]}


def episode_row(setup: dict, dt: float, success: bool, toppled: bool, length_steps: int, first_success_step: int) -> dict:
    """One episode of the play/demo JSON and PNG: its setup plus the outcome (times in s)."""
    return {**setup, "success": success, "toppled": toppled, "length_s": length_steps * dt,
            "time_to_success_s": first_success_step * dt if first_success_step else None}


def concatenate_episodes(paths: list[Trajectories]) -> Trajectories:
    """Side by side (as worlds) the one-world paths of consecutive episodes, padded with NaN to the longest."""
    steps = max(len(p.base) for p in paths)

    def stacked(name: str) -> list[np.ndarray]:
        columns = []
        for p in paths:
            rows = np.concatenate(getattr(p, name), axis=0)  # (steps of this episode, k)
            columns.append(np.vstack([rows, np.full((steps - len(rows), rows.shape[1]), np.nan)]))
        return list(np.stack(columns, axis=1))  # steps x (episodes, k)

    return Trajectories(stacked("base"), stacked("ee"), stacked("object"))


def play(policy_path: Path, episodes: int, out: Path, usd: Path | None = None, noise: bool | None = None,
         seed: int = 0, overrides: tuple[str, ...] = ()) -> dict:
    """Rolls out ``episodes`` first episodes (one per world); writes the PNG ``out``, a JSON beside it, and ``usd``."""
    policy = OnnxPolicy(policy_path, batched=True)
    env = make_push_env(env_config_for(policy, episodes, noise, "cpu", seed, overrides))
    env.reset(randomize_episode_step=False)
    observer = TrajectoryObserver(env, usd)
    setups = [episode_setup(env, w) for w in range(episodes)]
    try:
        outcome = run_first_episodes(env, policy, [observer], started=True)
    finally:
        observer.close()
    rows = [episode_row(setups[w], env.cfg.control_dt, bool(outcome.success[w]), bool(outcome.toppled[w]),
                        int(outcome.length[w]), int(outcome.first_success_step[w])) for w in range(episodes)]
    result = {"policy": str(policy_path), "episodes": rows, "usd": str(usd) if usd else None}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(result, indent=2, allow_nan=False))
    plot_play(result, observer.paths, out)
    return result


def plot_play(result: dict, paths: Trajectories, path: Path) -> None:
    """One top-down panel per episode: base, end-effector and object paths, object and goal outlines."""
    from matplotlib.figure import Figure

    rows = result["episodes"]
    columns = min(len(rows), 4)
    fig = Figure(figsize=(4.2 * columns, 4.4 * math.ceil(len(rows) / columns)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(math.ceil(len(rows) / columns), columns, squeeze=False)).ravel()
    base, ee, obj = (np.stack(p) for p in (paths.base, paths.ee, paths.object))
    for w, (ax, row) in enumerate(zip(axes, rows)):
        last = np.flatnonzero(~np.isnan(obj[:, w, 0]))[-1]
        ax.plot(base[:, w, 0], base[:, w, 1], color="tab:blue", lw=1.2, label="robot base")
        ax.plot(ee[:, w, 0], ee[:, w, 1], color="tab:orange", lw=0.8, label="end-effector")
        ax.plot(obj[:, w, 0], obj[:, w, 1], color="k", lw=1.2, label="object centroid")
        bx, by, byaw = base[0, w]
        ax.annotate("", (bx + 0.3 * math.cos(byaw), by + 0.3 * math.sin(byaw)), (bx, by),
                    arrowprops={"arrowstyle": "->", "color": "tab:blue"})
        draw_outline(ax, row["shape"], row["dims_m"], obj[0, w, :2], obj[0, w, 2], color="gray", ls="--", lw=1)
        draw_outline(ax, row["shape"], row["dims_m"], obj[last, w, :2], obj[last, w, 2], color="k", lw=1.2)
        gx, gy, gyaw = row["goal"]
        draw_outline(ax, row["shape"], row["dims_m"], (gx, gy), gyaw, color="tab:green", lw=1.5)
        outcome = ("success at {:.1f} s".format(row["time_to_success_s"]) if row["success"]
                   else "toppled" if row["toppled"] else "failed")
        dims = "x".join(f"{d:.2f}" for d in (row["dims_m"] if row["shape"] == "cuboid" else row["dims_m"][1:]))
        ax.set_title(f"{w}: {row['shape']} {dims} m, {row['mass_kg']:.1f} kg\n{outcome} ({row['length_s']:.1f} s)",
                     fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    for ax in axes[len(rows):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(f"{Path(result['policy']).name}: top view (world frame, m); goal green, start dashed")
    fig.savefig(path, dpi=110)
