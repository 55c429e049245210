"""The runtime's YAML configuration: typed dataclasses, validated with errors naming the field.

A config file holds the sections ``mocap``, ``robot``, ``push_policy``, ``locomotion``, ``rates``,
``safety``, ``goals`` and ``log`` (every field documented below and in ``configs/runtime_*.yaml``).
Unknown keys, wrong types and values outside the allowed set raise :class:`RuntimeConfigError` whose
message names the field (``mocap.frames.up_axis``) and what it allows. Relative input paths
(``push_policy.path``, ``locomotion.onnx.path``, ``mocap.replay_log``) are relative to the config
file; ``log.directory`` is relative to the working directory.

Frames and units: goals are in the runtime's world frame (Z-up, metres, yaw in degrees about z);
limits are radians (joints) and the locomotion command's units (m/s, rad/s, rad, m).

Network trust: every UDP socket binds to one named IPv4 address (``bind_address``; the wildcard 0.0.0.0
is refused) and takes datagrams only from the addresses in its section's ``allowed_senders``; goals
must lie within ``goals.workspace`` (``trust.py``, ``goals.py``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import ipaddress
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from dynpush.assets_usd import ARM_JOINT_NAMES
from dynpush.errors import UserError

from .frames import QUATERNION_ORDERS, UNITS, UP_AXES, BodyOffset, FrameConvention
from .locomotion_layout import LOCOMOTION_TERMS, NUM_LEG_JOINTS
from .observation import NUM_ARM_JOINTS

MOTIONCAPTURE_SOURCES = ("vicon", "optitrack", "qualisys", "vrpn", "mock")  # motioncapture.connect types
MOCAP_SOURCES = ("udp", "replay", *MOTIONCAPTURE_SOURCES)
ROBOT_LINKS = ("udp",)
LOCOMOTION_MODES = ("onboard", "onnx")
CLOCKS = ("realtime", "lockstep")
MAX_TIMEOUT_S = 1.0  # staleness limits: older measurements must stop the robot within a second
MAX_RAMP_S = 60.0
MAX_ADVANCE_AFTER_S = 3600.0
MAX_OVERRUN_WINDOW = 500  # control periods (10 s at 50 Hz): the overrun check is about the last seconds, not the run
LOOPBACK = "127.0.0.1"


class RuntimeConfigError(UserError, ValueError):
    """An invalid runtime configuration; the message names the field and the allowed values."""


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise RuntimeConfigError(message)


def _check_choice(name: str, value: str, allowed: tuple[str, ...]) -> None:
    _require(value in allowed, f"{name} must be one of {list(allowed)}, got {value!r}")


def _check_positive(name: str, value: float) -> None:
    _require(math.isfinite(value) and value > 0.0, f"{name} must be a finite number > 0, got {value!r}")


def _check_at_most(name: str, value: float, upper: float) -> None:
    _require(value <= upper, f"{name} must be <= {upper}, got {value!r}")


def _check_finite(name: str, values: list[float]) -> None:
    for i, value in enumerate(values):
        _require(math.isfinite(value), f"{name}[{i}] must be finite, got {value!r}")


def _ipv4(name: str, value: str) -> ipaddress.IPv4Address:
    try:
        return ipaddress.IPv4Address(value)
    except ValueError:
        raise RuntimeConfigError(f"{name} must be an IPv4 address such as {LOOPBACK}, got {value!r}") from None


def _check_bind_address(name: str, value: str) -> None:
    _require(not _ipv4(name, value).is_unspecified, f"{name} must name one interface's address ({LOOPBACK}, or this"
             f" computer's address on the robot's network), not {value!r}, which listens on every interface")


def _check_senders(name: str, values: list[str]) -> None:
    _require(bool(values), f"{name} must list at least one sender address (e.g. [{LOOPBACK}])")
    for i, value in enumerate(values):
        _ipv4(f"{name}[{i}]", value)


def _check_port(name: str, value: int) -> None:
    _require(0 <= value <= 65535, f"{name} must be a UDP port in [0, 65535] (0 = any free port), got {value!r}")


def _check_length(name: str, value: list, size: int, allow_empty: bool = False) -> None:
    ok = len(value) == size or (allow_empty and not value)
    _require(ok, f"{name} must have {size} entries{' (or be empty)' if allow_empty else ''}, got {len(value)}")


def _check_limits(prefix: str, lower: list[float], upper: list[float], size: int, required: bool) -> None:
    _check_length(f"{prefix}_lower", lower, size, allow_empty=not required)
    _check_length(f"{prefix}_upper", upper, size, allow_empty=not required)
    _require(bool(lower) == bool(upper), f"{prefix}_lower and {prefix}_upper must both be given or both be empty")
    for i, (lo, hi) in enumerate(zip(lower, upper)):
        _require(lo <= hi, f"{prefix}_lower[{i}] must be <= {prefix}_upper[{i}], got {lo} > {hi}")


@dataclass
class MocapConfig:
    """Where the base and object poses come from.

    ``source``: ``udp`` (``DPM1`` datagrams, see packets.py), ``replay`` (the mocap poses of a tick
    log), or a ``motioncapture`` system type (vicon, optitrack, qualisys, vrpn, mock).
    """

    source: str = "udp"
    base_body: str = "base"  # rigid-body name of the robot base in the mocap system
    object_body: str = "object"  # rigid-body name of the pushed object
    timeout_s: float = 0.1  # a pose older than this (since it was received) is stale
    frames: FrameConvention = field(default_factory=FrameConvention)
    base_offset: BodyOffset = field(default_factory=BodyOffset)  # robot base frame in the tracked frame
    object_offset: BodyOffset = field(default_factory=BodyOffset)  # object centroid frame in the tracked frame
    bind_address: str = LOOPBACK  # udp: listen address (127.0.0.1 unless the stream comes from another host)
    port: int = 9870  # udp
    allowed_senders: list[str] = field(default_factory=lambda: [LOOPBACK])  # udp: addresses DPM1 is taken from
    hostname: str = ""  # motioncapture: address of the mocap server
    options: dict[str, str] = field(default_factory=dict)  # motioncapture: extra connect() options
    replay_log: str = ""  # replay: a tick log written by this runtime

    def validate(self, prefix: str = "mocap") -> None:
        _check_choice(f"{prefix}.source", self.source, MOCAP_SOURCES)
        _require(bool(self.base_body) and bool(self.object_body) and self.base_body != self.object_body,
                 f"{prefix}.base_body and {prefix}.object_body must be two different non-empty names")
        _check_positive(f"{prefix}.timeout_s", self.timeout_s)
        _check_at_most(f"{prefix}.timeout_s", self.timeout_s, MAX_TIMEOUT_S)
        f = self.frames
        _check_choice(f"{prefix}.frames.up_axis", f.up_axis, UP_AXES)
        _check_choice(f"{prefix}.frames.quaternion_order", f.quaternion_order, QUATERNION_ORDERS)
        _check_choice(f"{prefix}.frames.units", f.units, tuple(UNITS))
        for name in ("base_offset", "object_offset"):
            offset = getattr(self, name)
            _check_length(f"{prefix}.{name}.position", offset.position, 3)
            _check_length(f"{prefix}.{name}.quat_xyzw", offset.quat_xyzw, 4)
            _check_finite(f"{prefix}.{name}.position", offset.position)
            _check_finite(f"{prefix}.{name}.quat_xyzw", offset.quat_xyzw)
            _require(math.hypot(*offset.quat_xyzw) > 1e-6, f"{prefix}.{name}.quat_xyzw must be non-zero")
        _check_bind_address(f"{prefix}.bind_address", self.bind_address)
        _check_port(f"{prefix}.port", self.port)
        _check_senders(f"{prefix}.allowed_senders", self.allowed_senders)
        if self.source in MOTIONCAPTURE_SOURCES:
            _require(f.quaternion_order == "xyzw", f"{prefix}.frames.quaternion_order must be 'xyzw' for the motioncapture"
                     f" package (it names its quaternion components), got {f.quaternion_order!r}")
        if self.source == "replay":
            _require(bool(self.replay_log), f"{prefix}.replay_log must name a tick log when {prefix}.source is 'replay'")
            _require(f.is_runtime_convention(), f"{prefix}.frames must be up_axis 'z', quaternion_order 'xyzw', units 'm'"
                     " for replay (tick logs hold converted poses)")


@dataclass
class RobotConfig:
    """The robot link: state in, targets out (``DPS1`` / ``DPC1`` over UDP, see packets.py)."""

    link: str = "udp"
    bind_address: str = LOOPBACK  # the runtime receives robot state here
    port: int = 9871
    allowed_senders: list[str] = field(default_factory=lambda: [LOOPBACK])  # addresses DPS1 is taken from
    robot_address: str = ""  # commands go to (robot_address, robot_port); "" = the first admitted state's sender
    robot_port: int = 9872
    timeout_s: float = 0.1  # robot state older than this stops the robot (damping)
    arm_joint_names: list[str] = field(default_factory=lambda: list(ARM_JOINT_NAMES[:NUM_ARM_JOINTS]))
    leg_joint_names: list[str] = field(default_factory=list)  # order of leg_q and leg targets (onnx locomotion)

    def validate(self, prefix: str = "robot") -> None:
        _check_choice(f"{prefix}.link", self.link, ROBOT_LINKS)
        _check_bind_address(f"{prefix}.bind_address", self.bind_address)
        _check_port(f"{prefix}.port", self.port)
        _check_senders(f"{prefix}.allowed_senders", self.allowed_senders)
        if self.robot_address:
            _ipv4(f"{prefix}.robot_address", self.robot_address)
        _check_port(f"{prefix}.robot_port", self.robot_port)
        _check_positive(f"{prefix}.timeout_s", self.timeout_s)
        _check_at_most(f"{prefix}.timeout_s", self.timeout_s, MAX_TIMEOUT_S)
        _check_length(f"{prefix}.arm_joint_names", self.arm_joint_names, NUM_ARM_JOINTS)
        _check_length(f"{prefix}.leg_joint_names", self.leg_joint_names, NUM_LEG_JOINTS, allow_empty=True)


@dataclass
class PushPolicyConfig:
    path: str = ""  # the exported push policy (ONNX with the PolicyContract in its metadata)

    def validate(self, prefix: str = "push_policy") -> None:
        _require(bool(self.path), f"{prefix}.path must name the push policy ONNX file")


@dataclass
class LocomotionTerm:
    """One block of the locomotion observation: ``scale * term`` (term sizes in ``LOCOMOTION_TERMS``)."""

    name: str = ""
    scale: float = 1.0


@dataclass
class OnnxLocomotionConfig:
    """A learned locomotion policy run by this runtime: 6D command -> 12 leg joint targets.

    Leg targets = ``default_joint_positions + action_scale * output``, in ``joint_names`` order.
    """

    path: str = ""
    input_name: str = "obs"
    output_name: str = "actions"
    observation: list[LocomotionTerm] = field(default_factory=list)
    joint_names: list[str] = field(default_factory=list)  # (12,) leg joints, in the network's order
    default_joint_positions: list[float] = field(default_factory=list)  # (12,) [rad]
    action_scale: float = 0.5  # rad per unit output

    @property
    def observation_size(self) -> int:
        return sum(LOCOMOTION_TERMS[t.name] for t in self.observation)

    def validate(self, prefix: str) -> None:
        _require(bool(self.path), f"{prefix}.path must name the locomotion ONNX file")
        _require(bool(self.observation), f"{prefix}.observation must list at least one term of {list(LOCOMOTION_TERMS)}")
        for i, term in enumerate(self.observation):
            _check_choice(f"{prefix}.observation[{i}].name", term.name, tuple(LOCOMOTION_TERMS))
            _require(math.isfinite(term.scale), f"{prefix}.observation[{i}].scale must be finite")
        _check_length(f"{prefix}.joint_names", self.joint_names, NUM_LEG_JOINTS)
        _check_length(f"{prefix}.default_joint_positions", self.default_joint_positions, NUM_LEG_JOINTS)
        _check_finite(f"{prefix}.default_joint_positions", self.default_joint_positions)
        _check_positive(f"{prefix}.action_scale", self.action_scale)


@dataclass
class LocomotionConfig:
    """``onboard``: the robot's own locomotion takes the 6D base command; ``onnx``: this runtime runs it."""

    mode: str = "onboard"
    onnx: OnnxLocomotionConfig = field(default_factory=OnnxLocomotionConfig)

    def validate(self, prefix: str = "locomotion") -> None:
        _check_choice(f"{prefix}.mode", self.mode, LOCOMOTION_MODES)
        if self.mode == "onnx":
            self.onnx.validate(f"{prefix}.onnx")


@dataclass
class OverrunConfig:
    """How many control deadlines the runtime may skip (its own ticks overran) before it stops the robot.

    More than ``max_skipped`` skipped among the last ``window_periods`` deadlines latches STOPPED
    (``timing.OverrunGuard``). The default, 5 of 50 (1 s at 50 Hz), asks the runtime to keep 90 % of the control
    rate in every second, the bound sim2sim asks of the simulator (``min_rate``): one stall that skips 5 deadlines
    (about 0.1 s without a new command) passes; a computer that keeps losing ticks, and so drives the robot at a
    rate its policy was not trained for, is stopped.
    """

    max_skipped: int = 5  # skipped deadlines allowed within the window; one more is a fault
    window_periods: int = 50  # [control periods]

    def validate(self, prefix: str) -> None:
        window = self.window_periods
        _require(1 <= window <= MAX_OVERRUN_WINDOW,
                 f"{prefix}.window_periods must be an integer in [1, {MAX_OVERRUN_WINDOW}], got {window!r}")
        _require(0 <= self.max_skipped < window, f"{prefix}.max_skipped must be an integer in [0, {window - 1}]"
                 f" (fewer than {prefix}.window_periods), got {self.max_skipped!r}")


@dataclass
class RatesConfig:
    control_hz: float = 50.0  # must equal the push policy's control rate (paper III: 50 Hz)
    clock: str = "realtime"  # realtime: perf_counter deadlines; lockstep: one tick per robot state (simulators)
    log_flush_s: float = 1.0  # the tick log reaches the OS at least this often
    overrun: OverrunConfig = field(default_factory=OverrunConfig)  # skipped deadlines that stop the robot

    def validate(self, prefix: str = "rates") -> None:
        _check_positive(f"{prefix}.control_hz", self.control_hz)
        _check_choice(f"{prefix}.clock", self.clock, CLOCKS)
        _check_positive(f"{prefix}.log_flush_s", self.log_flush_s)
        _require(self.log_flush_s <= 1.0, f"{prefix}.log_flush_s must be <= 1 s, got {self.log_flush_s}")
        self.overrun.validate(f"{prefix}.overrun")


@dataclass
class SafetyConfig:
    """Limits of the safety state machine (safety.py). Empty limit lists use the policy contract's."""

    arm_ramp_s: float = 2.0  # duration of the start-up ramp of the arm to its default pose [s]
    max_tilt_deg: float = 30.0  # base tilt (IMU) beyond which the robot is stopped [deg]
    arm_joint_lower: list[float] = field(default_factory=list)  # (5,) [rad], within the contract's
    arm_joint_upper: list[float] = field(default_factory=list)
    base_command_lower: list[float] = field(default_factory=list)  # (6,) within the contract's
    base_command_upper: list[float] = field(default_factory=list)
    leg_joint_lower: list[float] = field(default_factory=list)  # (12,) [rad], required with onnx locomotion
    leg_joint_upper: list[float] = field(default_factory=list)

    def validate(self, prefix: str = "safety", legs_required: bool = False) -> None:
        _check_positive(f"{prefix}.arm_ramp_s", self.arm_ramp_s)
        _check_at_most(f"{prefix}.arm_ramp_s", self.arm_ramp_s, MAX_RAMP_S)
        _require(0.0 < self.max_tilt_deg < 90.0, f"{prefix}.max_tilt_deg must lie in (0, 90), got {self.max_tilt_deg!r}")
        _check_limits(f"{prefix}.arm_joint", self.arm_joint_lower, self.arm_joint_upper, NUM_ARM_JOINTS, False)
        _check_limits(f"{prefix}.base_command", self.base_command_lower, self.base_command_upper, 6, False)
        _check_limits(f"{prefix}.leg_joint", self.leg_joint_lower, self.leg_joint_upper, NUM_LEG_JOINTS, legs_required)


@dataclass
class GoalConfig:
    x: float = 0.0  # object goal position, world frame [m]
    y: float = 0.0
    yaw_deg: float = 0.0  # object goal yaw about world z [deg]


@dataclass
class WorkspaceConfig:
    """Where goals may lie: the rectangle the robot may push objects in, world frame [m]."""

    x_min: float = -5.0
    x_max: float = 5.0
    y_min: float = -5.0
    y_max: float = 5.0

    def validate(self, prefix: str) -> None:
        for axis in ("x", "y"):
            lower, upper = getattr(self, f"{axis}_min"), getattr(self, f"{axis}_max")
            _require(math.isfinite(lower) and math.isfinite(upper) and lower < upper,
                     f"{prefix}.{axis}_min and {prefix}.{axis}_max must be finite with {axis}_min < {axis}_max,"
                     f" got {lower!r}, {upper!r}")

    def outside(self, x: float, y: float) -> str | None:
        """Why the point (x, y) [m] is no goal (outside the rectangle or not finite), or None."""
        for axis, value in (("x", x), ("y", y)):
            lower, upper = getattr(self, f"{axis}_min"), getattr(self, f"{axis}_max")
            if not math.isfinite(value):
                return f"{axis} {value!r} not finite"
            if not lower <= value <= upper:
                return f"{axis} {value!r} m outside the workspace [{lower}, {upper}]"
        return None


@dataclass
class GoalsConfig:
    """Object goals: the list is taken in order (cyclically); ``DPG1`` commands set or advance the goal."""

    sequence: list[GoalConfig] = field(default_factory=list)
    advance_after_s: float | None = None  # after success, wait this long and take the next goal; null = wait for a command
    command_port: int | None = 9873  # DPG1 goal commands are received here; null = no goal commands
    bind_address: str = LOOPBACK
    allowed_senders: list[str] = field(default_factory=lambda: [LOOPBACK])  # addresses DPG1 is taken from
    workspace: WorkspaceConfig = field(default_factory=WorkspaceConfig)  # goals outside it are refused

    def validate(self, prefix: str = "goals") -> None:
        self.workspace.validate(f"{prefix}.workspace")
        for i, goal in enumerate(self.sequence):
            _require(math.isfinite(goal.yaw_deg), f"{prefix}.sequence[{i}].yaw_deg must be finite")
            outside = self.workspace.outside(goal.x, goal.y)
            _require(outside is None, f"{prefix}.sequence[{i}]: {outside} ({prefix}.workspace)")
        if self.advance_after_s is not None:
            _require(math.isfinite(self.advance_after_s) and 0.0 <= self.advance_after_s <= MAX_ADVANCE_AFTER_S,
                     f"{prefix}.advance_after_s must be null or a number in [0, {MAX_ADVANCE_AFTER_S}],"
                     f" got {self.advance_after_s!r}")
            _require(bool(self.sequence), f"{prefix}.advance_after_s needs goals in {prefix}.sequence")
        _check_bind_address(f"{prefix}.bind_address", self.bind_address)
        _check_senders(f"{prefix}.allowed_senders", self.allowed_senders)
        if self.command_port is not None:
            _check_port(f"{prefix}.command_port", self.command_port)
        _require(bool(self.sequence) or self.command_port is not None,
                 f"{prefix}: give a {prefix}.sequence or a {prefix}.command_port, otherwise the robot never gets a goal")


@dataclass
class LogConfig:
    directory: str = "runs/runtime"  # one tick log per run, named by its start time

    def validate(self, prefix: str = "log") -> None:
        _require(bool(self.directory), f"{prefix}.directory must not be empty")


@dataclass
class RuntimeConfig:
    """The whole deployment runtime (see the module docstring)."""

    mocap: MocapConfig = field(default_factory=MocapConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    push_policy: PushPolicyConfig = field(default_factory=PushPolicyConfig)
    locomotion: LocomotionConfig = field(default_factory=LocomotionConfig)
    rates: RatesConfig = field(default_factory=RatesConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    goals: GoalsConfig = field(default_factory=GoalsConfig)
    log: LogConfig = field(default_factory=LogConfig)

    @property
    def control_period_s(self) -> float:
        return 1.0 / self.rates.control_hz

    def validate(self) -> RuntimeConfig:
        for f in dataclasses.fields(self):
            if f.name != "safety":
                getattr(self, f.name).validate(f.name)
        onnx_legs = self.locomotion.mode == "onnx"
        self.safety.validate("safety", legs_required=onnx_legs)
        if onnx_legs:
            _require(self.robot.leg_joint_names == self.locomotion.onnx.joint_names,
                     f"robot.leg_joint_names {self.robot.leg_joint_names} must equal locomotion.onnx.joint_names"
                     f" {self.locomotion.onnx.joint_names} (same joints, same order)")
        return self

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


# ---------------------------------------------------------------------------------------------- loading
def _convert(value: object, kind: object, name: str) -> object:
    """``value`` from YAML as type ``kind`` (a dataclass, list, dict, optional or scalar type)."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _convert(value, inner, name)
    if dataclasses.is_dataclass(kind):
        if not isinstance(value, dict):
            raise RuntimeConfigError(f"{name} must be a mapping with keys {[f.name for f in dataclasses.fields(kind)]}")
        return _build(kind, value, name)
    if origin is list:
        if not isinstance(value, list):
            raise RuntimeConfigError(f"{name} must be a list, got {value!r}")
        return [_convert(v, args[0], f"{name}[{i}]") for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, dict):
            raise RuntimeConfigError(f"{name} must be a mapping, got {value!r}")
        return {_convert(k, args[0], f"{name} key"): _convert(v, args[1], f"{name}.{k}") for k, v in value.items()}
    if kind is float and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if kind is float and isinstance(value, str):  # PyYAML reads 1e-3 (no dot) as a string
        with contextlib.suppress(ValueError):
            return float(value)
    if isinstance(value, kind) and not (kind is int and isinstance(value, bool)):
        return value
    raise RuntimeConfigError(f"{name} must be of type {kind.__name__}, got {value!r}")


def _build(cls: type, data: dict, prefix: str) -> object:
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        where = f"{prefix}." if prefix else ""
        raise RuntimeConfigError(f"unknown field {where}{unknown[0]} (allowed: {names})")
    return cls(**{key: _convert(value, hints[key], f"{prefix}.{key}" if prefix else key) for key, value in data.items()})


def config_from_dict(data: dict) -> RuntimeConfig:
    """A validated :class:`RuntimeConfig` from plain data (what ``yaml.safe_load`` returns)."""
    if not isinstance(data, dict):
        raise RuntimeConfigError(f"a runtime config must be a mapping of sections {[f.name for f in dataclasses.fields(RuntimeConfig)]}")
    return _build(RuntimeConfig, data, "").validate()


def _merge(data: dict, updates: dict) -> dict:
    merged = dict(data)
    for key, value in updates.items():
        merged[key] = _merge(merged[key], value) if isinstance(value, dict) and isinstance(merged.get(key), dict) else value
    return merged


def load_config(path: str | Path, updates: dict | None = None) -> RuntimeConfig:
    """Reads a YAML config, applies ``updates`` (nested like the file) on top, resolves relative input
    paths against the file's folder, and validates it."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as error:
        raise RuntimeConfigError(f"cannot read runtime config {path}: {error}") from error
    cfg = config_from_dict(_merge(data, updates or {}) if isinstance(data, dict) else data)
    base = path.resolve().parent
    resolve = lambda p: str(base / p) if p and not Path(p).is_absolute() else p  # noqa: E731
    cfg.push_policy.path = resolve(cfg.push_policy.path)
    cfg.locomotion.onnx.path = resolve(cfg.locomotion.onnx.path)
    cfg.mocap.replay_log = resolve(cfg.mocap.replay_log)
    return cfg
