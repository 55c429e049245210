"""Per-tick compute time of the deployment runtime on one CPU core: p50/p99/max, printed as JSON.

Measures the controller's tick in its heaviest configuration, a PUSH tick with a locomotion ONNX
(``configs/runtime_optitrack_onnx.yaml``: 56 inputs), split into its stages:

- ``observation``: the 54-d push observation (``runtime/observation.py``) from poses and robot state
- ``push_onnx``: the push policy, the cpu preset's actor size (54-256-128-64-11, ELU, normaliser in the graph)
- ``locomotion_onnx``: locomotion observation assembly + a 512-256-128 ELU network (the paper's usual size)
- ``controller_tick``: the whole ``Controller.step`` (the three above + safety, commands, clamping, log record)
- ``log_write``: appending the tick's record to the tick log

Networks have random weights (built with ``onnx.helper``); timings do not depend on the values. The
process is pinned to one core (``--cpu``) and onnxruntime runs with one thread, no spinning. Every
stage is timed twice, on alternate ticks: ``wall`` (``time.perf_counter``, what the loop sees,
including preemption by other processes on a shared core) and ``cpu`` (``time.thread_time``, the
compute itself).

    python benchmarks/runtime_latency.py [--ticks 5000] [--cpu 0]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import onnx
import onnxruntime
from onnx import TensorProto, helper, numpy_helper

from dynpush.assets_usd import ARM_JOINT_NAMES
from dynpush.runtime.config import load_config
from dynpush.runtime.contract import PolicyContract
from dynpush.runtime.controller import Controller
from dynpush.runtime.frames import Pose
from dynpush.runtime.goals import Goal
from dynpush.runtime.locomotion import OnnxLocomotion
from dynpush.runtime.mocap import TrackedPose
from dynpush.runtime.packets import Proprioception
from dynpush.runtime.policy import load_push_policy
from dynpush.runtime.robot_link import ReceivedState
from dynpush.runtime.safety import State
from dynpush.runtime.tick_log import TickLogWriter
from dynpush.runtime.timing import TickTiming

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "runtime_optitrack_onnx.yaml"


def mlp(path: Path, sizes: list[int], normaliser: bool, metadata: dict[str, str], rng: np.random.Generator) -> Path:
    """ELU MLP ``obs [1, sizes[0]] -> actions [1, sizes[-1]]``, optionally ``(x - mean) / std`` first."""
    nodes, weights, x = [], [], "obs"
    if normaliser:
        weights += [numpy_helper.from_array(rng.normal(size=sizes[0]).astype(np.float32), "mean"),
                    numpy_helper.from_array(rng.uniform(0.5, 2.0, sizes[0]).astype(np.float32), "std")]
        nodes += [helper.make_node("Sub", [x, "mean"], ["centred"]), helper.make_node("Div", ["centred", "std"], ["x0"])]
        x = "x0"
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        weights += [numpy_helper.from_array((rng.normal(size=(n_in, n_out)) / np.sqrt(n_in)).astype(np.float32), f"W{i}"),
                    numpy_helper.from_array(np.zeros(n_out, np.float32), f"B{i}")]
        last = i == len(sizes) - 2
        nodes.append(helper.make_node("Gemm", [x, f"W{i}", f"B{i}"], ["actions" if last else f"z{i}"]))
        if not last:
            nodes.append(helper.make_node("Elu", [f"z{i}"], [f"h{i}"]))
            x = f"h{i}"
    graph = helper.make_graph(nodes, "mlp", [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, sizes[0]])],
                              [helper.make_tensor_value_info("actions", TensorProto.FLOAT, [1, sizes[-1]])], weights)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    helper.set_model_props(model, metadata)
    onnx.save(model, str(path))
    return path


def benchmark_contract() -> PolicyContract:
    return PolicyContract(
        base_command_default=[0.0, 0.0, 0.0, 0.0, 0.0, 0.5], base_command_scale=[1.0, 0.6, 1.0, 0.2, 0.2, 0.1],
        base_command_lower=[-1.0, -0.6, -1.0, -0.2, -0.2, 0.4], base_command_upper=[1.0, 0.6, 1.0, 0.2, 0.2, 0.6],
        arm_joint_names=list(ARM_JOINT_NAMES[:5]), arm_default_joint_positions=[0.0] * 5, arm_action_scale=0.5,
        arm_joint_lower=[-3.0] * 5, arm_joint_upper=[3.0] * 5, arm_joint_velocity_limit=[3.0] * 5,
        frozen_joint_name=ARM_JOINT_NAMES[5], action_clip=10.0,
    )


def percentiles(samples: list[float]) -> dict[str, float]:
    us = 1e6 * np.asarray(samples)
    return {"p50_us": float(np.percentile(us, 50)), "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max())}


def timed(clock, stages: dict[str, list[float]], name: str, function, *args):
    """``function(*args)``, appending its duration on ``clock`` to ``stages[name]``."""
    start = clock()
    result = function(*args)
    stages[name].append(clock() - start)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--ticks", type=int, default=5000)
    parser.add_argument("--cpu", type=int, default=0, help="core to pin the process to")
    args = parser.parse_args()
    os.sched_setaffinity(0, {args.cpu})
    rng = np.random.default_rng(0)
    folder = Path(tempfile.mkdtemp(prefix="dynpush-latency-"))
    cfg = load_config(CONFIG)
    cfg.push_policy.path = str(mlp(folder / "push.onnx", [54, 256, 128, 64, 11], True, benchmark_contract().to_metadata(), rng))
    loco_inputs = cfg.locomotion.onnx.observation_size
    cfg.locomotion.onnx.path = str(mlp(folder / "loco.onnx", [loco_inputs, 512, 256, 128, 12], False, {}, rng))
    cfg.safety.arm_ramp_s = 0.02
    cfg.goals.sequence = []
    push, contract = load_push_policy(cfg)
    locomotion = OnnxLocomotion(cfg.locomotion.onnx, contract)
    controller = Controller(cfg, contract, push, locomotion)
    writer = TickLogWriter(folder / "bench.dplog", controller.layout, {}, cfg.rates.log_flush_s)

    unit = lambda q: np.asarray(q) / np.linalg.norm(q)  # noqa: E731
    base_pose = Pose(np.array([-1.0, 0.2, 0.5]), unit([0.02, -0.01, 0.3, 0.95]))
    object_pose = Pose(np.array([0.0, 0.0, 0.35]), unit([0.0, 0.0, 0.1, 0.995]))
    state = Proprioception(0, 0.0, base_pose.quat_xyzw, rng.normal(size=3), rng.normal(size=3), np.array([0.6, 0.0, 0.3]),
                           rng.normal(size=5), rng.normal(size=5), rng.normal(size=12), rng.normal(size=12))
    goal = Goal(1.5, 0.5, 0.7)
    names = ("observation", "push_onnx", "locomotion_onnx", "controller_tick", "log_write")
    clocks = {"wall": time.perf_counter, "cpu": time.thread_time}  # cpu: this thread's CPU time, immune to preemption
    stages = {clock: {name: [] for name in names} for clock in clocks}
    warmup = 200
    for k in range(warmup + args.ticks):
        t = 0.02 * k
        base, obj, robot = TrackedPose(base_pose, t), TrackedPose(object_pose, t), ReceivedState(state, t)
        timing = TickTiming(index=k, deadline=t, start=t, lateness=0.0, skipped=0)
        which = "wall" if k % 2 else "cpu"
        samples = stages[which] if k >= warmup else {name: [] for name in names}
        clock = clocks[which]
        command = timed(clock, samples, "controller_tick", controller.step, timing, base, obj, robot, goal, False)
        if k >= warmup and command.state != State.PUSH:
            raise RuntimeError(f"benchmark tick not in PUSH (state {State(command.state).name})")
        timed(clock, samples, "log_write", writer.write, controller.record)
        timed(clock, samples, "observation", controller.observe, base, obj, robot, goal)
        timed(clock, samples, "push_onnx", push.run)
        timed(clock, samples, "locomotion_onnx", locomotion.step, state, command.base_command)
    writer.close()
    result = {
        "ticks": args.ticks, "cpu": args.cpu, "processor": platform.processor() or platform.machine(),
        "load_average": os.getloadavg(), "onnxruntime": onnxruntime.__version__,
        "networks": {"push": [54, 256, 128, 64, 11], "locomotion": [loco_inputs, 512, 256, 128, 12]},
        **{clock: {name: percentiles(samples) for name, samples in by_name.items()} for clock, by_name in stages.items()},
        "target": "controller_tick p99 < 1000 us",
    }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
