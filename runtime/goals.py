"""The object goal: from the config's sequence, advanced after success, or set by ``DPG1`` commands.

A goal is (x, y) [m] and yaw [rad] of the object centroid frame in the runtime's world (Z-up). The
task is planar: the goal's height is the object's measured height when the goal arrived (the controller). Goal
commands come only from ``goals.allowed_senders`` (trust.py); a goal outside ``goals.workspace`` or with
a non-finite yaw is refused, counted and logged with the reason, and the current goal stays.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from .config import GoalsConfig
from .packets import GOAL_NEXT, GoalCommand, decode_goal
from .trust import Drops, SenderGuard
from .udp import UdpEndpoint

_LOG = logging.getLogger(__name__)


@dataclass
class Goal:
    x: float  # [m], world frame
    y: float
    yaw: float  # [rad] about world z


@dataclass
class GoalStats(Drops):
    accepted: int = 0  # goal commands taken
    refused: int = 0  # well-formed goal commands outside goals.workspace or with a non-finite yaw


class GoalManager:
    """The current goal. ``poll`` takes commands and the automatic advance; it says when the goal changed."""

    def __init__(self, cfg: GoalsConfig):
        self._sequence = [Goal(g.x, g.y, math.radians(g.yaw_deg)) for g in cfg.sequence]
        self._advance_after_s = cfg.advance_after_s
        self._workspace = cfg.workspace
        self._index = -1
        self.goal: Goal | None = None
        self.endpoint = UdpEndpoint(cfg.bind_address, cfg.command_port) if cfg.command_port is not None else None
        self.guard = SenderGuard("goals", cfg.allowed_senders)
        self.stats = GoalStats()
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
            for _, command in self.guard.admit(self.endpoint.drain(), decode_goal, self.stats):
                changed |= self._take(command)
        if (not changed and self._advance_after_s is not None and reached_since is not None
                and now - reached_since >= self._advance_after_s - 1e-9):  # ticks sit on a float grid
            changed = self._advance()
        return changed

    def _take(self, command: GoalCommand) -> bool:
        """Applies one admitted goal command; True when the goal changed."""
        if command.kind == GOAL_NEXT:
            self.stats.accepted += 1
            return self._advance()
        reason = self._workspace.outside(command.x, command.y) or (
            None if math.isfinite(command.yaw) else f"yaw {command.yaw!r} rad not finite")
        if reason is not None:
            self.stats.refused += 1
            _LOG.warning("goals: refused goal command %d (%r, %r, yaw %r): %s; the goal stays", command.seq, command.x,
                         command.y, command.yaw, reason)
            return False
        self.stats.accepted += 1
        self.goal = Goal(command.x, command.y, math.remainder(command.yaw, math.tau))
        return True

    def close(self) -> None:
        if self.endpoint is not None:
            self.endpoint.close()
