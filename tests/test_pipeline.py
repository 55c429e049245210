"""The whole pipeline in CI size: train (CLI) -> export (CLI) -> deployment runtime against the simulator,
and shipping a run (export + evaluation + learning curve + provenance)."""

import json

from dynpush.cli import main


def test_train_export_and_run_the_policy_in_sim2sim(tmp_path):
    runs = tmp_path / "runs"
    assert main(["train", "--runs", str(runs), "--name", "tiny", "--set", "env.num_envs=8", "iterations=2",
                 "num_steps_per_env=8", "network.actor_hidden=(32, 32)", "network.critic_hidden=(32, 32)"]) == 0
    launches = [json.loads(line) for line in (runs / "tiny" / "launches.jsonl").read_text().splitlines()]
    assert len(launches) == 1 and launches[0]["command"].startswith(f"dynpush train --runs {runs} --name tiny --set")
    assert main(["export", str(runs / "tiny")]) == 0
    policy = runs / "tiny" / "policy.onnx"
    assert not (runs / "tiny" / "policy.onnx.data").exists()  # one self-contained file
    config = tmp_path / "runtime.yaml"
    config.write_text(json.dumps({"safety": {"arm_ramp_s": 0.2}}))
    report_path = tmp_path / "sim2sim.json"
    assert main(["sim2sim", str(policy), "--episodes", "1", "--lockstep", "--config", str(config),
                 "--set", "env.episode_length_s=1.0", "--log-dir", str(tmp_path / "logs"), "--out", str(report_path),
                 "--png", str(tmp_path / "paths.png")]) == 0
    report = json.loads(report_path.read_text())
    assert report["completed"] and report["simulator_exit_code"] == 0 and report["episodes"] == 1
    assert report["trajectory_png"] == str(tmp_path / "paths.png") and (tmp_path / "paths.png").stat().st_size > 10_000
    episode = report["episode_results"][0]
    assert episode["shape"] in ("cuboid", "cylinder") and episode["length_s"] == 1.0 and len(episode["goal"]) == 3
    runtime = report["runtime"]
    assert runtime["states"].get("PUSH", 0) >= 40  # the trained policy drove the simulated robot
    assert runtime["robot_link"]["malformed"] == 0 and runtime["mocap"]["malformed"] == 0


def test_ship_writes_a_consistent_shipment(tmp_path):
    from dynpush.policies.onnx_policy import OnnxPolicy
    from dynpush.policies.ship import ship

    runs = tmp_path / "runs"
    assert main(["train", "--runs", str(runs), "--name", "tiny", "--set", "env.num_envs=8", "iterations=3",
                 "num_steps_per_env=8", "save_interval=2", "network.actor_hidden=(32,)", "network.critic_hidden=(32,)"]) == 0
    out = tmp_path / "shipped"
    record = ship(runs / "tiny", out, checkpoint="model_2.pt", episodes=8)
    assert sorted(p.name for p in out.iterdir()) == ["eval.json", "eval.png", "learning_curve.png", "policy.onnx",
                                                    "training.json", "training_config.json"]
    assert record == json.loads((out / "training.json").read_text())
    assert record["commands"] == [json.loads((runs / "tiny" / "launches.jsonl").read_text())["command"]]
    assert record["iterations"] == 3 and record["world_steps"] == 3 * 8 * 8 and record["training_wall_clock_h"] > 0
    evaluation = json.loads((out / "eval.json").read_text())
    assert record["evaluation"]["success_percent"] == evaluation["success_rate"] and evaluation["episodes"] == 8
    assert OnnxPolicy(out / "policy.onnx").contract.training_config_sha256 == record["training_config_sha256"]
    assert json.loads((out / "training_config.json").read_text()) == json.loads((runs / "tiny" / "config.json").read_text())
