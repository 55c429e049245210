"""Helpers shared by the runtime tests (this file holds no tests): tiny ONNX networks, contracts, a fake clock and
a fake robot.

Networks are one Gemm layer (``y = x W + b``) with small random weights built with ``onnx.helper``;
contracts carry the dynpush robot's numbers (arm joints, defaults, limits) written out by hand, so
these tests need no simulator (the sim-to-sim test builds its contract from the real scene).
"""

from __future__ import annotations

import json
import math
import socket
import threading
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from dynpush.runtime.app import Runtime
from dynpush.runtime.config import RuntimeConfig, config_from_dict
from dynpush.runtime.contract import PolicyContract
from dynpush.runtime.packets import (
    GOAL_SET, GoalCommand, MocapBody, MocapFrame, Proprioception, RobotCommand, decode_command, encode_goal,
    encode_mocap, encode_state,
)
from dynpush.runtime.udp import UdpEndpoint

ARM_NAMES = ["SH_ROT", "SH_FLE", "EL_FLE", "FA_ROT", "WRIST_1"]
ARM_DEFAULT = [0.0, -1.2, 2.1, 0.0, 0.6]


def contract(**changes) -> PolicyContract:
    """A valid contract with the robot's action mapping; ``changes`` override fields."""
    values = dict(
        base_command_default=[0.0, 0.0, 0.0, 0.0, 0.0, 0.5], base_command_scale=[1.0, 0.6, 1.0, 0.2, 0.2, 0.1],
        base_command_lower=[-1.0, -0.6, -1.0, -0.2, -0.2, 0.4], base_command_upper=[1.0, 0.6, 1.0, 0.2, 0.2, 0.6],
        arm_joint_names=list(ARM_NAMES), arm_default_joint_positions=list(ARM_DEFAULT), arm_action_scale=0.5,
        arm_joint_lower=[-3.0, -2.5, 0.0, -3.0, -2.0], arm_joint_upper=[3.0, 0.5, 2.8, 3.0, 2.0],
        arm_joint_velocity_limit=[3.0] * 5, frozen_joint_name="WRIST_2", frozen_joint_position=0.0, action_clip=10.0,
        control_period_s=0.02, success_distance_m=0.1, success_angle_rad=math.radians(10.0),
    )
    values.update(changes)
    return PolicyContract(**values)


def write_gemm(path: Path, inputs: int, outputs: int, *, metadata: dict[str, str] | None = None, scale: float = 0.01,
               bias: np.ndarray | None = None, seed: int = 0, input_name: str = "obs", output_name: str = "actions",
               input_shape: list | None = None) -> Path:
    """A one-Gemm ONNX network ``[1, inputs] -> [1, outputs]`` with ``metadata_props``."""
    rng = np.random.default_rng(seed)
    weights = numpy_helper.from_array((scale * rng.standard_normal((inputs, outputs))).astype(np.float32), "W")
    b = np.zeros(outputs, np.float32) if bias is None else np.asarray(bias, np.float32)
    graph = helper.make_graph(
        [helper.make_node("Gemm", [input_name, "W", "B"], [output_name])], "tiny",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, input_shape or [1, inputs])],
        [helper.make_tensor_value_info(output_name, TensorProto.FLOAT, [1, outputs])],
        [weights, numpy_helper.from_array(b, "B")],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    if metadata:
        helper.set_model_props(model, metadata)
    onnx.save(model, str(path))
    return path


def write_policy(path: Path, policy_contract: PolicyContract | None = None, **kwargs) -> Path:
    """A tiny push policy ``obs [1, 54] -> actions [1, 11]`` carrying ``policy_contract`` (default: :func:`contract`)."""
    return write_gemm(path, 54, 11, metadata=(policy_contract or contract()).to_metadata(), **kwargs)


def robot_state(seq: int = 0, arm_q=ARM_DEFAULT, legs: int = 0, quat=(0.0, 0.0, 0.0, 1.0)) -> Proprioception:
    """An upright, resting robot."""
    return Proprioception(seq=seq, stamp_s=0.0, base_quat_xyzw=np.array(quat, float), base_linear_velocity_b=np.zeros(3),
                          base_angular_velocity_b=np.zeros(3), ee_position_b=np.array([0.6, 0.0, 0.3]),
                          arm_q=np.array(arm_q, float), arm_qd=np.zeros(5), leg_q=np.zeros(legs), leg_qd=np.zeros(legs))


class FakeClock:
    """A clock for :class:`~dynpush.runtime.timing.Ticker` whose time advances only when the loop sleeps or
    'computes' (``work``) [s]."""

    def __init__(self, start: float = 100.0):
        self.t = start

    def now(self) -> float:
        return self.t

    def sleep_until(self, deadline: float) -> None:
        self.t = max(self.t, deadline)

    def work(self, seconds: float) -> None:
        self.t += seconds


class FakeRobot(threading.Thread):
    """A lock-step robot and mocap system on loopback: answers every command with a mocap frame and a state.

    ``script(step, robot)`` runs before each answer (step 0 is the first message, before any command)
    and may change ``base``/``object`` poses, ``state`` or switch ``mocap_on``/``state_on`` off.
    """

    def __init__(self, runtime, script=None, legs: int = 0):
        super().__init__(daemon=True)
        self.endpoint = UdpEndpoint("127.0.0.1", 0)
        self.mocap_address = ("127.0.0.1", runtime.mocap.endpoint.port)
        self.state_address = ("127.0.0.1", runtime.link.endpoint.port)
        self.goal_address = ("127.0.0.1", runtime.goals.endpoint.port) if runtime.goals.endpoint else None
        self.script = script
        self.base = (np.array([-1.0, 0.0, 0.5]), np.array([0.0, 0.0, 0.0, 1.0]))
        self.object = (np.array([0.0, 0.0, 0.35]), np.array([0.0, 0.0, 0.0, 1.0]))
        self.state = robot_state(legs=legs)
        self.mocap_on = True
        self.state_on = True
        self.commands: list[RobotCommand] = []
        self.goal_seq = 0
        self.halt = threading.Event()

    def send_goal(self, x: float, y: float, yaw: float, kind: int = GOAL_SET) -> None:
        self.goal_seq += 1
        self.endpoint.send(encode_goal(GoalCommand(self.goal_seq, kind, x, y, yaw)), self.goal_address)

    def _answer(self, step: int) -> None:
        if self.script is not None:
            self.script(step, self)
        if self.mocap_on:
            bodies = [MocapBody("base", *self.base), MocapBody("object", *self.object)]
            self.endpoint.send(encode_mocap(MocapFrame(step, 0.0, bodies)), self.mocap_address)
        if self.state_on:
            self.state.seq = step
            self.endpoint.send(encode_state(self.state), self.state_address)

    def run(self) -> None:
        self._answer(0)
        while not self.halt.is_set():
            if self.endpoint.wait_readable(0.02):
                for datagram in self.endpoint.drain():
                    self.commands.append(decode_command(datagram.data))
                self._answer(len(self.commands))

    def close(self) -> None:
        self.halt.set()
        self.join(timeout=2.0)
        self.endpoint.close()


def lockstep_config(policy: Path, log_dir: Path, **sections) -> RuntimeConfig:
    """A lock-step runtime on ephemeral loopback ports; ``sections`` update the YAML-level dict."""
    data = {"push_policy": {"path": str(policy)}, "mocap": {"port": 0}, "robot": {"port": 0, "robot_address": ""},
            "goals": {"command_port": 0}, "rates": {"clock": "lockstep"}, "safety": {"arm_ramp_s": 0.1},
            "log": {"directory": str(log_dir)}}
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value}
    return config_from_dict(data)


def streaming_robot_code(mocap_port: int, state_port: int) -> str:
    """Python source (for a subprocess) of a daemon thread streaming mocap frames and robot state at 100 Hz."""
    return f"""
import threading, time
import numpy as np
from dynpush.runtime.packets import MocapBody, MocapFrame, Proprioception, encode_mocap, encode_state
from dynpush.runtime.udp import UdpEndpoint
def _stream():
    out, quat = UdpEndpoint("127.0.0.1", 0), np.array([0.0, 0.0, 0.0, 1.0])
    for seq in range(10**7):
        bodies = [MocapBody("base", np.array([-1.0, 0, 0.5]), quat), MocapBody("object", np.array([0.0, 0, 0.35]), quat)]
        out.send(encode_mocap(MocapFrame(seq, 0.0, bodies)), ("127.0.0.1", {mocap_port}))
        out.send(encode_state(Proprioception(seq, 0.0, quat, np.zeros(3), np.zeros(3), np.array([0.6, 0, 0.3]),
                 np.zeros(5), np.zeros(5), np.zeros(0), np.zeros(0))), ("127.0.0.1", {state_port}))
        time.sleep(0.01)
threading.Thread(target=_stream, daemon=True).start()
"""


def free_ports(count: int) -> list[int]:
    """``count`` loopback UDP ports that are free now, drawn from below the kernel's ephemeral range.

    A port closed here is bound again later by a runtime in another process; an ephemeral port could
    meanwhile be handed to any socket bound to port 0 (the streaming robot's own sender, CI neighbours),
    which made the runtime's startup fail with "address already in use" (seen once in CI)."""
    ephemeral_low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    rng = np.random.default_rng()
    ports: list[int] = []
    while len(ports) < count:
        port = int(rng.integers(1024, ephemeral_low))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
        if port not in ports:
            ports.append(port)
    return ports


def streaming_config(path: Path, policy: Path, log_dir: Path) -> tuple[Path, str]:
    """A real-time runtime YAML listening on free loopback ports, and the code of a robot streaming to them."""
    mocap_port, state_port = free_ports(2)
    path.write_text(json.dumps({  # JSON is YAML
        "push_policy": {"path": str(policy)}, "mocap": {"port": mocap_port},
        "robot": {"port": state_port, "robot_address": ""},
        "goals": {"command_port": None, "sequence": [{"x": 1.0, "y": 0.0}]}, "safety": {"arm_ramp_s": 0.1},
        "log": {"directory": str(log_dir)},
    }))
    return path, streaming_robot_code(mocap_port, state_port)


def run_with_robot(cfg, ticks: int, script=None) -> tuple[dict, FakeRobot, Runtime]:
    """Runs a lock-step runtime for ``ticks`` ticks against a :class:`FakeRobot` with ``script``."""
    runtime = Runtime(cfg)
    robot = FakeRobot(runtime, script)
    robot.start()
    try:
        summary = runtime.run(max_ticks=ticks)
    finally:
        robot.close()
    return summary, robot, runtime
