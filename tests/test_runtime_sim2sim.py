"""Sim-to-sim end to end: ``dynpush sim2sim`` with a tiny push policy (one Gemm layer, small random weights,
the contract of the real robot and training config) runs the deployment runtime against the Newton
simulator in a child process over loopback UDP, with mocap noise, latency and dropped frames."""

import json

import numpy as np
import pytest

from dynpush.cli import main
from dynpush.runtime.config import RuntimeConfigError
from dynpush.runtime.safety import State
from dynpush.runtime.sim2sim import SimToSimOptions, run_sim2sim, runtime_config
from dynpush.runtime.tick_log import read_log
from test_runtime_helpers import write_policy


@pytest.fixture(scope="module")
def robot_policy(tmp_path_factory):
    """A tiny policy with the contract ``dynpush export`` writes (robot from robot.usda, cpu preset)."""
    from dynpush.policies.export import build_contract
    from dynpush.policies.train import TrainConfig

    bias = np.zeros(11)
    bias[0] = 0.3  # walk forward at about 0.3 m/s
    return write_policy(tmp_path_factory.mktemp("sim2sim") / "tiny.onnx", build_contract(TrainConfig.preset_config("cpu")),
                        bias=bias)


def test_sim2sim_end_to_end(robot_policy, tmp_path):
    config = tmp_path / "runtime.yaml"
    config.write_text(json.dumps({"safety": {"arm_ramp_s": 0.2}, "push_policy": {"path": "replaced.onnx"}}))
    out = tmp_path / "report.json"
    status = main(["sim2sim", str(robot_policy), "--episodes", "1", "--lockstep", "--config", str(config),
                   "--mocap-noise", "0.002", "--mocap-noise-rad", "0.005", "--latency", "0.02", "--drop", "0.1",
                   "--set", "env.episode_length_s=1.0", "--log-dir", str(tmp_path / "logs"), "--out", str(out)])
    report = json.loads(out.read_text())
    assert status == 0 and report["completed"] and report["simulator_exit_code"] == 0
    assert report["timing"] == "lockstep" and report["realtime_check"] is None
    assert report["episodes"] == 1 and report["success_rate"] in (0.0, 1.0)
    assert report["episode_results"][0]["steps"] == 50, "1 s episode at 50 Hz"
    runtime = report["runtime"]
    assert runtime["states"]["PUSH"] >= 45 and runtime["goal_commands"]["accepted"] == 1
    for stream in ("robot_link", "mocap", "goal_commands"):
        assert runtime[stream]["malformed"] == runtime[stream]["foreign"] == runtime[stream]["replayed"] == 0, stream
    sent = runtime["robot_link"]["states"]  # one state and, unless dropped, one mocap frame per simulator step
    assert 0.75 * sent <= runtime["mocap"]["frames"] <= 0.97 * sent, "about 10 % of the mocap frames dropped"

    log = read_log(runtime["log"])
    push = log.column("state")[:, 0] == State.PUSH
    base = log.column("base_position")[push]
    assert np.linalg.norm(base[-1, :2] - base[0, :2]) > 0.08, "the base command moved the simulated robot"
    actions = np.clip(log.column("actions")[push], -10.0, 10.0)
    expected = np.array([0, 0, 0, 0, 0, 0.5]) + np.array([1.0, 0.6, 1.0, 0.2, 0.2, 0.1]) * actions[:, :6]
    np.testing.assert_allclose(log.column("base_command")[push], expected, atol=1e-6)
    assert np.isfinite(log.column("obs")[push]).all()


def test_sim2sim_ends_when_the_runtime_stops(robot_policy, tmp_path):
    config = tmp_path / "runtime.yaml"
    config.write_text(json.dumps({"robot": {"timeout_s": 1e-7}}))  # any robot state is "stale": STOPPED at once
    report = run_sim2sim(SimToSimOptions(policy=str(robot_policy), episodes=3, lockstep=True, config=str(config),
                                         log_dir=str(tmp_path)))
    assert not report["completed"] and report["episodes"] == 0 and report["simulator"]["runtime_stopped"]
    assert report["runtime"]["final_state"] == "STOPPED" and "robot state stale" in report["runtime"]["final_reason"]


def test_sim2sim_wiring_replaces_the_config(robot_policy, tmp_path):
    config = tmp_path / "runtime.yaml"
    config.write_text(json.dumps({"mocap": {"source": "vicon", "timeout_s": 0.3}, "goals": {"sequence": [{"x": 1.0}]},
                                  "robot": {"bind_address": "192.168.1.5", "allowed_senders": ["192.168.1.20"]}}))
    cfg = runtime_config(SimToSimOptions(policy=str(robot_policy), config=str(config), lockstep=True))
    assert cfg.mocap.source == "udp" and cfg.mocap.port == 0 and cfg.mocap.timeout_s == 0.3
    assert cfg.robot.bind_address == "127.0.0.1" and cfg.robot.allowed_senders == ["127.0.0.1"], "the simulator's link"
    assert cfg.goals.sequence == [] and cfg.goals.command_port == 0 and cfg.rates.clock == "lockstep"
    assert cfg.robot.robot_address == "" and cfg.push_policy.path == str(robot_policy.resolve())
    legs = [f"{leg}_{joint}" for leg in ("LF", "RF", "LH", "RH") for joint in ("HAA", "HFE", "KFE")]
    config.write_text(json.dumps({
        "locomotion": {"mode": "onnx", "onnx": {"path": "loco.onnx", "observation": [{"name": "base_command"}],
                                                "joint_names": legs, "default_joint_positions": [0.0] * 12}},
        "robot": {"leg_joint_names": legs}, "safety": {"leg_joint_lower": [-1.0] * 12, "leg_joint_upper": [1.0] * 12}}))
    with pytest.raises(RuntimeConfigError, match="locomotion.mode must be 'onboard' in a sim2sim config"):
        runtime_config(SimToSimOptions(policy=str(robot_policy), config=str(config)))
    with pytest.raises(RuntimeConfigError, match=r"drop must lie in \[0, 1\)"):
        SimToSimOptions(policy="p.onnx", drop=1.0).validate()


@pytest.mark.slow
def test_sim2sim_real_time(robot_policy, tmp_path):
    """The default clock: simulator and runtime each on their own 50 Hz deadlines."""
    report = run_sim2sim(SimToSimOptions(policy=str(robot_policy), episodes=2, overrides=["env.episode_length_s=2.0"],
                                         latency_s=0.02, drop=0.05, log_dir=str(tmp_path)))
    assert report["completed"] and report["episodes"] == 2 and report["conditions"]["clock"] == "realtime"
    assert report["timing"] == "realtime" and report["realtime_check"]["slowest_window_rate"] >= 0.9
    assert report["realtime_check"]["periods"] >= 200, "the simulator's clock reports cover the run"
    runtime = report["runtime"]
    assert runtime["states"]["PUSH"] >= 150
    assert runtime["timing"]["lateness"]["p50_ms"] < 5.0
