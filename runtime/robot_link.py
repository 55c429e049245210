"""The robot link: proprioception in, joint targets and base command out.

:class:`RobotLink` is the interface the runtime drives; :class:`UdpRobotLink` implements it with the
``DPS1`` (state) and ``DPC1`` (command) datagrams of packets.py, for a robot-side bridge or the
simulator of sim-to-sim on loopback. A robot whose bridge speaks something else gets its own class
with the same five members.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from .config import RobotConfig
from .locomotion_layout import NUM_LEG_JOINTS
from .observation import NUM_ARM_JOINTS
from .packets import PacketError, Proprioception, RobotCommand, decode_state, encode_command
from .trust import Drops, SenderGuard
from .udp import UdpEndpoint


@dataclass
class LinkStats(Drops):
    states: int = 0  # state messages admitted
    commands: int = 0  # commands sent


@dataclass
class ReceivedState:
    state: Proprioception
    receive_time: float  # runtime clock [s]


class RobotLink(Protocol):
    stats: LinkStats

    def poll(self, now: float) -> None:
        """Takes in the robot state that arrived since the last call (``now``: runtime clock [s])."""

    @property
    def latest(self) -> ReceivedState | None:
        """The newest robot state, or None before the first."""

    def send(self, command: RobotCommand) -> None:
        """Sends one command (no-op while the robot's address is unknown)."""

    def wait_for_state(self, timeout_s: float) -> bool:
        """Blocks up to ``timeout_s`` until new robot state is waiting (lock-step clocks)."""

    def close(self) -> None: ...


class UdpRobotLink:
    """``DPS1`` in on ``robot.bind_address:robot.port`` from ``robot.allowed_senders``; ``DPC1`` out to
    ``robot.robot_address:robot_port``, or, with an empty ``robot_address``, back to the first admitted sender
    of a state, which is then the only one admitted (simulators on loopback; trust.py).

    ``leg_joints`` is the number of leg joints the state must carry (12 with a locomotion ONNX; 0, the
    robot's own locomotion, accepts 0 or 12, DPS1's two forms). Datagrams with other counts are dropped as
    malformed.
    """

    def __init__(self, cfg: RobotConfig, leg_joints: int):
        self.endpoint = UdpEndpoint(cfg.bind_address, cfg.port)
        self._address = (cfg.robot_address, cfg.robot_port) if cfg.robot_address else None
        self.guard = SenderGuard("robot", cfg.allowed_senders, latch=self._address is None)
        self._leg_counts = (leg_joints,) if leg_joints else (0, NUM_LEG_JOINTS)
        self._latest: ReceivedState | None = None
        self.stats = LinkStats()

    @property
    def latest(self) -> ReceivedState | None:
        return self._latest

    def _decode(self, data: bytes) -> Proprioception:
        """A ``DPS1`` message with the joint counts this runtime takes; PacketError otherwise."""
        state = decode_state(data)
        if len(state.arm_q) != NUM_ARM_JOINTS or len(state.leg_q) not in self._leg_counts:
            raise PacketError(f"DPS1 with {len(state.arm_q)} arm and {len(state.leg_q)} leg joints, this runtime takes"
                              f" {NUM_ARM_JOINTS} arm and {' or '.join(map(str, self._leg_counts))} leg joints")
        return state

    def poll(self, now: float) -> None:
        for datagram, state in self.guard.admit(self.endpoint.drain(), self._decode, self.stats):
            self.stats.states += 1
            self._latest = ReceivedState(state, now - datagram.waited_s)

    def send(self, command: RobotCommand) -> None:
        address = self._address or self.guard.peer
        if address is not None:
            self.endpoint.send(encode_command(command), address)
            self.stats.commands += 1

    def wait_for_state(self, timeout_s: float) -> bool:
        return self.endpoint.wait_readable(timeout_s)

    def close(self) -> None:
        self.endpoint.close()


def open_robot_link(cfg: RobotConfig, leg_joints: int) -> RobotLink:
    """The link named by ``robot.link`` (a new link: a class with :class:`RobotLink`'s members, a name here
    and in ``config.ROBOT_LINKS``)."""
    assert cfg.link == "udp"
    return UdpRobotLink(cfg, leg_joints)
