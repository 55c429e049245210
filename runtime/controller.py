"""One control tick: measurements -> safety state -> push policy -> locomotion -> clamped command.

The controller holds no sockets and no clock: the loop (app.py) hands it the newest mocap poses,
robot state and goal with the tick's timing, sends the returned command and logs :attr:`record`.

Measurements enter the push policy's observation (observation.py) as follows: base and object
poses from mocap; base twist from the robot's state estimator (base frame, rotated into the world
with the mocap base orientation, which the observation builder rotates back); end-effector position
from the robot's arm forward kinematics (base frame, placed in the world with the mocap base pose);
goal height equal to the object's measured height when the goal arrived (planar task; training's goal is at
the object's resting centroid height). Actions become commands as in
training, by the contract's action mapping (actions.py): ``u_base = default + scale * a[0:6]``,
``q_arm = default + arm_scale * a[6:11]``, with ``a`` clipped to ``+-action_clip``. Every command is
clamped to its limits and checked before it leaves: one with a non-finite value (or beyond a limit)
latches STOPPED and is replaced by a stop command. So do the runtime's own overruns: more deadlines skipped
within a window than ``rates.overrun`` allows (:class:`~.timing.OverrunGuard`, fed every tick's timing) latches
STOPPED with the figures as its reason, also logged as one error line.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .config import RuntimeConfig
from .contract import PolicyContract
from .frames import rotation_angle, tilt_angle, yaw_quat
from .goals import Goal
from .locomotion import OnnxLocomotion
from .locomotion_layout import NUM_LEG_JOINTS
from .mocap import TrackedPose
from .observation import NUM_ACTIONS, NUM_ARM_JOINTS, POLICY_OBSERVATION_SIZE, policy_observation
from .packets import MODE_STOP, MODE_TARGETS, STATE_FIXED_VALUES, RobotCommand
from .policy import OnnxModel
from .robot_link import ReceivedState
from .safety import CommandLimits, SafetyInputs, SafetyMachine, State
from .tick_log import RecordLayout
from .timing import OverrunGuard, TickTiming

_LOG = logging.getLogger(__name__)
ACTIVE_STATES = (State.RAMP, State.PUSH, State.HOLD, State.MOCAP_LOST)  # the robot tracks targets


def record_columns(leg_joints: int, locomotion_inputs: int) -> list[tuple[str, int]]:
    """Tick log columns; leg target and locomotion columns only with a locomotion ONNX. ``robot_state`` holds the
    largest state the link accepts (with legs), NaN where the robot reports no leg joints."""
    columns = [
        ("time_s", 1), ("tick", 1), ("state", 1), ("mode", 1), ("lateness_s", 1), ("compute_s", 1), ("skipped", 1),
        ("base_age_s", 1), ("object_age_s", 1), ("robot_age_s", 1),
        ("base_position", 3), ("base_quat_xyzw", 4), ("object_position", 3), ("object_quat_xyzw", 4),
        ("goal", 3),  # x [m], y [m], yaw [rad]
        ("robot_state", STATE_FIXED_VALUES + 2 * NUM_ARM_JOINTS + 2 * NUM_LEG_JOINTS),  # DPS1 value order
        ("obs", POLICY_OBSERVATION_SIZE), ("actions", NUM_ACTIONS), ("base_command", 6), ("arm_targets", NUM_ARM_JOINTS),
    ]
    if locomotion_inputs:
        columns += [("locomotion_obs", locomotion_inputs), ("locomotion_actions", leg_joints), ("leg_targets", leg_joints)]
    return columns


class Controller:
    def __init__(self, cfg: RuntimeConfig, contract: PolicyContract, push: OnnxModel,
                 locomotion: OnnxLocomotion | None):
        self.contract = contract
        self.push = push
        self.locomotion = locomotion
        self.limits = CommandLimits.resolve(cfg, contract)
        self.safety = SafetyMachine(cfg.robot.timeout_s, cfg.mocap.timeout_s, math.radians(cfg.safety.max_tilt_deg))
        self.overruns = OverrunGuard(cfg.rates.overrun.max_skipped, cfg.rates.overrun.window_periods)
        self._mocap_timeout_s = cfg.mocap.timeout_s
        self._ramp_s = cfg.safety.arm_ramp_s
        self._mapping = contract.action_mapping()
        self._arm_default = self._mapping.arm.default
        self._last_actions = np.zeros(NUM_ACTIONS)
        self._arm_hold = self._arm_default.copy()
        self._leg_joints = NUM_LEG_JOINTS if locomotion else 0
        self._leg_hold = locomotion.legs.default.copy() if locomotion else np.zeros(0)
        self._ramp_from = self._arm_default.copy()
        self._ramp_start = 0.0
        self._ramp_done = False
        self._seq = 0
        # The goal's height [m]: the object's when the goal arrived, its centroid's height at rest, as the training's
        # goal is (half the object's height), so that a tilting object moves off its goal in z as it did in training.
        self._goal_height: float | None = None
        self.mocap_age = math.inf  # of the latest tick [s]
        locomotion_inputs = locomotion.model.input.shape[1] if locomotion else 0
        self.layout = RecordLayout(record_columns(self._leg_joints, locomotion_inputs))
        self.record = self.layout.new_record()

    # ------------------------------------------------------------------ measurements
    def observe(self, base: TrackedPose, obj: TrackedPose, robot: ReceivedState, goal: Goal) -> np.ndarray:
        """The 54-d observation, written into the push policy's input buffer."""
        s = robot.state
        R_b = base.pose.rotation
        if self._goal_height is None:
            self._goal_height = float(obj.pose.position[2])
        self.push.input[0] = policy_observation(
            base_position=base.pose.position, base_quat=base.pose.quat_xyzw,
            base_linear_velocity_w=R_b @ s.base_linear_velocity_b, base_angular_velocity_w=R_b @ s.base_angular_velocity_b,
            object_position=obj.pose.position, object_quat=obj.pose.quat_xyzw,
            ee_position=base.pose.position + R_b @ s.ee_position_b,
            arm_joint_position=s.arm_q, arm_joint_velocity=s.arm_qd, arm_default=self._arm_default,
            goal_position=(goal.x, goal.y, self._goal_height), goal_quat=yaw_quat(goal.yaw),
            last_actions=self._last_actions,
        )
        return self.push.input[0]

    def _at_goal(self, obj: TrackedPose, goal: Goal) -> bool:
        """Training's success test (``kernels/push/rewards.py``): the object's centroid within the success distance of
        the goal point (at the goal's height, as the observation places it) and its rotation within the success angle
        of the goal's."""
        p = obj.pose.position
        goal_height = p[2] if self._goal_height is None else self._goal_height
        return (math.dist(p, (goal.x, goal.y, goal_height)) <= self.contract.success_distance_m
                and rotation_angle(obj.pose.quat_xyzw, yaw_quat(goal.yaw)) <= self.contract.success_angle_rad)

    # ------------------------------------------------------------------ the tick
    def step(self, timing: TickTiming, base: TrackedPose | None, obj: TrackedPose | None, robot: ReceivedState | None,
             goal: Goal | None, goal_changed: bool) -> RobotCommand:
        """One tick at ``timing.start`` (runtime clock [s]); fills :attr:`record` and returns the command."""
        now = timing.start
        age = lambda tracked: now - tracked.receive_time if tracked is not None else math.inf  # noqa: E731
        base_age, object_age, robot_age = age(base), age(obj), age(robot)
        self.mocap_age = max(base_age, object_age)
        fresh = self.mocap_age <= self._mocap_timeout_s
        self.record.fill(np.nan)
        if goal_changed:
            self._goal_height = None  # taken at the next observation
        finite, tilt, actions = self._measure(base, obj, robot, goal if fresh else None)

        previous = self.safety.state
        overrun = self.overruns.add(timing)
        if overrun is not None and previous != State.STOPPED:
            _LOG.error("%s; stopping", overrun)
            self.safety.trip(overrun)
        state = self.safety.update(SafetyInputs(
            now=now, robot_age=robot_age, mocap_age=self.mocap_age, tilt=tilt, finite=finite, ramp_done=self._ramp_done,
            has_goal=goal is not None, at_goal=fresh and goal is not None and self._at_goal(obj, goal),
            goal_changed=goal_changed,
        ))
        if state == State.RAMP and previous != State.RAMP:
            self._ramp_start, self._ramp_from, self._ramp_done = now, robot.state.arm_q.copy(), False
        state, base_command, arm_targets, leg_targets = self._commands(now, state, actions, robot)

        self._seq += 1
        command = RobotCommand(seq=self._seq, stamp_s=now, mode=MODE_TARGETS if state in ACTIVE_STATES else MODE_STOP,
                               state=int(state), base_command=base_command, arm_targets=arm_targets,
                               leg_targets=leg_targets)
        self._fill_record(timing, command, base, obj, goal, (base_age, object_age, robot_age))
        return command

    def _measure(self, base: TrackedPose | None, obj: TrackedPose | None, robot: ReceivedState | None,
                 goal: Goal | None) -> tuple[bool, float, np.ndarray | None]:
        """(everything finite, base tilt [rad] or NaN, policy actions or None); ``goal`` None without fresh mocap."""
        view = self.layout.view
        finite, tilt, actions = True, math.nan, None
        if robot is not None:
            values = robot.state.values()
            view(self.record, "robot_state")[:values.size] = values  # onboard locomotion: legs reported or not
            finite = bool(np.isfinite(values).all())
            if finite and np.linalg.norm(robot.state.base_quat_xyzw) > 1e-9:
                tilt = tilt_angle(robot.state.base_quat_xyzw)
        if robot is not None and goal is not None and finite:
            obs = view(self.record, "obs")
            obs[:] = self.observe(base, obj, robot, goal)
            actions = self.push.run().astype(np.float64)
            view(self.record, "actions")[:] = actions
            finite = bool(np.isfinite(obs).all() and np.isfinite(actions).all())
        return finite, tilt, actions

    def _commands(self, now: float, state: State, actions: np.ndarray | None,
                  robot: ReceivedState | None) -> tuple[State, np.ndarray, np.ndarray, np.ndarray]:
        """The clamped base command, arm and leg targets of ``state`` (which a locomotion fault may turn STOPPED)."""
        base_command = self._mapping.base.default.copy()
        arm_targets = self._arm_hold.copy()
        clipped = None
        if state == State.RAMP:
            alpha = min(1.0, (now - self._ramp_start) / self._ramp_s)
            arm_targets = self._ramp_from + alpha * (self._arm_default - self._ramp_from)
            self._ramp_done = alpha >= 1.0  # the default pose has been commanded
        elif state == State.PUSH:
            clipped = self._mapping.clipped(actions)
            base_command, arm_targets = self._mapping.commands(clipped)
        leg_targets = self._leg_hold.copy()
        # The locomotion network reads the base command the robot receives, clamped to its limits (as in training).
        fault = self.limits.clamp(base_command, arm_targets, np.zeros(0))
        if fault is None:
            if self.locomotion is not None and state in ACTIVE_STATES:
                leg_targets = self.locomotion.step(robot.state, base_command)
                self.layout.view(self.record, "locomotion_obs")[:] = self.locomotion.model.input[0]
                # the raw network output, as the push policy's actions column (replay re-runs the network on the inputs)
                self.layout.view(self.record, "locomotion_actions")[:] = self.locomotion.model.output[0]
            fault = self.limits.clamp(base_command, arm_targets, leg_targets)
        if fault is not None:
            state = self.safety.trip(fault)
            base_command, arm_targets, leg_targets = self._stop_targets()
        if state in ACTIVE_STATES:
            self._arm_hold, self._leg_hold = arm_targets, leg_targets
            # a_{t-1} of the next observation: the policy's clipped output, or what was applied, as actions
            self._last_actions = clipped if clipped is not None else self._mapping.actions(base_command, arm_targets)
        return state, base_command, arm_targets, leg_targets

    def stop(self, now: float, reason: str) -> RobotCommand:
        """Latches STOPPED with ``reason`` and returns the stop command (``now``: runtime clock [s]); for a tick that
        could not finish."""
        state = self.safety.trip(reason)
        self._seq += 1
        return RobotCommand(self._seq, now, MODE_STOP, int(state), *self._stop_targets())

    def _stop_targets(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What a stop command carries: the default base command and the last targets that passed the check."""
        targets = self._mapping.base.default.copy(), self._arm_hold.copy(), self._leg_hold.copy()
        self.limits.clamp(*targets)  # finite: validated defaults, or targets that passed this check
        return targets

    def _fill_record(self, timing: TickTiming, command: RobotCommand, base: TrackedPose | None, obj: TrackedPose | None,
                     goal: Goal | None, ages: tuple[float, float, float]) -> None:
        record, view = self.record, self.layout.view
        scalars = (("time_s", timing.start), ("tick", timing.index), ("state", command.state), ("mode", command.mode),
                   ("lateness_s", timing.lateness), ("skipped", timing.skipped), ("base_age_s", ages[0]),
                   ("object_age_s", ages[1]), ("robot_age_s", ages[2]))
        for name, value in scalars:
            view(record, name)[0] = value
        for name, tracked in (("base", base), ("object", obj)):
            if tracked is not None:
                view(record, f"{name}_position")[:] = tracked.pose.position
                view(record, f"{name}_quat_xyzw")[:] = tracked.pose.quat_xyzw
        if goal is not None:
            view(record, "goal")[:] = (goal.x, goal.y, goal.yaw)
        view(record, "base_command")[:] = command.base_command
        view(record, "arm_targets")[:] = command.arm_targets
        if self._leg_joints:
            view(record, "leg_targets")[:] = command.leg_targets
