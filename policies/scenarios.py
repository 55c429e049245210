"""Scenario files: known objects pushed through goal sequences, as in the paper's hardware tests (IV-C).

A scenario (YAML) lists objects (shape, size, mass, CoM offset, friction) and, per object, a sequence
of goals. ``dynpush eval policy.onnx --scenario scenarios/hardware_like.yaml`` runs every object's
sequence ``trials`` times (all runs in parallel worlds) and reports, per object, the success rate per
goal and the contact face switches per goal, beside the paper's values where the file gives them.

File format (SI units, degrees where the key says so; every key but ``name`` of an object optional
where a default is given)::

    name: hardware_like
    trials: 12                 # runs of each object's goal sequence
    goal_timeout_s: 20.0       # time budget of one goal
    robot_start_radius: 1.5    # m: run i starts the robot on this circle at angle 2 pi i / trials, facing the object
    face_hold_s: 0.1           # s: a contact must stay on a face this long to count (face switches)
    objects:
      - name: P-CU
        shape: cuboid          # cuboid | cylinder
        size: [0.60, 0.34, 0.40]   # cuboid (x, y, z); cylinder (diameter, height)  [m]
        mass: 6.43             # kg
        com_offset: [0, 0, 0]  # m, object frame, from the centroid (default 0)
        friction: 1.0          # combined object-floor coefficient
        start_yaw_deg: 0       # the object's yaw at the start (it starts at the world origin)
        goals:                 # world frame
          - {position: [1.5, 0.0], yaw_change_deg: 180}
          - {position: [0.0, 0.0], yaw_change_deg: 180}
        paper: {success_rate: 91.6, face_switches_per_goal: 0.90}   # optional reference values

A goal's yaw is the previous goal's yaw plus ``yaw_change_deg`` (the first goal: the object's start
yaw plus it), so goals alternating between two positions with a change of 180 deg alternate between two
fixed poses, as on the hardware.

**How a sequence continues.** A goal ends on success (the first step with the environment's success
flag: within ``success_distance`` and ``success_angle``; a goal the object already meets when it starts
counts at once), on time-out (``goal_timeout_s``), or when the object topples
or the robot falls. After a success or a time-out the next goal starts at once from where the object and
the robot are: no manual repositioning, as on the hardware. A topple or fall ends the run (its remaining
goals are not attempted). The next goal is set with ``PushEnv.set_goals``: robot, object and arm keep
their state and velocities, only the goal and the episode clock change.

**Face switches** (IV-C: "a face switch is considered when the robot switches contact to a different
face of the cuboid"). While the end-effector touches the object (the environment's EE-object contact,
critic observation column 54), the contacted face is the vertical face of the cuboid whose outward
normal axis has the largest normalised end-effector coordinate in the object frame
(``argmax(|x| / (d_x / 2), |y| / (d_y / 2))`` with its sign: +x, -x, +y or -y); a touch from above the top
face counts as no vertical face. A face becomes *the contacted face* once it has been touched for
``face_hold_s`` without interruption (so grazing an edge does not count), and a face switch is counted
whenever the contacted face changes to a different one. The contacted face carries over from one goal to
the next (a robot that keeps pushing the same face for the next goal makes no switch). Face switches are
undefined for cylinders (reported as null), as in the paper. The per-object number is the mean over
successful goals.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import yaml
from tqdm import tqdm

from dynpush.sim.config import ConfigError
from dynpush.sim.episode import SHAPES, EpisodeSpec
from dynpush.sim.envs import make_push_env

from .env_probe import EE_CONTACT_COLUMN, EnvProbe
from .onnx_policy import OnnxPolicy
from .trained_env import env_config_for

FACE_NAMES = ("+x", "-x", "+y", "-y")  # vertical faces of a cuboid by outward normal (object frame)
NO_FACE = -1


# ---------------------------------------------------------------------------------------------- file format
@dataclass
class ScenarioGoal:
    """One goal: object centroid position (world frame, m) and yaw change from the previous goal (deg)."""

    position: tuple[float, float]
    yaw_change_deg: float = 0.0


@dataclass
class ScenarioObject:
    """One object and its goal sequence."""

    name: str
    shape: str
    size: tuple[float, ...]  # cuboid (x, y, z), cylinder (diameter, height) [m]
    mass: float  # kg
    friction: float  # combined object-floor coefficient
    goals: list[ScenarioGoal]
    com_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, object frame, from the centroid
    start_yaw_deg: float = 0.0
    paper: dict[str, float] = field(default_factory=dict)  # reference values (success_rate, face_switches_per_goal)

    @property
    def dims(self) -> tuple[float, float, float]:
        """Full side lengths as EpisodeSpec takes them (a cylinder: diameter, diameter, height)."""
        if self.shape == "cylinder":
            return (self.size[0], self.size[0], self.size[1])
        return tuple(self.size)

    def goal_poses(self) -> list[tuple[float, float, float]]:
        """(x, y, yaw [rad]) of each goal in the world frame."""
        yaw, poses = math.radians(self.start_yaw_deg), []
        for goal in self.goals:
            yaw += math.radians(goal.yaw_change_deg)
            poses.append((goal.position[0], goal.position[1], math.atan2(math.sin(yaw), math.cos(yaw))))
        return poses


@dataclass
class Scenario:
    """A scenario file (see the module docstring)."""

    name: str
    objects: list[ScenarioObject]
    trials: int = 12
    goal_timeout_s: float = 20.0
    robot_start_radius: float = 1.5
    face_hold_s: float = 0.1


def _number(value, where: str, low: float = -math.inf, high: float = math.inf, integer: bool = False) -> float:
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or not math.isfinite(value):
        raise ConfigError(f"{where} must be {'an integer' if integer else 'a number'}, got {value!r}")
    if not low <= value <= high:
        raise ConfigError(f"{where} must lie in [{low}, {high}], got {value!r}")
    return value if integer else float(value)


def _numbers(value, where: str, count: int, low: float = -math.inf, high: float = math.inf) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != count:
        raise ConfigError(f"{where} must be a list of {count} numbers, got {value!r}")
    return tuple(_number(v, f"{where}[{i}]", low, high) for i, v in enumerate(value))


def _mapping(value, where: str, required: set[str], optional: set[str]) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where} must be a mapping, got {value!r}")
    unknown = set(value) - required - optional
    if unknown:
        raise ConfigError(f"{where}.{sorted(unknown)[0]} is not a known field; allowed: {sorted(required | optional)}")
    missing = required - set(value)
    if missing:
        raise ConfigError(f"{where}.{sorted(missing)[0]} is required")
    return value


def _goal(data, where: str) -> ScenarioGoal:
    data = _mapping(data, where, {"position"}, {"yaw_change_deg"})
    return ScenarioGoal(position=_numbers(data["position"], f"{where}.position", 2, -50.0, 50.0),
                        yaw_change_deg=_number(data.get("yaw_change_deg", 0.0), f"{where}.yaw_change_deg", -360.0, 360.0))


def _object(data, where: str) -> ScenarioObject:
    optional = {"com_offset", "start_yaw_deg", "paper"}
    data = _mapping(data, where, {"name", "shape", "size", "mass", "friction", "goals"}, optional)
    if not isinstance(data["name"], str) or not data["name"]:
        raise ConfigError(f"{where}.name must be a non-empty string, got {data['name']!r}")
    if data["shape"] not in SHAPES:
        raise ConfigError(f"{where}.shape must be one of {SHAPES}, got {data['shape']!r}")
    size_count = 2 if data["shape"] == "cylinder" else 3
    size_help = "(diameter, height)" if size_count == 2 else "(x, y, z)"
    if not isinstance(data["size"], (list, tuple)) or len(data["size"]) != size_count:
        raise ConfigError(f"{where}.size of a {data['shape']} must be {size_count} lengths {size_help} [m], got {data['size']!r}")
    goals = data["goals"]
    if not isinstance(goals, list) or not goals:
        raise ConfigError(f"{where}.goals must be a non-empty list of goals, got {goals!r}")
    paper = _mapping(data.get("paper", {}), f"{where}.paper", set(), {"success_rate", "face_switches_per_goal"})
    return ScenarioObject(
        name=data["name"],
        shape=data["shape"],
        size=_numbers(data["size"], f"{where}.size", size_count, 0.05, 2.0),
        mass=_number(data["mass"], f"{where}.mass", 1e-3, 1e3),
        friction=_number(data["friction"], f"{where}.friction", 0.0, 5.0),
        goals=[_goal(g, f"{where}.goals[{i}]") for i, g in enumerate(goals)],
        com_offset=_numbers(data.get("com_offset", [0.0, 0.0, 0.0]), f"{where}.com_offset", 3, -1.0, 1.0),
        start_yaw_deg=_number(data.get("start_yaw_deg", 0.0), f"{where}.start_yaw_deg", -360.0, 360.0),
        paper={k: _number(v, f"{where}.paper.{k}", 0.0) for k, v in paper.items()},
    )


def parse_scenario(data, where: str = "scenario") -> Scenario:
    """Validates a parsed YAML document; errors name the offending field (e.g. ``scenario.objects[1].mass``)."""
    data = _mapping(data, where, {"name", "objects"}, {"trials", "goal_timeout_s", "robot_start_radius", "face_hold_s"})
    if not isinstance(data["objects"], list) or not data["objects"]:
        raise ConfigError(f"{where}.objects must be a non-empty list of objects, got {data['objects']!r}")
    objects = [_object(o, f"{where}.objects[{i}]") for i, o in enumerate(data["objects"])]
    names = [o.name for o in objects]
    if len(set(names)) != len(names):
        raise ConfigError(f"{where}.objects[].name must be unique, got {names}")
    return Scenario(
        name=str(data["name"]),
        objects=objects,
        trials=_number(data.get("trials", 12), f"{where}.trials", 1, 10000, integer=True),
        goal_timeout_s=_number(data.get("goal_timeout_s", 20.0), f"{where}.goal_timeout_s", 0.02, 3600.0),
        robot_start_radius=_number(data.get("robot_start_radius", 1.5), f"{where}.robot_start_radius", 0.5, 20.0),
        face_hold_s=_number(data.get("face_hold_s", 0.1), f"{where}.face_hold_s", 0.0, 10.0),
    )


def load_scenario(path: Path) -> Scenario:
    """Reads and validates a scenario YAML file."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ConfigError(f"{path}: not valid YAML: {error}") from error
    return parse_scenario(data, where=path.stem)


# ---------------------------------------------------------------------------------------------- face switches
def contact_face(ee_o: np.ndarray, dims: np.ndarray) -> np.ndarray:
    """Index into :data:`FACE_NAMES` of the vertical cuboid face at the end-effector, per row.

    ``ee_o`` (n, 3): end-effector point in the object frame [m]; ``dims`` (n, 3): full side lengths [m].
    :data:`NO_FACE` where the end-effector is above the top face.
    """
    half = 0.5 * np.asarray(dims, dtype=np.float64)
    u = ee_o[:, :2] / half[:, :2]
    axis = np.argmax(np.abs(u), axis=1)
    along = u[np.arange(len(u)), axis]
    face = 2 * axis + (along < 0)
    above_top = (ee_o[:, 2] > half[:, 2]) & (np.abs(along) <= 1.0)
    return np.where(above_top, NO_FACE, face)


class FaceTracker:
    """Contacted face and face-switch count of many worlds (see the module docstring)."""

    def __init__(self, count: int, hold_steps: int):
        self.hold_steps = max(1, hold_steps)
        self.face = np.full(count, NO_FACE)  # the contacted face
        self.candidate = np.full(count, NO_FACE)  # face touched in the current uninterrupted run
        self.run = np.zeros(count, dtype=np.int64)  # steps of that run
        self.switches = np.zeros(count, dtype=np.int64)

    def update(self, touched: np.ndarray) -> None:
        """One control step: ``touched`` is each world's touched face, or :data:`NO_FACE`."""
        same = (touched == self.candidate) & (touched != NO_FACE)
        self.run = np.where(same, self.run + 1, (touched != NO_FACE).astype(np.int64))
        self.candidate = touched.copy()
        confirmed = (self.run >= self.hold_steps) & (touched != self.face)
        self.switches += confirmed & (self.face != NO_FACE)
        self.face = np.where(confirmed, touched, self.face)


def count_face_switches(faces: list[int] | np.ndarray, hold_steps: int) -> int:
    """Face switches of one contact sequence (a face index or :data:`NO_FACE` per control step)."""
    tracker = FaceTracker(1, hold_steps)
    for face in faces:
        tracker.update(np.array([face]))
    return int(tracker.switches[0])


# ---------------------------------------------------------------------------------------------- running
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
    min_friction = 0.5 * env.scene.ground_friction
    for i, obj in enumerate(scenario.objects):
        if obj.friction < min_friction:
            raise ConfigError(f"{scenario.name}.objects[{i}].friction must be >= {min_friction} (half the floor's"
                              f" own coefficient in ground.usda), got {obj.friction}")
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
            for w in np.flatnonzero(ended):  # the environment reset this world: its object is gone
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


def plot_scenario(scenario: Scenario, result: dict, paths: np.ndarray, path: Path) -> None:
    """Success rate and face switches per object beside the paper's; the object paths of the first run."""
    from matplotlib.figure import Figure

    from .play import draw_outline

    count = len(scenario.objects)
    fig = Figure(figsize=(max(10, 3 * count), 8), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=(1, 1.1))
    ax_success, ax_switches = top.subplots(1, 2)
    names = [o.name for o in scenario.objects]
    x = np.arange(count)
    rows = [result["objects"][name] for name in names]
    for ax, key, label in ((ax_success, "success_rate", "success rate [%]"),
                           (ax_switches, "face_switches_per_goal", "face switches / successful goal")):
        ours = [np.nan if r[key] is None else r[key] for r in rows]  # no bar where undefined
        paper = [r["paper"].get(key, np.nan) for r in rows]
        ax.bar(x - 0.2, ours, 0.4, label="this policy")
        ax.bar(x + 0.2, paper, 0.4, label="paper (hardware)", color="tab:gray")
        ax.set_xticks(x, names, fontsize=8, rotation=20)
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    ax_success.set_ylim(0, 105)
    ax_switches.set_ylim(bottom=0)
    ax_success.set_title(f"{scenario.name}: {scenario.trials} runs per object")
    ax_switches.set_title("contact face switches (cuboids)")

    axes = np.atleast_1d(bottom.subplots(1, count))
    for index, (ax, obj) in enumerate(zip(axes, scenario.objects)):
        ax.plot(paths[:, index, 1, 0], paths[:, index, 1, 1], color="tab:blue", lw=0.8, label="robot base (run 0)")
        ax.plot(paths[:, index, 0, 0], paths[:, index, 0, 1], color="k", lw=1.2, label="object (run 0)")
        ax.plot(0.0, 0.0, "ko", ms=3)
        labels: dict[tuple[float, float], list[str]] = {}  # goals at one position share a label: "1,3"
        for k, (gx, gy, gyaw) in enumerate(obj.goal_poses()):
            draw_outline(ax, obj.shape, obj.dims, (gx, gy), gyaw, color="tab:green", ls="-", lw=1)
            labels.setdefault((round(gx, 3), round(gy, 3)), []).append(str(k + 1))
        for (gx, gy), numbers in labels.items():
            ax.annotate(",".join(numbers), (gx, gy), color="tab:green", fontsize=8, ha="center", va="center")
        draw_outline(ax, obj.shape, obj.dims, (0.0, 0.0), math.radians(obj.start_yaw_deg), color="gray", ls="--", lw=1)
        # Frame the object's path and the goals; a robot that wanders off leaves the picture.
        points = np.vstack([paths[:, index, 0][~np.isnan(paths[:, index, 0, 0])], [(0.0, 0.0)],
                            [pose[:2] for pose in obj.goal_poses()]])
        low, high = points.min(axis=0) - 1.0, points.max(axis=0) + 1.0
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_aspect("equal", adjustable="box")
        outcomes = result["objects"][obj.name]["outcomes"]
        ax.set_title(f"{obj.name}\n" + ", ".join(f"{v} {k}" for k, v in outcomes.items() if v), fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=7)
    fig.savefig(path, dpi=100)
