"""Scenario files: known objects and their goal sequences (the paper's hardware tests, IV-C), read and validated.

A scenario (YAML) lists objects (shape, size, mass, CoM offset, friction) and, per object, a sequence
of goals; ``scenarios.py`` runs it. File format (SI units, degrees where the key says so; every key but ``name``
of an object optional where a default is given)::

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
fixed poses, as on the hardware. A file that breaks these rules is a :class:`ConfigError` naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from dynpush.sim.config import ConfigError
from dynpush.sim.episode import SHAPES


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
