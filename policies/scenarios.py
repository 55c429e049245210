"""Scenario runs: each object of a scenario file pushed through its goal sequence, as in the hardware tests (IV-C).

``dynpush scenario policy.onnx scenarios/hardware_like.yaml`` runs every object's sequence ``trials`` times
(all runs in parallel worlds) and reports, per object, the success rate per goal and the contact face switches per
goal, beside the paper's values where the file gives them (``scenario.json``, and ``scenario.png`` by
``scenario_plot.py``). The file format is ``scenario_schema.py``'s.

**How a sequence continues.** A goal ends on success (the first step with the environment's success
flag: within ``success_distance`` and ``success_angle``; a goal the object already meets when it starts
counts at once), on time-out (``goal_timeout_s``), or when the object topples
or the robot falls. After a success or a time-out the next goal starts at once from where the object and
the robot are: no manual repositioning, as on the hardware. A topple or fall ends the run (its remaining
goals are not attempted). The next goal is set with ``PushEnv.set_goals``: robot, object and arm keep
their state and velocities, only the goal and the episode clock change.

**Face switches** (``face_switches.py``). The end-effector touches the object while the environment's EE-object
contact (critic observation column 54) is set; a face must be touched for ``face_hold_s`` to become the contacted
face. The contacted face carries over from one goal to the next (a robot that keeps pushing the same face for the
next goal makes no switch). Cylinders report null. The per-object number is the mean over successful goals.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from dynpush.sim.config import check_object_friction
from dynpush.sim.episode import EpisodeSpec
from dynpush.sim.envs import make_push_env

from .env_probe import EE_CONTACT_COLUMN, EnvProbe
from .face_switches import NO_FACE, FaceTracker, contact_face
from .onnx_policy import OnnxPolicy
from .scenario_plot import plot_scenario
from .scenario_schema import Scenario
from .trained_env import env_config_for


@dataclass
class GoalRecord:
    """The outcome of one goal of one run."""

    object: str
    trial: int
    goal: int
    outcome: str  # success | timeout | toppled | fallen
    time_s: float
    face_switches: int | None  # None for cylinders
    final_distance_m: float | None  # object centroid to goal, xy (None: the object toppled)


def run_scenario(policy_path: Path, scenario: Scenario, out_dir: Path, noise: bool | None = None,
                 device: str = "cpu", seed: int = 0, overrides: tuple[str, ...] = ()) -> dict:
    """Runs every object's goal sequence ``scenario.trials`` times; writes ``scenario.json`` and ``scenario.png``."""
    policy = OnnxPolicy(policy_path, batched=True)
    worlds = [(o, t) for o in range(len(scenario.objects)) for t in range(scenario.trials)]
    # The environment's own time-out must never end a goal: the per-goal budget is enforced here.
    env_overrides = (*overrides, f"env.episode_length_s={scenario.goal_timeout_s + 1.0}")
    env_cfg = env_config_for(policy, len(worlds), noise, device, seed, env_overrides)
    env = make_push_env(env_cfg)
    for i, obj in enumerate(scenario.objects):
        check_object_friction(f"{scenario.name}.objects[{i}].friction", obj.friction, env.scene.ground_friction)
    probe = EnvProbe(env)
    dt = env_cfg.control_dt
    budget = int(round(scenario.goal_timeout_s / dt))
    objects = [scenario.objects[o] for o, _ in worlds]
    dims = np.array([obj.dims for obj in objects])
    cuboid = np.array([obj.shape == "cuboid" for obj in objects])
    goals = [obj.goal_poses() for obj in objects]
    n = len(worlds)

    goal_index = np.zeros(n, dtype=np.int64)
    goal_step = np.zeros(n, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    faces = FaceTracker(n, int(round(scenario.face_hold_s / dt)))
    switches_at_start = np.zeros(n, dtype=np.int64)
    records: list[GoalRecord] = []
    paths: list[np.ndarray] = []  # (n, 2, 2) object centroid and robot base per step, scenario frame (NaN once over)

    def start_first_goals() -> None:
        """Places every world's object at the origin and its robot on the start circle, facing it."""
        episodes = {}
        for w, obj in enumerate(objects):
            angle = 2.0 * math.pi * worlds[w][1] / scenario.trials
            r = scenario.robot_start_radius
            episodes[w] = EpisodeSpec(shape=obj.shape, dims=obj.dims, mass=obj.mass, com_offset=obj.com_offset,
                                      friction=obj.friction, object_yaw=math.radians(obj.start_yaw_deg),
                                      goal=goals[w][0], base=(r * math.cos(angle), r * math.sin(angle), angle + math.pi))
        env.set_episodes(episodes)

    def start_next_goals(selected: np.ndarray) -> None:
        env.set_goals({int(w): goals[w][goal_index[w]] for w in np.flatnonzero(selected)})
        goal_step[selected] = 0
        switches_at_start[selected] = faces.switches[selected]

    def finish(w: int, outcome: str) -> None:
        obj_xy = probe.object()[w, :2]
        gx, gy, _ = goals[w][goal_index[w]]
        records.append(GoalRecord(
            object=objects[w].name, trial=worlds[w][1], goal=int(goal_index[w]), outcome=outcome,
            time_s=float(goal_step[w] * dt),
            face_switches=int(faces.switches[w] - switches_at_start[w]) if cuboid[w] else None,
            final_distance_m=float(np.hypot(obj_xy[0] - gx, obj_xy[1] - gy))))

    start_first_goals()
    total_goals = sum(len(g) for g in goals)
    with tqdm(total=total_goals, desc=f"scenario {scenario.name}", unit="goal") as bar:
        while not done.all():
            obs = env.get_observations()["policy"]
            env.step(torch.from_numpy(policy(obs.cpu().numpy())).to(env.device))
            active = ~done
            goal_step[active] += 1
            ended = (env.reset_t != 0).cpu().numpy() & active
            success = (env.success_t != 0).cpu().numpy() & active & ~ended
            touching = (env.critic_obs_t[:, EE_CONTACT_COLUMN] > 0.5).cpu().numpy() & active & ~ended & cuboid
            faces.update(np.where(touching, contact_face(probe.ee_in_object(), dims), NO_FACE))
            xy = np.stack([probe.object()[:, :2], probe.base()[:, :2]], axis=1)
            xy[done | ended] = np.nan
            paths.append(xy)
            toppled = env.episode_toppled_t.cpu().numpy() == 1
            for w in np.flatnonzero(ended):  # the environment reset this world (toppled, fallen or diverged)
                records.append(GoalRecord(objects[w].name, worlds[w][1], int(goal_index[w]),
                                          "toppled" if toppled[w] else "fallen", float(goal_step[w] * dt),
                                          None, None))
                bar.update(len(goals[w]) - goal_index[w])
                done[w] = True
            timeout = active & ~ended & ~success & (goal_step >= budget)
            next_goal = np.zeros(n, dtype=bool)
            for w in np.flatnonzero(success | timeout):
                finish(w, "success" if success[w] else "timeout")
                bar.update(1)
                goal_index[w] += 1
                if goal_index[w] == len(goals[w]):
                    done[w] = True
                else:
                    next_goal[w] = True
            if next_goal.any():
                start_next_goals(next_goal)

    result = summarize(scenario, records, dt)
    result["config"] = {"scenario": dataclasses.asdict(scenario), "noise": env_cfg.noise.enabled, "seed": seed,
                        "env_overrides": list(env_overrides),
                        "training_config_sha256": policy.contract.training_config_sha256}
    result["policy"] = str(policy_path)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "scenario.json").write_text(json.dumps(result, indent=2, allow_nan=False))
    first_trial = [worlds.index((o, 0)) for o in range(len(scenario.objects))]
    plot_scenario(scenario, result, np.stack(paths)[:, first_trial], out_dir / "scenario.png")
    return result


def summarize(scenario: Scenario, records: list[GoalRecord], dt: float) -> dict:
    """Per object: goals attempted, success rate (%), face switches per successful goal, time per goal."""
    objects = {}
    for obj in scenario.objects:
        own = [r for r in records if r.object == obj.name]
        won = [r for r in own if r.outcome == "success"]
        switches = [r.face_switches for r in won if r.face_switches is not None]
        objects[obj.name] = {
            "goals_attempted": len(own),
            "goals_planned": len(obj.goals) * scenario.trials,
            "success_rate": 100.0 * len(won) / len(own) if own else None,
            "face_switches_per_goal": float(np.mean(switches)) if switches else None,
            "time_per_successful_goal_s": float(np.mean([r.time_s for r in won])) if won else None,
            "outcomes": {k: sum(r.outcome == k for r in own) for k in ("success", "timeout", "toppled", "fallen")},
            "paper": obj.paper,
        }
    return {"scenario": scenario.name, "objects": objects, "goals": [dataclasses.asdict(r) for r in records]}
