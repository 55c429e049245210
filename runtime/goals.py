"""The object goal: from the config's sequence, advanced after success, or set by ``DPG1`` commands.

A goal is (x, y) [m] and yaw [rad] of the object centroid frame in the runtime's world (Z-up). The
task is planar: the goal's height is taken equal to the object's measured height each tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .config import GoalsConfig
from .packets import GOAL_NEXT, PacketError, decode_goal
from .udp import UdpEndpoint


@dataclass
class Goal:
    x: float  # [m], world frame
    y: float
    yaw: float  # [rad] about world z


class GoalManager:
    """The current goal. ``poll`` takes commands and the automatic advance; it says when the goal changed."""

    def __init__(self, cfg: GoalsConfig):
        self._sequence = [Goal(g.x, g.y, math.radians(g.yaw_deg)) for g in cfg.sequence]
        self._advance_after_s = cfg.advance_after_s
        self._index = -1
        self.goal: Goal | None = None
        self.endpoint = UdpEndpoint(cfg.bind_address, cfg.command_port) if cfg.command_port is not None else None
        self.commands = 0
        self.malformed = 0
        self._changed = self._advance()

    def _advance(self) -> bool:
        if not self._sequence:
            return False
        self._index = (self._index + 1) % len(self._sequence)
        self.goal = self._sequence[self._index]
        return True

    def poll(self, now: float, reached_since: float | None) -> bool:
        """True when the goal changed since the last call (``now``, ``reached_since``: runtime clock [s])."""
        changed, self._changed = self._changed, False
        if self.endpoint is not None:
            for datagram in self.endpoint.drain():
                try:
                    command = decode_goal(datagram.data)
                except PacketError:
                    self.malformed += 1
                    continue
                if not all(math.isfinite(v) for v in (command.x, command.y, command.yaw)):
                    self.malformed += 1
                    continue
                self.commands += 1
                if command.kind == GOAL_NEXT:
                    changed |= self._advance()
                else:
                    self.goal = Goal(command.x, command.y, command.yaw)
                    changed = True
        if (not changed and self._advance_after_s is not None and reached_since is not None
                and now - reached_since >= self._advance_after_s - 1e-9):  # ticks sit on a float grid
            changed = self._advance()
        return changed

    def close(self) -> None:
        if self.endpoint is not None:
            self.endpoint.close()
