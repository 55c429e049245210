"""Safety state machine transitions (stale mocap, stale robot state, NaN, attitude, success, new goal), the
controller's outputs in each state (ramp, hold, clamping, stop), its stop on the runtime's own overruns, the check of
every outgoing command, a locomotion ONNX, and frame conversion."""

import math

import numpy as np
import pytest

from dynpush.runtime.config import config_from_dict
from dynpush.runtime.controller import Controller
from dynpush.runtime.frames import BodyOffset, FrameConvention, Pose, PoseConverter, yaw_quat
from dynpush.runtime.goals import Goal
from dynpush.runtime.locomotion import OnnxLocomotion
from dynpush.runtime.mocap import TrackedPose
from dynpush.runtime.packets import MODE_STOP, MODE_TARGETS
from dynpush.runtime.policy import load_push_policy
from dynpush.runtime.robot_link import ReceivedState
from dynpush.runtime.safety import CommandLimits, SafetyInputs, SafetyMachine, State
from dynpush.runtime.timing import TickTiming
from test_runtime_helpers import ARM_DEFAULT, contract, robot_state, write_gemm, write_policy

LEGS = [f"{leg}_{joint}" for leg in ("LF", "RF", "LH", "RH") for joint in ("HAA", "HFE", "KFE")]
SQ = math.sqrt(0.5)


# ---------------------------------------------------------------------------------------------- state machine
def inputs(**changes) -> SafetyInputs:
    values = dict(now=0.0, robot_age=0.0, mocap_age=0.0, tilt=0.0, finite=True, ramp_done=True, has_goal=True,
                  at_goal=False, goal_changed=False)
    return SafetyInputs(**(values | changes))


def machine() -> SafetyMachine:
    return SafetyMachine(robot_timeout_s=0.1, mocap_timeout_s=0.1, max_tilt_rad=math.radians(30.0))


def test_startup_ramp_push_and_mocap_loss():
    m = machine()
    assert m.update(inputs(robot_age=math.inf, mocap_age=math.inf)) == State.STARTUP
    assert m.update(inputs(robot_age=math.inf, finite=False)) == State.STARTUP, "nothing to judge before robot state"
    assert m.update(inputs(mocap_age=math.inf)) == State.RAMP
    assert m.update(inputs(ramp_done=False)) == State.RAMP
    assert m.update(inputs(mocap_age=0.5)) == State.MOCAP_LOST, "ramp ends into mocap loss when mocap is stale"
    assert m.update(inputs()) == State.PUSH
    assert m.update(inputs(mocap_age=0.11)) == State.MOCAP_LOST
    assert m.update(inputs(mocap_age=0.09)) == State.PUSH


def test_success_holds_until_a_new_goal():
    m = machine()
    m.update(inputs())
    m.update(inputs())
    assert m.state == State.PUSH
    assert m.update(inputs(now=3.0, at_goal=True)) == State.HOLD and m.reason == "goal reached"
    assert m.reached_since == 3.0
    assert m.update(inputs(at_goal=False)) == State.HOLD, "no resumption without a new goal"
    assert m.update(inputs(mocap_age=1.0)) == State.MOCAP_LOST
    assert m.update(inputs()) == State.HOLD, "the goal stays reached across a mocap loss"
    assert m.update(inputs(goal_changed=True)) == State.PUSH and m.reached_since is None
    m2 = machine()
    m2.update(inputs())
    assert m2.update(inputs(has_goal=False)) == State.HOLD and m2.reason == "no goal"


@pytest.mark.parametrize("bad, reason", [
    ({"robot_age": 0.2}, "robot state stale"),
    ({"finite": False}, "non-finite"),
    ({"tilt": math.radians(31.0)}, "base tilt 31.0 deg"),
    ({"tilt": math.nan}, "base tilt"),
])
@pytest.mark.parametrize("state", [State.RAMP, State.PUSH, State.HOLD, State.MOCAP_LOST])
def test_stop_conditions_latch_from_every_state(state, bad, reason):
    m = machine()
    m.state = state
    assert m.update(inputs(**bad)) == State.STOPPED and reason in m.reason
    assert m.update(inputs()) == State.STOPPED, "STOPPED is latched until restart"


# ---------------------------------------------------------------------------------------------- controller
def controller(tmp_path, bias=None, locomotion=False, leg_output=10.0, **sections) -> Controller:
    policy = write_policy(tmp_path / "p.onnx", bias=bias)
    data = {"push_policy": {"path": str(policy)}, "safety": {"arm_ramp_s": 1.0}}
    if locomotion:
        write_gemm(tmp_path / "loco.onnx", 3 + 6 + 12 + 5, 12, scale=0.0, bias=np.full(12, leg_output))
        data |= {"locomotion": {"mode": "onnx", "onnx": {
            "path": str(tmp_path / "loco.onnx"), "joint_names": LEGS, "default_joint_positions": [0.1] * 12,
            "observation": [{"name": "projected_gravity_b"}, {"name": "base_command", "scale": 2.0},
                            {"name": "leg_joint_position"}, {"name": "arm_joint_position"}]}},
                 "robot": {"leg_joint_names": LEGS}}
        data["safety"] |= {"leg_joint_lower": [-1.0] * 12, "leg_joint_upper": [1.0] * 12}
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value}
    cfg = config_from_dict(data)
    push, c = load_push_policy(cfg)
    return Controller(cfg, c, push, OnnxLocomotion(cfg.locomotion.onnx, c) if locomotion else None)


class Ticks:
    """Drives a controller tick by tick with fresh measurements unless told otherwise."""

    def __init__(self, ctrl: Controller, legs: int = 0):
        self.ctrl, self.k, self.legs = ctrl, 0, legs
        self.skipped = 0
        self.state = robot_state(legs=legs)
        self.object = np.array([0.0, 0.0, 0.35])
        self.goal = Goal(1.0, 0.0, 0.0)

    def __call__(self, mocap_age=0.0, robot_age=0.0, goal_changed=False, skip=0):
        """One tick; ``skip``: deadlines skipped before it (the previous tick overran)."""
        self.k += skip
        self.skipped += skip
        t = 0.02 * self.k
        timing = TickTiming(index=self.k, deadline=t, start=t, lateness=0.0, skipped=self.skipped)
        self.k += 1
        base = TrackedPose(Pose(np.array([-1.0, 0.0, 0.5]), np.array([0, 0, 0, 1.0])), t - mocap_age)
        obj = TrackedPose(Pose(self.object.copy(), np.array([0, 0, 0, 1.0])), t - mocap_age)
        return self.ctrl.step(timing, base, obj, ReceivedState(self.state, t - robot_age), self.goal, goal_changed)


def test_ramp_moves_the_arm_linearly_to_default(tmp_path):
    ticks = Ticks(controller(tmp_path))
    start = np.array(ARM_DEFAULT) + 0.4
    ticks.state.arm_q[:] = start
    commands = [ticks() for _ in range(60)]
    assert [c.state for c in commands[:51]] == [State.RAMP] * 51 and commands[51].state == State.PUSH
    for k in (0, 25, 50):
        np.testing.assert_allclose(commands[k].arm_targets, start + (k / 50) * (np.array(ARM_DEFAULT) - start), atol=1e-9)
        np.testing.assert_array_equal(commands[k].base_command, [0, 0, 0, 0, 0, 0.5])
        assert commands[k].mode == MODE_TARGETS


def test_the_goal_height_is_the_objects_when_the_goal_arrived(tmp_path):
    """Training puts the goal at the object's resting centroid height (half its height); the runtime, which does not
    know the object, takes its measured height when the goal arrives, so a tilting object moves off its goal in z."""
    ticks = Ticks(controller(tmp_path))
    object_to_goal_b = slice(31, 34)  # runtime.observation.POLICY_OBSERVATION_LAYOUT; the base frame is the world's here
    ticks()
    np.testing.assert_allclose(ticks.ctrl.push.input[0, object_to_goal_b], [1.0, 0.0, 0.0], atol=1e-6)
    ticks.object[2] = 0.45  # the object tilts: its centroid rises
    ticks()
    np.testing.assert_allclose(ticks.ctrl.push.input[0, object_to_goal_b], [1.0, 0.0, -0.1], atol=1e-6)
    ticks(goal_changed=True)  # a new goal is taken at the height the object has now
    np.testing.assert_allclose(ticks.ctrl.push.input[0, object_to_goal_b], [1.0, 0.0, 0.0], atol=1e-6)


def test_push_commands_are_clamped_to_limits(tmp_path):
    huge = np.array([50.0, -50.0, 50.0, -50.0, 50.0, 50.0, 50.0, -50.0, 50.0, -50.0, 50.0])
    lower, upper = [-1.0, -1.0, 0.5, -1.0, -1.0], [1.0, 0.4, 1.5, 1.0, 1.0]  # within the contract's
    ticks = Ticks(controller(tmp_path, bias=huge, safety={"arm_ramp_s": 0.02, "arm_joint_lower": lower,
                                                          "arm_joint_upper": upper}))
    command = [ticks() for _ in range(5)][-1]
    assert command.state == State.PUSH
    c = contract()
    expected_base = np.where(huge[:6] > 0, c.base_command_upper, c.base_command_lower)
    np.testing.assert_allclose(command.base_command, expected_base)
    np.testing.assert_allclose(command.arm_targets, np.where(huge[6:] > 0, upper, lower))
    np.testing.assert_allclose(ticks.ctrl.record[ticks.ctrl.layout.slices["actions"]], huge, atol=2.0,
                               err_msg="the log keeps the raw (unclipped) policy output")


def test_success_stop_and_resume_with_a_new_goal(tmp_path):
    ticks = Ticks(controller(tmp_path, bias=np.full(11, 0.5), safety={"arm_ramp_s": 0.02}))
    pushing = [ticks() for _ in range(4)][-1]
    assert pushing.state == State.PUSH and pushing.base_command[0] == pytest.approx(0.5, abs=0.05)
    ticks.object[:] = (1.05, 0.03, 0.35)  # 5.8 cm from the goal, aligned: success
    held = ticks()
    assert held.state == State.HOLD
    np.testing.assert_array_equal(held.base_command, [0, 0, 0, 0, 0, 0.5])
    np.testing.assert_array_equal(held.arm_targets, pushing.arm_targets)
    ticks.goal = Goal(1.0, 0.0, math.radians(45.0))
    assert ticks(goal_changed=True).state == State.PUSH


def test_stale_mocap_zero_base_arm_holds(tmp_path):
    ticks = Ticks(controller(tmp_path, bias=np.full(11, 0.5), safety={"arm_ramp_s": 0.02}))
    pushing = [ticks() for _ in range(4)][-1]
    lost = ticks(mocap_age=0.15)
    assert lost.state == State.MOCAP_LOST and lost.mode == MODE_TARGETS
    np.testing.assert_array_equal(lost.base_command, [0, 0, 0, 0, 0, 0.5])
    np.testing.assert_array_equal(lost.arm_targets, pushing.arm_targets)
    assert np.isnan(ticks.ctrl.record[ticks.ctrl.layout.slices["obs"]]).all(), "no observation from stale mocap"
    assert ticks().state == State.PUSH


@pytest.mark.parametrize("fault", ["nan_state", "nan_policy", "tilt", "stale_robot"])
def test_faults_stop_the_robot(tmp_path, fault):
    bias = np.full(11, np.nan) if fault == "nan_policy" else None
    ticks = Ticks(controller(tmp_path, bias=bias, safety={"arm_ramp_s": 0.02}))
    ticks()
    if fault == "nan_state":
        ticks.state.arm_qd[2] = np.nan
    elif fault == "tilt":
        ticks.state.base_quat_xyzw[:] = (math.sin(math.radians(20)), 0.0, 0.0, math.cos(math.radians(20)))  # 40 deg roll
    command = ticks(robot_age=0.5 if fault == "stale_robot" else 0.0)
    if fault == "nan_policy":  # the policy only runs once the ramp is over
        command = [ticks() for _ in range(3)][-1]
    assert command.state == State.STOPPED and command.mode == MODE_STOP
    assert np.isfinite(command.base_command).all() and np.isfinite(command.arm_targets).all()


def test_overruns_beyond_the_limit_stop_the_robot(tmp_path, caplog):
    """``rates.overrun``: 2 skipped deadlines within 10 periods are allowed, the 3rd latches STOPPED."""
    ticks = Ticks(controller(tmp_path, bias=np.full(11, 0.5), safety={"arm_ramp_s": 0.02},
                             rates={"overrun": {"max_skipped": 2, "window_periods": 10}}))
    assert [ticks() for _ in range(4)][-1].state == State.PUSH and ticks(skip=2).state == State.PUSH
    last = ticks()
    assert last.state == State.PUSH, "2 skipped deadlines are within the limit"
    stopped = ticks(skip=1)
    assert stopped.state == State.STOPPED and stopped.mode == MODE_STOP
    np.testing.assert_array_equal(stopped.arm_targets, last.arm_targets, err_msg="the last targets that passed")
    assert [ticks() for _ in range(12)][-1].state == State.STOPPED, "latched after the skips left the window"
    reason = "control rate: 3 deadlines skipped in the last 10 control periods (limit 2)"
    assert ticks.ctrl.safety.reason == reason and [r.getMessage() for r in caplog.records] == [f"{reason}; stopping"]


def test_the_goal_is_reached_as_training_counts_it(tmp_path):
    """Within the success distance of the goal point in 3D, at the goal's height (the object's when the goal came): an
    object at the goal's x, y but 15 cm lower (tilted, say) has not arrived; 5 cm lower it has."""
    ticks = Ticks(controller(tmp_path, safety={"arm_ramp_s": 0.02}))
    ticks.object, ticks.goal = np.array([0.5, 0.0, 0.35]), Goal(0.0, 0.0, 0.0)
    assert [ticks() for _ in range(4)][-1].state == State.PUSH
    ticks.object = np.array([0.0, 0.0, 0.20])
    assert ticks().state == State.PUSH
    ticks.object = np.array([0.0, 0.0, 0.30])
    assert ticks().state == State.HOLD


def test_locomotion_onnx_sends_12_leg_and_5_arm_targets(tmp_path):
    ticks = Ticks(controller(tmp_path, locomotion=True, safety={"arm_ramp_s": 0.02}), legs=12)
    command = [ticks() for _ in range(3)][-1]
    assert command.mode == MODE_TARGETS and command.arm_targets.shape == (5,) and command.leg_targets.shape == (12,)
    np.testing.assert_allclose(command.leg_targets, 1.0, err_msg="0.1 + 0.5 * 10 clamped to the leg limit 1.0")
    ctrl = ticks.ctrl
    obs = ctrl.record[ctrl.layout.slices["locomotion_obs"]]
    np.testing.assert_allclose(obs[:3], [0, 0, -1], err_msg="projected gravity from the IMU")
    np.testing.assert_allclose(obs[3:9], 2.0 * command.base_command, rtol=1e-6, err_msg="scaled base command")
    np.testing.assert_allclose(obs[9:21], -0.1, rtol=1e-6, err_msg="leg positions relative to the default")


def test_the_locomotion_network_reads_the_clamped_base_command(tmp_path):
    """A push policy that asks for more than the base command's limits: the locomotion network's command term is the
    command the robot receives, clamped, as the legged simulator gives it in training."""
    ctrl = controller(tmp_path, bias=np.full(11, 3.0), locomotion=True, safety={"arm_ramp_s": 0.02})
    ticks = Ticks(ctrl, legs=12)
    command = [ticks() for _ in range(3)][-1]
    assert command.state == State.PUSH
    mapping = ctrl.contract.action_mapping()
    asked, _ = mapping.commands(mapping.clipped(np.full(11, 3.0)))
    upper = np.array(ctrl.contract.base_command_upper)
    assert (asked > upper).any()
    np.testing.assert_allclose(command.base_command, np.minimum(asked, upper))
    obs = ctrl.record[ctrl.layout.slices["locomotion_obs"]]
    np.testing.assert_allclose(obs[3:9], 2.0 * command.base_command, rtol=1e-6, err_msg="the clamped command, scaled")


@pytest.mark.parametrize("leg_output", [25.0, -1e6])
def test_locomotion_outputs_are_clipped_at_the_push_policy_action_clip(tmp_path, leg_output):
    """As the legged simulator clips them (``env.actions.clip``, which the push policy's contract carries as
    ``action_clip``): an output beyond the bound gives the leg target of the bound, and the next observation's
    ``last_leg_actions`` hold the clipped output; the tick log keeps the raw one (replay re-runs the network)."""
    ctrl = controller(tmp_path, locomotion=True, leg_output=leg_output, safety={"arm_ramp_s": 0.02})
    loco, bound = ctrl.locomotion, math.copysign(ctrl.contract.action_clip, leg_output)
    assert ctrl.contract.action_clip == 10.0
    targets = loco.step(robot_state(legs=12), np.zeros(6))
    np.testing.assert_allclose(targets, 0.1 + 0.5 * bound, err_msg="default + action_scale * the bound")
    np.testing.assert_allclose(loco.last_actions, bound)
    ticks = Ticks(ctrl, legs=12)
    ticks()
    np.testing.assert_allclose(ctrl.record[ctrl.layout.slices["locomotion_actions"]], leg_output)


@pytest.mark.parametrize("leg_output", [np.nan, np.inf])
def test_a_command_that_is_not_finite_is_never_sent(tmp_path, leg_output):
    """The last check before a command leaves: a locomotion network gone NaN or infinite (clamping keeps a NaN a NaN)
    latches STOPPED, and the stop command carries the last targets that passed."""
    ticks = Ticks(controller(tmp_path, locomotion=True, leg_output=leg_output, safety={"arm_ramp_s": 0.02}), legs=12)
    command = ticks()
    assert command.state == State.STOPPED and command.mode == MODE_STOP
    assert ticks.ctrl.safety.reason.startswith("leg targets [") and ticks.ctrl.safety.reason.endswith("not finite")
    values = np.concatenate([command.base_command, command.arm_targets, command.leg_targets])
    assert np.isfinite(values).all()
    np.testing.assert_allclose(command.leg_targets, 0.1, err_msg="the default leg pose, clamped")


def test_command_limits_clamp_and_name_what_must_not_be_sent():
    limits = CommandLimits(np.zeros(6), np.ones(6), np.zeros(5), np.ones(5), np.zeros(0), np.zeros(0))
    base, arm = np.full(6, 0.5), np.full(5, 1.5)
    assert limits.clamp(base, arm, np.zeros(0)) is None and (arm == 1.0).all()
    assert limits.clamp(np.array([0.5, np.inf, 0.5, 0.5, 0.5, 0.5]), arm, np.zeros(0)).startswith("base command")
    inverted = CommandLimits(np.zeros(6), np.ones(6), np.ones(5), np.zeros(5), np.zeros(0), np.zeros(0))
    assert "beyond the limits" in inverted.clamp(base, np.full(5, 0.5), np.zeros(0))


# ---------------------------------------------------------------------------------------------- frames
def test_frame_conventions_convert_to_z_up_metres_xyzw():
    y_up = PoseConverter(FrameConvention(up_axis="y", quaternion_order="wxyz", units="mm"), BodyOffset())
    pose = y_up([1000.0, 2000.0, 3000.0], [SQ, 0.0, SQ, 0.0])  # (w, x, y, z): 90 deg about the up axis y
    np.testing.assert_allclose(pose.position, [1.0, -3.0, 2.0])
    np.testing.assert_allclose(pose.quat_xyzw, [0.0, 0.0, SQ, SQ], atol=1e-12, err_msg="yaw about the up axis stays yaw")
    same = PoseConverter(FrameConvention(), BodyOffset())([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 2.0])
    np.testing.assert_allclose(same.quat_xyzw, [0, 0, 0, 1.0], err_msg="quaternions are normalised")
    offset = PoseConverter(FrameConvention(), BodyOffset(position=[1.0, 0.0, 0.0], quat_xyzw=list(yaw_quat(0.5))))
    pose = offset([1.0, 1.0, 0.0], yaw_quat(math.pi / 2))
    np.testing.assert_allclose(pose.position, [1.0, 2.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(pose.quat_xyzw, yaw_quat(math.pi / 2 + 0.5), atol=1e-12)
    with pytest.raises(ValueError):
        offset([np.nan, 0.0, 0.0], [0, 0, 0, 1.0])
