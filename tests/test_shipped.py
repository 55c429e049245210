"""The shipped policy (dynpush/shipped) belongs to its records, and ``dynpush demo`` runs it offline."""

import json
import subprocess
import sys

from dynpush.policies.onnx_policy import OnnxPolicy
from dynpush.shipped import SHIPPED_DIR, shipped_file, training_record


def test_shipped_files_belong_together():
    record = training_record()
    policy = OnnxPolicy(shipped_file("policy.onnx"))
    config_text = shipped_file("training_config.json").read_text()
    assert policy.contract.training_config == json.loads(config_text)
    assert policy.contract.training_config_sha256 == record["training_config_sha256"]
    evaluation = json.loads(shipped_file("eval.json").read_text())
    assert evaluation["config"]["training_config_sha256"] == record["training_config_sha256"]
    assert evaluation["success_rate"] == record["evaluation"]["success_percent"]
    assert evaluation["episodes"] == record["evaluation"]["episodes"]
    assert record["commands"] and all(c.startswith(("dynpush train", "dynpush imitate")) for c in record["commands"])
    assert record["launches"][0]["commit"]
    assert record["checkpoint"].startswith("model_") or (record["checkpoint"] == "imitation.pt" and record["imitation"]["rounds"] > 0)
    for name in ("eval.png", "learning_curve.png"):
        assert shipped_file(name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (SHIPPED_DIR / "policy.onnx.data").exists()


def test_demo_runs_the_shipped_policy_through_the_runtime(tmp_path):
    out = tmp_path / "demo"
    done = subprocess.run([sys.executable, "-m", "dynpush", "demo", "--episodes", "2", "--lockstep", "--out", str(out),
                           "--set", "env.episode_length_s=1.0"], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split(":")[0] for line in lines[:2]] == ["episode 0", "episode 1"]
    assert lines[2] in ("success 0 % of 2 episodes", "success 50 % of 2 episodes", "success 100 % of 2 episodes")
    report = json.loads((out / "demo.json").read_text())
    assert report["completed"] and report["episodes"] == 2
    assert report["runtime"]["states"].get("PUSH", 0) > 0  # the runtime drove the simulated robot
    assert (out / "demo.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert list(out.glob("*.dplog"))  # the runtime's tick log


def test_shipped_locomotion_files_belong_together():
    from dynpush.sim.legged_push_env import LocomotionNetwork

    record = training_record("locomotion")
    network = LocomotionNetwork(str(shipped_file("locomotion/locomotion.onnx")))
    training_config = json.loads(shipped_file("locomotion/training_config.json").read_text())
    assert network.contract.values["training_config"] == training_config
    evaluation = json.loads(shipped_file("locomotion/locomotion_eval.json").read_text())
    assert record["evaluation"]["tracking_rms"] == evaluation["tracking_rms"]
    assert record["evaluation"]["fell_percent"] == evaluation["fell_percent"]
    assert record["commands"] and all(c.startswith("dynpush train --task locomotion") for c in record["commands"])
    assert record["launches"][0]["commit"] and record["checkpoint"].startswith("model_")
    for name in ("locomotion_eval.png", "learning_curve.png"):
        assert shipped_file(f"locomotion/{name}").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_demo_runs_both_shipped_policies_on_the_legged_robot(tmp_path):
    """``dynpush demo --locomotion onnx``: the runtime runs the shipped push and locomotion policies and sends the 17
    joint targets to the legged simulator (offline, no path given)."""
    out = tmp_path / "demo"
    done = subprocess.run([sys.executable, "-m", "dynpush", "demo", "--episodes", "1", "--lockstep", "--out", str(out),
                           "--locomotion", "onnx", "--set", "env.episode_length_s=1.0"], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "legged robot, locomotion" in done.stderr
    report = json.loads((out / "demo.json").read_text())
    assert report["completed"] and report["conditions"]["locomotion"] == str(shipped_file("locomotion/locomotion.onnx"))
    assert report["runtime"]["states"].get("PUSH", 0) > 0
