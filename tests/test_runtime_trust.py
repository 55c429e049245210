"""The runtime's network trust model over loopback UDP: only allowed senders, one robot peer in reply mode, no
replayed or reordered datagrams, goals within the workspace; and a time-bounded stateful fuzz of the receivers and
the controller in which every command that leaves is finite and within its limits."""

import logging
import math
import time

import numpy as np
import pytest

from dynpush.runtime.app import Runtime
from dynpush.runtime.config import GoalsConfig, MocapConfig, RobotConfig, config_from_dict
from dynpush.runtime.goals import GoalManager
from dynpush.runtime.mocap import UdpMocapSource
from dynpush.runtime.packets import (
    GOAL_NEXT, GOAL_SET, MODE_STOP, MODE_TARGETS, GoalCommand, MocapBody, MocapFrame, RobotCommand, decode_command,
    encode_goal, encode_mocap, encode_state,
)
from dynpush.runtime.robot_link import UdpRobotLink
from dynpush.runtime.safety import State
from dynpush.runtime.timing import Ticker
from dynpush.runtime.trust import SEQ_MODULUS, newer
from dynpush.runtime.udp import UdpEndpoint
from test_runtime_helpers import contract, lockstep_config, robot_state, run_with_robot, write_policy

FOREIGN = "127.0.0.2"  # another loopback address: a sender that is not in allowed_senders


def deliver(*receivers) -> None:
    """Lets loopback datagrams arrive, then polls every receiver."""
    time.sleep(0.05)
    for receiver in receivers:
        if isinstance(receiver, GoalManager):
            receiver.poll(0.0, None)
        else:
            receiver.poll(0.0)


def mocap_frame(seq: int, x: float = 0.0) -> bytes:
    quat = np.array([0.0, 0.0, 0.0, 1.0])
    return encode_mocap(MocapFrame(seq, 0.0, [MocapBody("base", np.array([x, 0.0, 0.5]), quat)]))


def test_sequence_numbers_compare_on_the_wrapping_counter():
    assert newer(6, 5) and not newer(5, 5) and not newer(4, 5)
    assert newer(0, SEQ_MODULUS - 1), "the counter wraps"
    assert not newer(SEQ_MODULUS - 1, 0), "just before is older, not 2**32 - 1 ahead"


def test_spoofed_state_over_loopback_cannot_redirect_commands():
    link = UdpRobotLink(RobotConfig(port=0, robot_address=""), leg_joints=0)  # reply mode
    robot, intruder, foreign = UdpEndpoint("127.0.0.1", 0), UdpEndpoint("127.0.0.1", 0), UdpEndpoint(FOREIGN, 0)
    address = ("127.0.0.1", link.endpoint.port)
    robot.send(encode_state(robot_state(seq=1)), address)
    deliver(link)
    assert link.guard.peer == ("127.0.0.1", robot.port), "the first admitted sender is the robot"
    intruder.send(encode_state(robot_state(seq=99)), address)  # an allowed address, but not the robot's port
    foreign.send(encode_state(robot_state(seq=99)), address)
    deliver(link)
    assert link.latest.state.seq == 1 and link.stats.foreign == 2 and link.stats.states == 1
    link.send(RobotCommand(1, 0.0, MODE_STOP, 0, np.zeros(6), np.zeros(5), np.zeros(0)))
    time.sleep(0.05)
    assert len(robot.drain()) == 1 and intruder.drain() == [] and foreign.drain() == [], "commands still go to the robot"
    for endpoint in (link, robot, intruder, foreign):
        endpoint.close()


def test_datagrams_only_from_allowed_senders():
    strict = UdpMocapSource(MocapConfig(port=0))
    trusting = UdpMocapSource(MocapConfig(port=0, allowed_senders=["127.0.0.1", FOREIGN]))
    goals = GoalManager(GoalsConfig(command_port=0))
    foreign = UdpEndpoint(FOREIGN, 0)
    for source in (strict, trusting):
        foreign.send(mocap_frame(1), ("127.0.0.1", source.endpoint.port))
    foreign.send(encode_goal(GoalCommand(1, GOAL_SET, 1.0, 1.0, 0.0)), ("127.0.0.1", goals.endpoint.port))
    deliver(strict, trusting, goals)
    assert strict.base is None and strict.stats.foreign == 1 and strict.stats.frames == 0
    assert trusting.base is not None and trusting.stats.foreign == 0
    assert goals.goal is None and goals.stats.foreign == 1 and goals.stats.accepted == 0
    for endpoint in (strict, trusting, goals, foreign):
        endpoint.close()


def test_replayed_and_reordered_datagrams_are_dropped_per_sender():
    mocap = UdpMocapSource(MocapConfig(port=0))
    first, second = UdpEndpoint("127.0.0.1", 0), UdpEndpoint("127.0.0.1", 0)
    address = ("127.0.0.1", mocap.endpoint.port)
    for seq, x in ((5, 0.5), (5, 9.0), (3, 9.0), (6, 0.6)):  # new, duplicate, reordered, new
        first.send(mocap_frame(seq, x), address)
    deliver(mocap)
    assert mocap.stats.frames == 2 and mocap.stats.replayed == 2 and mocap.base.pose.position[0] == 0.6
    second.send(mocap_frame(1, 0.1), address)  # another sender is a stream of its own
    deliver(mocap)
    assert mocap.stats.frames == 3 and mocap.base.pose.position[0] == 0.1
    first.send(mocap_frame(6, 9.0), address)  # the first sender's replay stays dropped
    deliver(mocap)
    assert mocap.stats.replayed == 3 and mocap.base.pose.position[0] == 0.1
    for endpoint in (mocap, first, second):
        endpoint.close()


def test_goals_outside_the_workspace_are_refused_and_logged_and_nothing_stops(tmp_path, caplog):
    cfg = lockstep_config(write_policy(tmp_path / "p.onnx"), tmp_path, goals={"sequence": [{"x": 1.0, "y": 0.0}]})
    bad = {10: (1e6, -1e6, 0.0), 12: (1e300, 0.0, 0.0), 14: (math.nan, 0.0, 0.0), 16: (1.0, 0.5, math.inf)}

    def script(step, robot):
        if step in bad:
            robot.send_goal(*bad[step])
        if step == 20:
            robot.send_goal(-1.0, 2.0, 7.0)  # within the workspace; the yaw wraps

    with caplog.at_level(logging.WARNING, logger="dynpush.runtime"):
        summary, robot, runtime = run_with_robot(cfg, 30, script)
    assert summary["goal_commands"]["refused"] == 4 and summary["goal_commands"]["accepted"] == 1
    assert "STOPPED" not in summary["states"] and summary["final_state"] == "PUSH"
    assert "x 1000000.0 m outside the workspace [-5.0, 5.0]" in caplog.text and "yaw inf rad not finite" in caplog.text
    assert runtime.goals.goal.x == -1.0 and runtime.goals.goal.yaw == pytest.approx(7.0 - 2.0 * math.pi)


# ---------------------------------------------------------------------------------------------- stateful fuzz
class ManualClock:
    """Simulated time that jumps to each deadline, so the fuzz ticks as fast as it computes."""

    def __init__(self):
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep_until(self, deadline: float) -> None:
        self.t = max(self.t, deadline)


class Fuzzer:
    """Random traffic into one runtime: a robot (the latched peer) and a mocap system that are sometimes late,
    garbled, replaying or reporting NaN, 12 leg joints or a fall; goal commands anywhere; an intruder on an allowed
    address and a foreign host sending anything."""

    def __init__(self, runtime: Runtime, rng: np.random.Generator):
        self.runtime, self.rng = runtime, rng
        self.robot, self.intruder, self.foreign = (UdpEndpoint(a, 0) for a in ("127.0.0.1", "127.0.0.1", FOREIGN))
        self.ports = {"state": runtime.link.endpoint.port, "mocap": runtime.mocap.endpoint.port,
                      "goal": runtime.goals.endpoint.port}
        self.seq = {"state": 0, "mocap": 0, "goal": 0}
        self.rates = {"state": rng.uniform(0.8, 1.0), "mocap": rng.uniform(0.4, 1.0), "goal": 0.05}  # per tick

    def _next_seq(self, stream: str) -> int:
        replay = self.rng.random() < 0.1
        self.seq[stream] += 0 if replay else int(self.rng.integers(1, 3))
        return self.seq[stream] - (int(self.rng.integers(0, 3)) if replay else 0)

    def _number(self, scale: float, bad: float = 0.002) -> float:
        """Mostly ``scale``-sized noise; with probability ``bad`` a NaN, an infinity or 1e300."""
        if self.rng.random() < bad:
            return float(self.rng.choice([np.nan, np.inf, -np.inf, 1e300]))
        return float(scale * self.rng.standard_normal())

    def _state(self) -> bytes:
        state = robot_state(seq=self._next_seq("state"), legs=int(self.rng.choice([0, 12])))
        if self.rng.random() < 0.005:
            state.base_quat_xyzw[:] = self.rng.standard_normal(4)  # a fall, or nonsense
        state.arm_q += [self._number(0.1) for _ in range(5)]
        state.base_linear_velocity_b[:] = [self._number(0.3) for _ in range(3)]
        return encode_state(state)

    def _mocap(self) -> bytes:
        quat = np.array([0.0, 0.0, self._number(0.2), 1.0])
        bodies = [MocapBody("base", np.array([-1.0 + self._number(0.1), self._number(0.1), 0.5]), quat),
                  MocapBody("object", np.array([self._number(0.3), self._number(0.3), 0.35]), quat)]
        return encode_mocap(MocapFrame(self._next_seq("mocap"), 0.0, bodies))

    def _goal(self) -> bytes:
        x, y, yaw = (self._number(float(self.rng.choice([1.0, 1e6])), bad=0.2) for _ in range(3))
        return encode_goal(GoalCommand(self._next_seq("goal"), int(self.rng.choice([GOAL_SET, GOAL_NEXT])), x, y, yaw))

    def _garble(self, data: bytes) -> bytes:
        data = bytearray(data)
        data[int(self.rng.integers(0, len(data)))] ^= 0xFF
        return bytes(data[:int(self.rng.integers(len(data) // 2, len(data) + 1))])

    def send(self) -> None:
        """One tick's traffic."""
        for stream, make in (("state", self._state), ("mocap", self._mocap), ("goal", self._goal)):
            if self.rng.random() < self.rates[stream]:
                data = make()
                self.robot.send(self._garble(data) if self.rng.random() < 0.05 else data, ("127.0.0.1", self.ports[stream]))
            if self.rng.random() < 0.1 and self.runtime.link.guard.peer is not None:  # strangers once the robot is known
                sender = self.intruder if self.rng.random() < 0.5 else self.foreign
                sender.send(make(), ("127.0.0.1", self.ports[stream]))

    def close(self) -> None:
        for endpoint in (self.robot, self.intruder, self.foreign):
            endpoint.close()


def check_command(command: RobotCommand, limits: dict) -> None:
    values = np.concatenate([command.base_command, command.arm_targets, command.leg_targets])
    assert np.isfinite(values).all(), command
    assert command.mode == (MODE_TARGETS if command.state not in (State.STARTUP, State.STOPPED) else MODE_STOP), command
    for name, values, (lower, upper) in (("base", command.base_command, limits["base"]),
                                         ("arm", command.arm_targets, limits["arm"])):
        assert (lower <= values).all() and (values <= upper).all(), (name, command)


def test_fuzz_receivers_and_controller_keep_every_command_safe(tmp_path):
    """Runtimes of 150 ticks each under random traffic until 4 s are up: no tick raises, every command that reaches the
    robot is finite and within its limits, STOPPED stays latched, no goal outside the workspace is taken, and no
    command reaches anyone but the robot."""
    policy = write_policy(tmp_path / "p.onnx", bias=np.full(11, 0.5))
    c = contract()
    limits = {"base": (np.array(c.base_command_lower), np.array(c.base_command_upper)),
              "arm": (np.array(c.arm_joint_lower), np.array(c.arm_joint_upper))}
    rng = np.random.default_rng(31)
    deadline, runs, commands = time.monotonic() + 4.0, 0, 0
    while time.monotonic() < deadline or runs < 2:
        cfg = config_from_dict({"push_policy": {"path": str(policy)}, "mocap": {"port": 0},
                                "robot": {"port": 0, "robot_address": ""}, "goals": {"command_port": 0},
                                "safety": {"arm_ramp_s": 0.1}, "log": {"directory": str(tmp_path / "logs")}})
        runtime = Runtime(cfg)
        runtime.clock = ManualClock()
        runtime.ticker = Ticker(runtime.clock, cfg.control_period_s)
        fuzzer = Fuzzer(runtime, rng)
        stopped = False
        try:
            for _ in range(150):
                fuzzer.send()
                time.sleep(0.0005)  # loopback delivery
                runtime.tick()
                goal = runtime.goals.goal
                assert goal is None or cfg.goals.workspace.outside(goal.x, goal.y) is None
                stopped = stopped or runtime.controller.safety.state == State.STOPPED
                assert runtime.controller.safety.state == State.STOPPED or not stopped, "STOPPED is latched"
                for datagram in fuzzer.robot.drain():
                    check_command(decode_command(datagram.data), limits)
                    commands += 1
                assert fuzzer.intruder.drain() == [] and fuzzer.foreign.drain() == []
        finally:
            runtime.run(max_ticks=0)  # closes sockets and log
            fuzzer.close()
        runs += 1
    assert commands > 100, "the fuzz reached the robot"
