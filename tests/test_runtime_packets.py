"""UDP datagrams: exact round trips, and fuzzing (random bytes, truncations, bit flips) of every parser and
of the sockets the runtime listens on: malformed datagrams are counted and dropped, nothing crashes."""

import time

import numpy as np
import pytest

from dynpush.runtime.config import GoalsConfig, MocapConfig, RobotConfig
from dynpush.runtime.goals import GoalManager
from dynpush.runtime.mocap import UdpMocapSource
from dynpush.runtime.packets import (
    GOAL_NEXT, GOAL_SET, MODE_TARGETS, GoalCommand, MocapBody, MocapFrame, PacketError, RobotCommand, decode_command,
    decode_goal, decode_mocap, decode_state, encode_command, encode_goal, encode_mocap, encode_state,
)
from dynpush.runtime.robot_link import UdpRobotLink
from dynpush.runtime.udp import UdpEndpoint
from test_runtime_helpers import robot_state

DECODERS = (decode_mocap, decode_state, decode_command, decode_goal)


def valid_datagrams() -> list[bytes]:
    rng = np.random.default_rng(0)
    frame = MocapFrame(7, 1.5, [MocapBody("base", rng.normal(size=3), rng.normal(size=4)),
                                MocapBody("objekt ü", rng.normal(size=3), rng.normal(size=4))])
    command = RobotCommand(3, 2.0, MODE_TARGETS, 2, rng.normal(size=6), rng.normal(size=5), rng.normal(size=12))
    return [encode_mocap(frame), encode_state(robot_state(5, legs=12)), encode_command(command),
            encode_goal(GoalCommand(9, GOAL_SET, 1.0, -2.0, 0.5))]


def test_round_trips_are_exact():
    rng = np.random.default_rng(1)
    frame = MocapFrame(2**32 - 1, 12.25, [MocapBody("base", rng.normal(size=3), rng.normal(size=4))])
    back = decode_mocap(encode_mocap(frame))
    assert back.seq == frame.seq and back.stamp_s == 12.25 and back.bodies[0].name == "base"
    np.testing.assert_array_equal(back.bodies[0].position, frame.bodies[0].position)
    np.testing.assert_array_equal(back.bodies[0].quat, frame.bodies[0].quat)
    state = robot_state(4, legs=12)
    state.leg_q[:] = rng.normal(size=12)
    np.testing.assert_array_equal(decode_state(encode_state(state)).values(), state.values())
    command = RobotCommand(1, 0.5, MODE_TARGETS, 3, rng.normal(size=6), rng.normal(size=5), np.zeros(0))
    back = decode_command(encode_command(command))
    np.testing.assert_array_equal(np.concatenate([back.base_command, back.arm_targets]),
                                  np.concatenate([command.base_command, command.arm_targets]))
    assert back.leg_targets.size == 0 and back.state == 3
    assert decode_goal(encode_goal(GoalCommand(1, GOAL_NEXT, 0.0, 0.0, 0.0))).kind == GOAL_NEXT


def test_decoders_reject_other_kinds_and_bad_values():
    datagrams = valid_datagrams()
    for i, decode in enumerate(DECODERS):
        for j, data in enumerate(datagrams):
            if i != j:
                with pytest.raises(PacketError):
                    decode(data)
    goal = bytearray(datagrams[3])
    goal[8] = 7  # kind
    with pytest.raises(PacketError, match="kind must be"):
        decode_goal(bytes(goal))
    command = bytearray(datagrams[2])
    command[16] = 9  # mode
    with pytest.raises(PacketError, match="mode must be"):
        decode_command(bytes(command))


def test_fuzz_random_bytes_only_raise_packet_error():
    rng = np.random.default_rng(2)
    magics = [b"DPM1", b"DPS1", b"DPC1", b"DPG1"]
    for trial in range(4000):
        data = rng.integers(0, 256, rng.integers(0, 400), dtype=np.uint8).tobytes()
        if trial % 2:  # a valid magic in front makes the parsers go deeper
            data = magics[trial % 4] + data
        for decode in DECODERS:
            try:
                decode(data)
            except PacketError:
                pass


def test_fuzz_mutated_valid_datagrams():
    rng = np.random.default_rng(3)
    for data in valid_datagrams():
        for _ in range(1500):
            mutated = bytearray(data)
            kind = rng.integers(0, 3)
            if kind == 0:
                mutated = mutated[:rng.integers(0, len(data))]
            elif kind == 1:
                for _ in range(rng.integers(1, 4)):
                    mutated[rng.integers(0, len(mutated))] ^= 1 << int(rng.integers(0, 8))
            else:
                mutated += rng.integers(0, 256, rng.integers(1, 20), dtype=np.uint8).tobytes()
            for decode in DECODERS:
                try:
                    decode(bytes(mutated))
                except PacketError:
                    pass


def test_listening_sockets_count_and_drop_garbage():
    mocap = UdpMocapSource(MocapConfig(port=0))
    link = UdpRobotLink(RobotConfig(port=0), leg_joints=0)
    goals = GoalManager(GoalsConfig(command_port=0))
    sender = UdpEndpoint("127.0.0.1", 0)
    rng = np.random.default_rng(4)
    good = valid_datagrams()
    garbage = [rng.integers(0, 256, rng.integers(0, 200), dtype=np.uint8).tobytes() for _ in range(60)]
    bad_counts = encode_state(robot_state(legs=3))  # well-formed, but 3 leg joints
    nan_goal = encode_goal(GoalCommand(1, GOAL_SET, float("nan"), 0.0, 0.0))
    for port, extra in ((mocap.endpoint.port, []), (link.endpoint.port, [bad_counts]), (goals.endpoint.port, [nan_goal])):
        for data in [*garbage, *extra, *good]:
            sender.send(data, ("127.0.0.1", port))
    time.sleep(0.2)
    mocap.poll(1.0)
    link.poll(1.0)
    goals.poll(1.0, None)
    assert mocap.stats.malformed == 60 + 3 and mocap.stats.frames == 1
    assert mocap.base is not None and mocap.object is None, "only the configured bodies are kept ('objekt ü' is not)"
    assert link.stats.malformed == 60 + 1 + 3 and link.stats.states == 1 and link.latest.state.seq == 5
    assert goals.stats.malformed == 60 + 3 and goals.stats.refused == 1, "the NaN goal is well-formed, but no goal"
    assert goals.stats.accepted == 1 and goals.goal.x == 1.0
    for closable in (mocap, link, goals, sender):
        closable.close()


def test_non_finite_or_zero_quaternion_poses_are_dropped():
    mocap = UdpMocapSource(MocapConfig(port=0))
    sender = UdpEndpoint("127.0.0.1", 0)
    frames = [[MocapBody("base", np.array([np.nan, 0, 0]), np.array([0, 0, 0, 1.0]))],
              [MocapBody("base", np.zeros(3), np.zeros(4))],
              [MocapBody("object", np.zeros(3), np.array([0, 0, np.inf, 1.0]))]]
    for seq, bodies in enumerate(frames):
        sender.send(encode_mocap(MocapFrame(seq, 0.0, bodies)), ("127.0.0.1", mocap.endpoint.port))
    time.sleep(0.1)
    mocap.poll(0.0)
    assert mocap.stats.invalid == 3 and mocap.base is None and mocap.object is None
    mocap.close()
    sender.close()
