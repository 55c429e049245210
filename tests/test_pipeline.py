"""The whole pipeline in CI size: train (CLI) -> export (CLI) -> deployment runtime against the simulator."""

import json

from dynpush.cli import main


def test_train_export_and_run_the_policy_in_sim2sim(tmp_path):
    runs = tmp_path / "runs"
    assert main(["train", "--runs", str(runs), "--name", "tiny", "--set", "env.num_envs=8", "iterations=2",
                 "num_steps_per_env=8", "network.actor_hidden=(32, 32)", "network.critic_hidden=(32, 32)"]) == 0
    assert main(["export", str(runs / "tiny")]) == 0
    policy = runs / "tiny" / "policy.onnx"
    config = tmp_path / "runtime.yaml"
    config.write_text(json.dumps({"safety": {"arm_ramp_s": 0.2}}))
    report_path = tmp_path / "sim2sim.json"
    assert main(["sim2sim", str(policy), "--episodes", "1", "--lockstep", "--config", str(config),
                 "--set", "env.episode_length_s=1.0", "--log-dir", str(tmp_path / "logs"), "--out", str(report_path)]) == 0
    report = json.loads(report_path.read_text())
    assert report["completed"] and report["simulator_exit_code"] == 0 and report["episodes"] == 1
    runtime = report["runtime"]
    assert runtime["states"].get("PUSH", 0) >= 40  # the trained policy drove the simulated robot
    assert runtime["robot_link"]["malformed"] == 0 and runtime["mocap"]["malformed"] == 0
