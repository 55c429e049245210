"""dynpush export: ONNX parity with the torch actor, graph checks, metadata contract, loader errors, warp-nn."""

import json
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from tensordict import TensorDict

from dynpush.assets_usd import ARM_JOINT_NAMES
from dynpush.cli import main
from dynpush.policies.actor import load_actor
from dynpush.policies.export import build_contract, config_sha256, export_policy
from dynpush.policies.onnx_policy import OnnxPolicy
from dynpush.policies.tasks import load_run_config
from dynpush.policies.train import TrainConfig, apply_overrides, train
from dynpush.runtime.contract import ContractError, PolicyContract
from dynpush.sim.onnx_session import read_metadata


def tiny_run(run_dir):
    """A run trained for one iteration on 8 worlds with tiny networks (the normaliser has seen data)."""
    cfg = apply_overrides(TrainConfig.preset_config("cpu"), [
        "env.num_envs=8", "iterations=1", "num_steps_per_env=6", "save_interval=1",
        "network.actor_hidden=(32, 16)", "network.critic_hidden=(16, 16)"])
    torch.manual_seed(0)
    train(cfg, run_dir)
    return run_dir


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    run = tiny_run(tmp_path_factory.mktemp("run"))
    return run, export_policy(run)


def observations(actor, count: int, seed: int) -> np.ndarray:
    """Random observations around the normaliser's statistics, plus uniform ones in [-3, 3]."""
    rng = np.random.default_rng(seed)
    mean = actor.obs_normalizer.mean.numpy()
    std = actor.obs_normalizer.std.numpy()
    around = mean + std * rng.standard_normal((count, mean.size))
    uniform = rng.uniform(-3.0, 3.0, (count, mean.size))
    return np.concatenate([around, uniform]).astype(np.float32)


def torch_actions(actor, obs: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return actor(TensorDict({"policy": torch.from_numpy(obs)}, batch_size=[len(obs)])).numpy()


def test_onnx_equals_torch_actor_with_normaliser(exported):
    run, path = exported
    actor = load_actor(run / "model_0.pt", load_run_config(run))
    assert int(actor.obs_normalizer.count) > 0, "the tiny run's normaliser must have been updated"
    obs = observations(actor, 32, seed=1)
    expected = torch_actions(actor, obs)
    single = OnnxPolicy(path)
    batched = OnnxPolicy(path, batched=True)
    one_by_one = np.concatenate([single(o[None]) for o in obs])
    assert np.abs(one_by_one - expected).max() < 1e-5
    assert np.abs(batched(obs) - expected).max() < 1e-5
    assert np.array_equal(single(obs[:1]), single(obs[:1]))  # deterministic mean, no sampling


def test_graph_passes_checker_with_contract_shapes(exported):
    _, path = exported
    model = onnx.load(str(path))
    onnx.checker.check_model(model, full_check=True)
    opset = next(o.version for o in model.opset_import if o.domain in ("", "ai.onnx"))
    assert opset >= 17
    dims = lambda v: [d.dim_value for d in v.type.tensor_type.shape.dim]  # noqa: E731
    assert [(v.name, dims(v)) for v in model.graph.input] == [("obs", [1, 54])]
    assert [(v.name, dims(v)) for v in model.graph.output] == [("actions", [1, 11])]
    ops = {node.op_type for node in model.graph.node}
    assert {"Sub", "Div"} <= ops  # the empirical normaliser is in the graph
    assert not any("Random" in op for op in ops)


def test_metadata_round_trips_through_the_contract(exported):
    run, path = exported
    contract = PolicyContract.from_metadata(read_metadata(onnx.load(str(path))))
    cfg = load_run_config(run)
    assert contract == build_contract(cfg)
    assert contract.arm_joint_names == list(ARM_JOINT_NAMES[:5]) and contract.frozen_joint_name == "WRIST_2"
    assert contract.training_config == json.loads((run / "config.json").read_text())
    assert contract.training_config_sha256 == config_sha256(contract.training_config)
    assert TrainConfig.from_dict(contract.training_config) == cfg
    assert contract.action_clip == cfg.env.actions.clip and contract.control_period_s == cfg.env.control_dt
    assert contract.observation_noise["base_angular_velocity_b"] == cfg.env.noise.base_angular_velocity_b
    lower, upper = np.array(contract.arm_joint_lower), np.array(contract.arm_joint_upper)
    assert np.all(lower < np.array(contract.arm_default_joint_positions)) and np.all(lower < upper)


def test_loader_rejects_wrong_inputs_and_foreign_files(exported, tmp_path):
    _, path = exported
    policy = OnnxPolicy(path)
    with pytest.raises(ValueError, match=r"'obs' must have shape \[1, 54\].*got \[1, 50\]"):
        policy(np.zeros((1, 50), np.float32))
    with pytest.raises(ValueError, match=r"got \[4, 54\]"):
        policy(np.zeros((4, 54), np.float32))
    with pytest.raises(ValueError, match="float32"):
        policy(np.zeros((1, 54)))
    assert OnnxPolicy(path, batched=True)(np.zeros((7, 54), np.float32)).shape == (7, 11)
    model = onnx.load(str(path))
    del model.metadata_props[:]
    onnx.save(model, str(tmp_path / "bare.onnx"))
    with pytest.raises(ContractError, match="observation_layout"):
        OnnxPolicy(tmp_path / "bare.onnx")


def test_cli_export_of_a_chosen_checkpoint(exported, tmp_path):
    run, _ = exported
    out = tmp_path / "chosen.onnx"
    assert main(["export", str(run), "--checkpoint", "model_0.pt", "--out", str(out)]) == 0
    assert read_metadata(onnx.load(str(out)))["checkpoint"] == "model_0.pt"
    with pytest.raises(FileNotFoundError, match="model_7.pt"):
        export_policy(run, "model_7.pt", tmp_path / "missing.onnx")


CAMPAIGNS = sorted(path.parent for path in (Path(__file__).resolve().parent.parent / "campaigns").glob("*/config.json"))


def test_the_project_long_run_is_committed():
    assert CAMPAIGNS, "campaigns/ holds no run: the project's long run lives in the repository"


@pytest.mark.parametrize("run", CAMPAIGNS, ids=[run.name for run in CAMPAIGNS])
def test_the_committed_long_runs_load_and_export_from_their_checkpoints(run, tmp_path):
    """The long runs in campaigns/ resume from their latest checkpoints in later sittings: those files keep loading
    into today's actor and exporting, whatever the code around it becomes."""
    checkpoint = max(run.glob("model_*.pt"), key=lambda path: int(path.stem.split("_")[1]))
    out = tmp_path / f"{run.name}.onnx"
    assert main(["export", str(run), "--checkpoint", checkpoint.name, "--out", str(out)]) == 0
    actor = load_actor(checkpoint, load_run_config(run))
    obs = observations(actor, 8, seed=3)
    np.testing.assert_allclose(OnnxPolicy(out, batched=True)(obs), torch_actions(actor, obs), atol=1e-5)


@pytest.mark.parametrize("run", CAMPAIGNS, ids=[run.name for run in CAMPAIGNS])
def test_the_committed_long_runs_resume_their_episodes(run):
    """The environment state in a committed run's latest checkpoint (the first process's) fits today's environment
    of the run's config: ``--resume`` continues its episodes instead of starting fresh ones."""
    from dynpush.policies.checkpoint_file import read_checkpoint
    from dynpush.sim.envs import make_push_env

    checkpoint = max(run.glob("model_*.pt"), key=lambda path: int(path.stem.split("_")[1]))
    state = read_checkpoint(checkpoint)["infos"]["env_state"]
    cfg = TrainConfig.from_dict(json.loads((run / "config.json").read_text()))
    cfg.env.num_envs = len(state["task.goal_pos"])
    assert make_push_env(cfg.env).state_mismatch(state) is None


def test_the_same_file_runs_in_warp_nn(exported):
    """warp-nn is the ONNX runtime of Newton's examples (``pip install newton[onnx]``)."""
    pytest.importorskip("warp_nn")
    import warp as wp
    from warp_nn.runtime import OnnxRuntime

    run, path = exported
    actor = load_actor(run / "model_0.pt", load_run_config(run))
    obs = observations(actor, 4, seed=2)
    runtime = OnnxRuntime(str(path), device="cpu")
    for o in obs:
        actions = runtime({"obs": wp.array(o[None], dtype=wp.float32, device="cpu")})["actions"].numpy()
        assert np.abs(actions - torch_actions(actor, o[None])).max() < 1e-5


def test_an_exported_actor_loads_back_into_a_new_actor(exported):
    from dynpush.policies.actor import build_actor, load_onnx_actor

    run, path = exported
    cfg = load_run_config(run)
    source = load_actor(run / "model_0.pt", cfg)
    actor = build_actor(cfg).eval()
    load_onnx_actor(actor, path)
    obs = observations(source, 32, seed=2)
    np.testing.assert_allclose(torch_actions(actor, obs), torch_actions(source, obs), atol=1e-5)
    np.testing.assert_allclose(actor.obs_normalizer._var.numpy(), source.obs_normalizer._var.numpy(), rtol=1e-4, atol=1e-6)
    # no sample count in the file: the statistics count as the samples of the run that wrote it
    assert int(actor.obs_normalizer.count) == cfg.iterations * cfg.env.num_envs * cfg.num_steps_per_env

    wider = build_actor(apply_overrides(TrainConfig.preset_config("cpu"), ["network.actor_hidden=(64, 16)"]))
    with pytest.raises(ValueError, match=r"actor_hidden"):
        load_onnx_actor(wider, path)
    deeper = build_actor(apply_overrides(TrainConfig.preset_config("cpu"), ["network.actor_hidden=(32, 16, 8)"]))
    with pytest.raises(ValueError, match=r"has 3 layers, the run's actor 4.*\[32, 16\]"):
        load_onnx_actor(deeper, path)


def test_a_new_run_starts_from_an_exported_policy_and_ship_counts_its_history(exported, tmp_path, capsys):
    from dynpush.policies.ship import onnx_provenance, provenance

    run, path = exported
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    (shipped / "policy.onnx").write_bytes(path.read_bytes())
    sha = OnnxPolicy(path).contract.training_config_sha256
    (shipped / "training.json").write_text(json.dumps({"run": "upstream", "commands": ["dynpush train --name upstream"],
                                                       "world_steps": 1000, "training_wall_clock_h": 0.5,
                                                       "training_config_sha256": sha}))
    fine = tmp_path / "fine"
    overrides = ["env.num_envs=8", "iterations=1", "num_steps_per_env=6", "save_interval=1",
                 "network.actor_hidden=(32, 16)", "network.critic_hidden=(16, 16)"]
    assert main(["train", "--name", "fine", "--runs", str(tmp_path), "--init-from", str(shipped / "policy.onnx"),
                 "--set", *overrides]) != 0
    assert "holds the actor only; set fine_tune.critic_warmup_iterations > 0" in capsys.readouterr().err
    assert main(["train", "--name", "fine", "--runs", str(tmp_path), "--init-from", str(shipped / "policy.onnx"),
                 "--set", *overrides, "fine_tune.critic_warmup_iterations=1", "network.actor_hidden=(64, 16)"]) != 0
    assert "set network.actor_hidden to the file's hidden sizes" in capsys.readouterr().err
    assert not fine.exists()  # both refused before anything was written
    main(["train", "--name", "fine", "--runs", str(tmp_path), "--init-from", str(shipped / "policy.onnx"),
          "--set", *overrides, "fine_tune.critic_warmup_iterations=1"])
    source = load_actor(run / "model_0.pt", load_run_config(run))
    tuned = load_actor(fine / "model_0.pt", load_run_config(fine))  # the actor was held in the warm-up iteration
    for name, value in source.state_dict().items():
        if name.startswith("mlp."):
            torch.testing.assert_close(tuned.state_dict()[name], value, msg=name)
    record = provenance(fine, fine / "model_0.pt")
    assert record["initialised_from"]["run"] == "upstream"
    assert record["commands"][0] == "dynpush train --name upstream" and record["world_steps"] == 1000 + 6 * 8
    (shipped / "training.json").unlink()  # a file without its record: its history is unknown, nothing is counted
    assert onnx_provenance(shipped / "policy.onnx")["history"] == "unknown"
