"""The safety state machine and the command limits.

States (:class:`State`) and what the robot is told in each:

- ``STARTUP``: no robot state yet. Command mode stop (the robot's own safe behaviour).
- ``RAMP``: the arm moves linearly from where it is to the contract's default pose over
  ``safety.arm_ramp_s``; base command zero (the default: no motion, nominal height).
- ``PUSH``: the push policy commands the base and the arm.
- ``HOLD``: no goal, or the goal is reached (contract thresholds): base command zero, arm holds its
  last target. A new goal resumes ``PUSH``.
- ``MOCAP_LOST``: base or object pose older than ``mocap.timeout_s``: base command zero, arm holds.
  Fresh poses resume the previous activity.
- ``STOPPED`` (latched until restart): robot state older than ``robot.timeout_s``, base tilt (IMU)
  beyond ``safety.max_tilt_deg``, a non-finite number anywhere in the tick, or an outgoing command
  that is not finite or lies beyond its limits after clamping (:meth:`CommandLimits.clamp`), or the
  runtime's own overruns: more deadlines skipped than ``rates.overrun`` allows (``timing.OverrunGuard``,
  tripped by the controller): command mode stop (damping on hardware).

Transitions: STARTUP -> RAMP on the first robot state; RAMP -> PUSH/HOLD/MOCAP_LOST when the ramp
ends; PUSH <-> HOLD <-> MOCAP_LOST as above; any -> STOPPED. Joint targets and the base command are
clamped to :class:`CommandLimits` in every state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from .config import RuntimeConfig
from .contract import PolicyContract


class State(IntEnum):
    STARTUP = 0
    RAMP = 1
    PUSH = 2
    HOLD = 3
    MOCAP_LOST = 4
    STOPPED = 5


@dataclass
class SafetyInputs:
    """What one tick measured. Ages are seconds since receipt (``inf`` before the first)."""

    now: float
    robot_age: float
    mocap_age: float  # the older of the base and object poses
    tilt: float  # base tilt from the IMU [rad] (NaN if unknown)
    finite: bool  # every number of this tick (robot state, observation, policy output) is finite
    ramp_done: bool
    has_goal: bool
    at_goal: bool  # object within the success thresholds of the goal (fresh mocap only)
    goal_changed: bool


class SafetyMachine:
    """The state machine of the module docstring; :meth:`update` once per tick."""

    def __init__(self, robot_timeout_s: float, mocap_timeout_s: float, max_tilt_rad: float):
        self.robot_timeout_s = robot_timeout_s
        self.mocap_timeout_s = mocap_timeout_s
        self.max_tilt_rad = max_tilt_rad
        self.state = State.STARTUP
        self.reason = "waiting for robot state"
        self.reached_since: float | None = None  # when the current goal was reached, or None

    def trip(self, reason: str) -> State:
        """Latches ``STOPPED`` with ``reason``."""
        if self.state != State.STOPPED:
            self.state, self.reason = State.STOPPED, reason
        return self.state

    def update(self, x: SafetyInputs) -> State:
        if self.state == State.STOPPED:
            return self.state
        if math.isfinite(x.robot_age):
            if x.robot_age > self.robot_timeout_s:
                return self.trip(f"robot state stale ({x.robot_age:.3f} s > {self.robot_timeout_s} s)")
            if not x.finite:
                return self.trip("non-finite value in robot state, observation or policy output")
            if not x.tilt <= self.max_tilt_rad:
                return self.trip(f"base tilt {math.degrees(x.tilt):.1f} deg beyond {math.degrees(self.max_tilt_rad):.1f} deg")
        if x.goal_changed:
            self.reached_since = None
        if self.state == State.STARTUP:
            if math.isfinite(x.robot_age):
                self._set(State.RAMP, "arm ramp to the default pose")
        elif self.state == State.RAMP:
            if x.ramp_done:
                self._operate(x)
        else:
            if self.state == State.PUSH and x.at_goal and x.mocap_age <= self.mocap_timeout_s:
                self.reached_since = x.now
            self._operate(x)
        return self.state

    def _operate(self, x: SafetyInputs) -> None:
        if not x.mocap_age <= self.mocap_timeout_s:
            self._set(State.MOCAP_LOST, f"mocap stale ({x.mocap_age:.3f} s > {self.mocap_timeout_s} s)")
        elif x.has_goal and self.reached_since is None:
            self._set(State.PUSH, "pushing")
        else:
            self._set(State.HOLD, "goal reached" if x.has_goal else "no goal")

    def _set(self, state: State, reason: str) -> None:
        self.state, self.reason = state, reason


@dataclass
class CommandLimits:
    """Bounds of everything sent to the robot: base command (6), arm targets (5) [rad], leg targets (12 or 0)."""

    base_lower: np.ndarray
    base_upper: np.ndarray
    arm_lower: np.ndarray
    arm_upper: np.ndarray
    leg_lower: np.ndarray
    leg_upper: np.ndarray

    @staticmethod
    def resolve(cfg: RuntimeConfig, contract: PolicyContract) -> CommandLimits:
        """The config's safety limits, or the contract's where the config leaves them empty."""
        s = cfg.safety
        pick = lambda own, fallback: np.asarray(own or fallback, dtype=np.float64)  # noqa: E731
        return CommandLimits(
            base_lower=pick(s.base_command_lower, contract.base_command_lower),
            base_upper=pick(s.base_command_upper, contract.base_command_upper),
            arm_lower=pick(s.arm_joint_lower, contract.arm_joint_lower),
            arm_upper=pick(s.arm_joint_upper, contract.arm_joint_upper),
            leg_lower=pick(s.leg_joint_lower, []),
            leg_upper=pick(s.leg_joint_upper, []),
        )

    def clamp(self, base_command: np.ndarray, arm_targets: np.ndarray, leg_targets: np.ndarray) -> str | None:
        """Clamps the three arrays in place; returns why the command must not be sent, or None: a non-finite value
        (judged before clamping, which would turn an infinity into a limit) or a value beyond its limit after."""
        blocks = (("base command", base_command, self.base_lower, self.base_upper),
                  ("arm targets", arm_targets, self.arm_lower, self.arm_upper),
                  ("leg targets", leg_targets, self.leg_lower, self.leg_upper))
        for name, values, _, _ in blocks:
            if not np.isfinite(values).all():
                return f"{name} {values.tolist()} not finite"
        for name, values, lower, upper in blocks:
            if values.size:
                np.clip(values, lower, upper, out=values)
                if not (np.all(lower <= values) and np.all(values <= upper)):
                    return f"{name} {values.tolist()} beyond the limits {lower.tolist()} / {upper.tolist()}"
        return None
