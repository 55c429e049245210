"""Binary UDP datagrams of the runtime: mocap stream, robot state, robot command, goal command.

One datagram is one message. All integers and floats are little-endian; floats are IEEE float64.
Every message starts with a 4-byte magic naming its kind and version and a ``uint32 seq`` (sender's
counter, wraps; a receiver drops a datagram whose seq is not newer than its sender's last, trust.py).
Decoders check the magic, the declared counts and the exact length, and raise :class:`PacketError`
for anything else; they never check meaning (finite values, expected joint counts): the receivers
do, and count what they drop.

``DPM1`` mocap frame (mocap system or simulator -> runtime)::

    4s  magic "DPM1"
    u32 seq
    f64 stamp_s          sender's clock [s] (informational; staleness uses the receive time)
    u16 body_count
    body_count times:
      u8  name_len
      name_len bytes     body name, UTF-8
      7 f64              position (3) in the source's units and axes, quaternion (4) in its order

    Positions, axes and quaternion order are those of the source, converted by the receiver
    (``dynpush.runtime.frames``).

``DPS1`` robot state (robot -> runtime), frames of the robot's state estimator::

    4s  magic "DPS1"
    u32 seq
    f64 stamp_s          robot clock [s]
    u8  n_arm            controlled arm joints (5)
    u8  n_leg            leg joints (12, or 0 if the robot does not report them)
    f64 x (13 + 2 n_arm + 2 n_leg):
      base_quat_xyzw (4)            IMU orientation of the base in a gravity-aligned frame (yaw may drift)
      base_linear_velocity_b (3)    base frame [m/s]
      base_angular_velocity_b (3)   base frame [rad/s]
      ee_position_b (3)             end-effector point in the base frame [m] (arm forward kinematics)
      arm_q (n_arm), arm_qd (n_arm) [rad], [rad/s], in the order of the config's robot.arm_joint_names
      leg_q (n_leg), leg_qd (n_leg) [rad], [rad/s], in the order of robot.leg_joint_names

``DPC1`` robot command (runtime -> robot)::

    4s  magic "DPC1"
    u32 seq
    f64 stamp_s          runtime clock [s]
    u8  mode             0 = stop (the robot's own damping / safe stop), 1 = track the targets below
    u8  state            runtime state code (dynpush.runtime.safety.State), for display and tests
    u8  n_arm
    u8  n_leg            12 when the runtime runs a locomotion ONNX, else 0
    f64 x (6 + n_arm + n_leg):
      base_command (6)   vx, vy [m/s], yaw rate [rad/s] (heading frame), roll, pitch [rad], height [m]
      arm_targets (n_arm) [rad]
      leg_targets (n_leg) [rad]

``DPG1`` goal command (operator or simulator -> runtime)::

    4s  magic "DPG1"
    u32 seq
    u8  kind             0 = go to (x, y, yaw); 1 = next goal of the config's list
    f64 x, y [m], yaw [rad]   object goal in the runtime's world frame (Z-up); ignored for kind 1
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

MOCAP_MAGIC = b"DPM1"
STATE_MAGIC = b"DPS1"
COMMAND_MAGIC = b"DPC1"
GOAL_MAGIC = b"DPG1"
MODE_STOP = 0
MODE_TARGETS = 1
GOAL_SET = 0
GOAL_NEXT = 1
MAX_DATAGRAM = 65507

_MOCAP_HEADER = struct.Struct("<4sIdH")
_NAME_LENGTH = struct.Struct("<B")
_BODY_VALUES = struct.Struct("<7d")
_STATE_HEADER = struct.Struct("<4sIdBB")
_COMMAND_HEADER = struct.Struct("<4sIdBBBB")
_GOAL = struct.Struct("<4sIB3d")
_F64 = np.dtype("<f8")
STATE_FIXED_VALUES = 13  # quaternion 4 + two velocities 3 + end-effector 3


class PacketError(ValueError):
    """A datagram that is not a well-formed message of the expected kind."""


@dataclass
class MocapBody:
    """One rigid body of a mocap frame, in the source's conventions."""

    name: str
    position: np.ndarray  # (3,)
    quat: np.ndarray  # (4,) in the source's order


@dataclass
class MocapFrame:
    seq: int
    stamp_s: float
    bodies: list[MocapBody]


@dataclass
class Proprioception:
    """Robot state of one ``DPS1`` message (frames and units in the module docstring)."""

    seq: int
    stamp_s: float
    base_quat_xyzw: np.ndarray
    base_linear_velocity_b: np.ndarray
    base_angular_velocity_b: np.ndarray
    ee_position_b: np.ndarray
    arm_q: np.ndarray
    arm_qd: np.ndarray
    leg_q: np.ndarray
    leg_qd: np.ndarray

    def values(self) -> np.ndarray:
        """All float values in message order."""
        return np.concatenate([self.base_quat_xyzw, self.base_linear_velocity_b, self.base_angular_velocity_b,
                               self.ee_position_b, self.arm_q, self.arm_qd, self.leg_q, self.leg_qd])


@dataclass
class RobotCommand:
    """One ``DPC1`` message: what the robot should track this control period."""

    seq: int
    stamp_s: float
    mode: int
    state: int
    base_command: np.ndarray  # (6,)
    arm_targets: np.ndarray  # (n_arm,)
    leg_targets: np.ndarray  # (n_leg,), empty without a locomotion ONNX


@dataclass
class GoalCommand:
    seq: int
    kind: int  # GOAL_SET or GOAL_NEXT
    x: float
    y: float
    yaw: float


def _check_magic(data: bytes, header: struct.Struct, magic: bytes) -> tuple:
    if len(data) < header.size:
        raise PacketError(f"{magic.decode()} datagram of {len(data)} bytes is shorter than its header ({header.size})")
    fields = header.unpack_from(data)
    if fields[0] != magic:
        raise PacketError(f"expected magic {magic!r}, got {fields[0]!r}")
    return fields


def _floats(data: bytes, offset: int, count: int) -> np.ndarray:
    return np.frombuffer(data, dtype=_F64, count=count, offset=offset).astype(np.float64)


# ---------------------------------------------------------------------------------------------- mocap
def encode_mocap(frame: MocapFrame) -> bytes:
    parts = [_MOCAP_HEADER.pack(MOCAP_MAGIC, frame.seq & 0xFFFFFFFF, frame.stamp_s, len(frame.bodies))]
    for body in frame.bodies:
        name = body.name.encode("utf-8")
        if len(name) > 255:
            raise PacketError(f"body name {body.name!r} is longer than 255 bytes")
        parts += [_NAME_LENGTH.pack(len(name)), name, _BODY_VALUES.pack(*body.position, *body.quat)]
    return b"".join(parts)


def decode_mocap(data: bytes) -> MocapFrame:
    _, seq, stamp, count = _check_magic(data, _MOCAP_HEADER, MOCAP_MAGIC)
    offset = _MOCAP_HEADER.size
    bodies = []
    for _ in range(count):
        if offset + 1 > len(data):
            raise PacketError("DPM1 datagram ends inside a body")
        n = data[offset]
        offset += 1
        end = offset + n + _BODY_VALUES.size
        if end > len(data):
            raise PacketError("DPM1 datagram ends inside a body")
        try:
            name = bytes(data[offset:offset + n]).decode("utf-8")
        except UnicodeDecodeError as error:
            raise PacketError(f"DPM1 body name is not UTF-8: {error}") from error
        values = _floats(data, offset + n, 7)
        bodies.append(MocapBody(name=name, position=values[:3], quat=values[3:]))
        offset = end
    if offset != len(data):
        raise PacketError(f"DPM1 datagram has {len(data) - offset} trailing bytes")
    return MocapFrame(seq=seq, stamp_s=stamp, bodies=bodies)


# ---------------------------------------------------------------------------------------------- state
def encode_state(state: Proprioception) -> bytes:
    n_arm, n_leg = len(state.arm_q), len(state.leg_q)
    if len(state.arm_qd) != n_arm or len(state.leg_qd) != n_leg:
        raise PacketError("joint positions and velocities must have the same counts")
    header = _STATE_HEADER.pack(STATE_MAGIC, state.seq & 0xFFFFFFFF, state.stamp_s, n_arm, n_leg)
    return header + state.values().astype(_F64).tobytes()


def decode_state(data: bytes) -> Proprioception:
    _, seq, stamp, n_arm, n_leg = _check_magic(data, _STATE_HEADER, STATE_MAGIC)
    count = STATE_FIXED_VALUES + 2 * n_arm + 2 * n_leg
    if len(data) != _STATE_HEADER.size + 8 * count:
        raise PacketError(f"DPS1 with n_arm={n_arm}, n_leg={n_leg} must have {_STATE_HEADER.size + 8 * count} bytes,"
                          f" got {len(data)}")
    v = _floats(data, _STATE_HEADER.size, count)
    cuts = np.cumsum([4, 3, 3, 3, n_arm, n_arm, n_leg])
    quat, lin, ang, ee, arm_q, arm_qd, leg_q, leg_qd = np.split(v, cuts)
    return Proprioception(seq=seq, stamp_s=stamp, base_quat_xyzw=quat, base_linear_velocity_b=lin,
                          base_angular_velocity_b=ang, ee_position_b=ee, arm_q=arm_q, arm_qd=arm_qd,
                          leg_q=leg_q, leg_qd=leg_qd)


# ---------------------------------------------------------------------------------------------- command
def encode_command(command: RobotCommand) -> bytes:
    header = _COMMAND_HEADER.pack(COMMAND_MAGIC, command.seq & 0xFFFFFFFF, command.stamp_s, command.mode,
                                  command.state, len(command.arm_targets), len(command.leg_targets))
    values = np.concatenate([command.base_command, command.arm_targets, command.leg_targets]).astype(_F64)
    return header + values.tobytes()


def decode_command(data: bytes) -> RobotCommand:
    _, seq, stamp, mode, state, n_arm, n_leg = _check_magic(data, _COMMAND_HEADER, COMMAND_MAGIC)
    count = 6 + n_arm + n_leg
    if len(data) != _COMMAND_HEADER.size + 8 * count:
        raise PacketError(f"DPC1 with n_arm={n_arm}, n_leg={n_leg} must have {_COMMAND_HEADER.size + 8 * count} bytes,"
                          f" got {len(data)}")
    if mode not in (MODE_STOP, MODE_TARGETS):
        raise PacketError(f"DPC1 mode must be {MODE_STOP} or {MODE_TARGETS}, got {mode}")
    v = _floats(data, _COMMAND_HEADER.size, count)
    return RobotCommand(seq=seq, stamp_s=stamp, mode=mode, state=state, base_command=v[:6],
                        arm_targets=v[6:6 + n_arm], leg_targets=v[6 + n_arm:])


# ---------------------------------------------------------------------------------------------- goal
def encode_goal(goal: GoalCommand) -> bytes:
    return _GOAL.pack(GOAL_MAGIC, goal.seq & 0xFFFFFFFF, goal.kind, goal.x, goal.y, goal.yaw)


def decode_goal(data: bytes) -> GoalCommand:
    _, seq, kind, x, y, yaw = _check_magic(data, _GOAL, GOAL_MAGIC)
    if len(data) != _GOAL.size:
        raise PacketError(f"DPG1 must have {_GOAL.size} bytes, got {len(data)}")
    if kind not in (GOAL_SET, GOAL_NEXT):
        raise PacketError(f"DPG1 kind must be {GOAL_SET} (set) or {GOAL_NEXT} (next), got {kind}")
    return GoalCommand(seq=seq, kind=kind, x=x, y=y, yaw=yaw)
