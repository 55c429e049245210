"""The chain beside the simulation: a sim-to-sim record (``--record``) read back, the runtime's observations against the
kernels' of the same states, and the recorded episodes run again in simulation from their start states."""

import json

import numpy as np
import pytest

from dynpush.policies.chain_record import ChainRecordError, read_record
from dynpush.policies.chain_replay import compare_observations, path_divergence, replay_in_simulation, safety_clamps
from dynpush.runtime.config import RuntimeConfigError
from dynpush.runtime.sim2sim import SimToSimOptions, run_sim2sim
from dynpush.runtime.contract import PolicyContract
from dynpush.runtime.safety import State
from dynpush.runtime.tick_log import TickLog, read_log
from test_runtime_helpers import write_policy


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two 1 s episodes of a tiny policy (walks forward, small random arm motions) through the runtime, recorded."""
    from dynpush.policies.export import build_contract
    from dynpush.policies.train import TrainConfig

    folder = tmp_path_factory.mktemp("chain")
    bias = np.zeros(11)
    bias[0] = 0.3
    policy = write_policy(folder / "tiny.onnx", build_contract(TrainConfig.preset_config("cpu")), bias=bias)
    config = folder / "runtime.yaml"
    config.write_text(json.dumps({"safety": {"arm_ramp_s": 0.2}, "push_policy": {"path": "replaced.onnx"}}))
    report = run_sim2sim(SimToSimOptions(policy=str(policy), episodes=2, lockstep=True, seed=3, config=str(config),
                                         overrides=["env.episode_length_s=1.0"], log_dir=str(folder / "logs"),
                                         record=str(folder / "record.npz")))
    assert report["completed"]
    return policy, report, read_record(folder / "record.npz")


def test_the_record_holds_every_step_and_each_episode_start(recorded):
    _, report, record = recorded
    rows = record.rows
    assert len(record.starts) == 2 and report["simulator"]["steps"] == len(rows["step"])
    assert np.array_equal(rows["step"], np.arange(len(rows["step"])))
    assert [int((rows["episode"] == i).sum()) for i in (0, 1)] == [50, 50], "two 1 s episodes at 50 Hz"
    assert rows["policy_obs"].shape == (len(rows["step"]), 54) and "locomotion_obs" not in rows, "tracked base"
    assert json.loads(str(rows["meta"]))["seed"] == 3


def test_the_runtime_observes_what_the_kernels_observe(recorded):
    _, report, record = recorded
    compared = compare_observations(record, read_log(report["runtime"]["log"]))
    assert compared["alignment_error_m"] < 1e-6, "tick k acted on the state recorded before step k"
    assert compared["ticks_compared"] >= 95
    push = compared["push_observation"]
    for term, difference in push.items():
        if term != "last_actions":  # the simulator's commands carry no actions; the runtime keeps its own
            assert difference["max"] < 1e-4, term
    assert push["last_actions"]["max"] > 0.01, "the runtime's own action history is there to be told apart"


def test_the_recorded_episodes_run_again_in_simulation(recorded):
    policy, report, record = recorded
    episodes = replay_in_simulation(record, str(policy), None, read_log(report["runtime"]["log"]))
    assert len(episodes) == 2
    for i, episode in enumerate(episodes):
        chain = report["episode_results"][i]
        assert episode["steps"] == chain["steps"] == 50
        assert (episode["success"], episode["toppled"], episode["fallen"]) == (chain["success"], chain["toppled"], False)
        divergence = path_divergence(record.episode_rows("base_pose", i)[:, :3], episode["base_position"])
        assert divergence["common_steps"] == 50
        # Same start state, action history and commands: the paths agree to float32 precision.
        assert divergence["max_m"] < 1e-4, divergence
    moved = episodes[0]["base_position"][-1, :2] - episodes[0]["base_position"][0, :2]
    assert np.linalg.norm(moved) > 0.08, "the policy walked; the paths compared are not two robots standing still"


def test_the_recorded_run_was_not_clamped_and_a_clamped_tick_is_counted(recorded):
    policy, report, _ = recorded
    from dynpush.policies.onnx_policy import OnnxPolicy

    contract: PolicyContract = OnnxPolicy(policy).contract
    log = read_log(report["runtime"]["log"])
    assert safety_clamps(log, contract) == {"base_command": 0.0, "arm_targets": 0.0}, "0.3 m/s and small arm motions"
    mapping = contract.action_mapping()
    actions = np.zeros((4, 11))
    actions[1, 0] = 2.0 / mapping.base.scale[0]  # asks for 2 m/s forward, beyond the 1 m/s limit
    base, arm = mapping.commands(mapping.clipped(actions))
    sent = base.copy()
    sent[1, 0] = 1.0  # what the safety layer sent
    state = np.array([[State.PUSH], [State.PUSH], [State.PUSH], [State.HOLD]], dtype=float)
    synthetic = TickLog(meta={}, columns={"state": state, "actions": actions, "base_command": sent, "arm_targets": arm},
                        records=4, partial_bytes=0)
    assert safety_clamps(synthetic, contract) == {"base_command": 1 / 3, "arm_targets": 0.0}


def test_a_file_that_is_no_record_is_refused_in_one_line(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, step=np.arange(3))
    with pytest.raises(ChainRecordError, match="not a sim-to-sim record .lacks"):
        read_record(path)
    path.write_bytes(b"not a zip")
    with pytest.raises(ChainRecordError, match="not a sim-to-sim record"):
        read_record(path)
    with pytest.raises(RuntimeConfigError, match="record: folder .* does not exist"):
        SimToSimOptions(policy="p.onnx", record=str(tmp_path / "missing" / "r.npz")).validate()
