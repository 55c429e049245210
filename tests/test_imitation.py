"""dynpush imitate (DAgger from the scripted pusher) and the critic warm-up of the CaT-PPO fine-tuning that follows."""

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from dynpush.policies.fine_tune import FineTuneConfig
from dynpush.policies.imitation import ImitationConfig, imitate
from dynpush.policies.train import apply_overrides, train
from dynpush.sim.config import ConfigError

from train_helpers import tiny


def tiny_imitation(rounds: int) -> ImitationConfig:
    return ImitationConfig(rounds=rounds, steps_per_round=40, epochs=20, batch_size=64, learning_rate=3e-3)


def expert_loss(actor: torch.nn.Module, observations: torch.Tensor, labels: torch.Tensor) -> float:
    with torch.no_grad():
        return float(torch.nn.functional.mse_loss(actor.mlp(actor.obs_normalizer(observations)), labels))


def test_dagger_fits_the_expert_and_its_checkpoint_exports_and_fine_tunes(tmp_path):
    from dynpush.policies.actor import load_actor
    from dynpush.policies.export import export_policy
    from dynpush.policies.onnx_policy import OnnxPolicy

    run = tmp_path / "bc"
    checkpoint = imitate(tiny(), tiny_imitation(2), run)
    rounds = [json.loads(line) for line in (run / "imitation.jsonl").read_text().splitlines()]
    assert [r["round"] for r in rounds] == [0, 1] and rounds[0]["expert_worlds"] == 8
    assert rounds[1]["samples"] == 2 * 8 * 40
    saved = torch.load(checkpoint, weights_only=False)
    assert saved["iter"] == 0

    data = torch.load(run / "imitation_data.pt", weights_only=False)["dagger"]
    fitted = load_actor(checkpoint, tiny())
    untrained = load_actor(checkpoint, tiny())
    for p in untrained.mlp.parameters():  # same normaliser, fresh weights
        torch.nn.init.normal_(p, std=0.1)
    fitted_loss = expert_loss(fitted, data["observations"], data["labels"])
    assert fitted_loss < 0.5 * expert_loss(untrained, data["observations"], data["labels"])
    assert fitted_loss == pytest.approx(rounds[1]["loss"], rel=0.5)

    policy = OnnxPolicy(export_policy(run, "imitation.pt"))
    observations = data["observations"][:1].numpy()
    with torch.no_grad():
        expected = fitted(observations_dict(observations)).numpy()
    np.testing.assert_allclose(policy(observations), expected, atol=1e-4)

    from dynpush.policies.progress import plot_learning_curve

    curve = plot_learning_curve(run, tmp_path / "curve.png")  # a DAgger-only run draws its rounds
    assert (tmp_path / "curve.png").read_bytes()[:4] == b"\x89PNG"
    assert curve["iterations"] == 0 and curve["success_percent"] == pytest.approx(100.0 * rounds[1]["success_rate"])
    assert curve["hours"] == pytest.approx(sum(r["seconds"] for r in rounds) / 3600.0)

    runner = train(tiny(), run, resume=True)  # CaT-PPO continues from the imitation checkpoint: iterations 0 and 1
    assert runner.current_learning_iteration == 1
    assert [json.loads(line)["iteration"] for line in (run / "progress.jsonl").read_text().splitlines()] == [0, 1]


def observations_dict(observations: np.ndarray):
    from tensordict import TensorDict

    return TensorDict({"policy": torch.from_numpy(observations)}, batch_size=[observations.shape[0]])


def test_interrupted_imitation_resumes_after_its_last_round(tmp_path):
    run = tmp_path / "bc"
    imitate(tiny(), replace(tiny_imitation(1), expert_object_size=0.4, expert_overrides=("push_speed=0.9",)), run)
    with pytest.raises(FileExistsError, match="holds a run already"):
        imitate(tiny(), tiny_imitation(2), run)
    imitate(tiny(), tiny_imitation(2), run, resume=True)
    rounds = [json.loads(line) for line in (run / "imitation.jsonl").read_text().splitlines()]
    assert [r["round"] for r in rounds] == [0, 1]
    assert rounds[1]["samples"] == 2 * 8 * 40  # the aggregated data set survived the restart
    launches = [json.loads(line) for line in (run / "launches.jsonl").read_text().splitlines()]
    assert [launch["resume"] for launch in launches] == [False, True]
    # The resumed rounds are labelled by the run's own expert, not by the default one of the resuming call.
    saved = json.loads((run / "imitation_config.json").read_text())
    assert saved["expert_object_size"] == 0.4 and saved["expert_overrides"] == ["push_speed=0.9"]


def test_imitation_config_errors_name_the_field():
    with pytest.raises(ConfigError, match="imitation.rounds must be an integer >= 1"):
        ImitationConfig(rounds=0).validate()
    with pytest.raises(ConfigError, match=r"imitation.expert_share must lie in \[0, 1\]"):
        ImitationConfig(expert_share=1.5).validate()
    with pytest.raises(ConfigError, match=r"imitation.expert_object_size must be None or in \(0, 2\] m"):
        ImitationConfig(expert_object_size=0.0).validate()
    with pytest.raises(ConfigError, match=r"imitation.expert_overrides: scripted.push_speed must be in \(0, 1\] m/s"):
        ImitationConfig(expert_overrides=("push_speed=1.5",)).validate()
    with pytest.raises(ConfigError, match="imitation.expert_overrides: unknown config field 'push_sped'"):
        ImitationConfig(expert_overrides=("push_sped=0.9",)).validate()
    with pytest.raises(ConfigError, match="^fine_tune.expert_overrides: override must look like field.path=value"):
        replace(tiny(), fine_tune=FineTuneConfig(expert_overrides=("push_speed",))).validate()
    with pytest.raises(ConfigError, match=r"^fine_tune.expert_overrides: scripted.yaw_gain must be a finite number >= 0"):
        replace(tiny(), fine_tune=FineTuneConfig(expert_overrides=("yaw_gain=-1.0",))).validate()
    expert = ImitationConfig(expert_object_size=0.4, expert_overrides=("push_speed=0.9", "yaw_gain=0.6")).expert()
    assert (expert.object_size, expert.push_speed, expert.yaw_gain) == (0.4, 0.9, 0.6)
    with pytest.raises(ConfigError, match="^fine_tune.critic_warmup_iterations must be an integer >= 0"):
        tiny(2, "fine_tune.critic_warmup_iterations=-1").validate()


def test_critic_warmup_holds_the_actor_and_trains_the_critic(tmp_path, monkeypatch):
    from dynpush.policies.cat_ppo import CaTPPO

    snapshots = []
    original = CaTPPO.update

    def update(self):
        learning_rates.append([group["lr"] for group in self.optimizer.param_groups])
        result = original(self)
        snapshots.append(([p.detach().clone() for p in self.actor.parameters()],
                          [p.detach().clone() for p in self.critic.parameters()]))
        return result

    monkeypatch.setattr(CaTPPO, "update", update)
    learning_rates = []
    cfg = apply_overrides(tiny(3, "fine_tune.critic_warmup_iterations=2"), ["ppo.schedule=fixed", "ppo.learning_rate=0.0002"])
    runner = train(cfg, tmp_path / "run")
    assert len(snapshots) == 3
    first, second, third = snapshots
    assert all(torch.equal(a, b) for a, b in zip(first[0], second[0]))  # the actor is held in iterations 0 and 1
    assert not all(torch.equal(a, b) for a, b in zip(first[1], second[1]))  # while the critic learns
    assert not all(torch.equal(a, b) for a, b in zip(second[0], third[0]))  # iteration 2 trains the actor
    assert all(p.requires_grad for p in runner.alg.actor.parameters())
    assert learning_rates == [[2e-4]] * 3

    learning_rates.clear()  # a warm-up learning rate of its own, the run's from the first actor update
    train(apply_overrides(cfg, ["fine_tune.critic_warmup_learning_rate=0.003"]), tmp_path / "run_lr")
    assert learning_rates == [[3e-3], [3e-3], [2e-4]]
    with pytest.raises(ConfigError, match=r"^fine_tune.critic_warmup_learning_rate must be None or in \(0, 0.01\]"):
        apply_overrides(cfg, ["fine_tune.critic_warmup_learning_rate=0.5"]).validate()



def test_expert_regularised_ppo_stores_the_experts_labels_and_pulls_the_actor_to_them(tmp_path, monkeypatch):
    from dynpush.policies.cat_ppo import CaTPPO
    from dynpush.policies.expert_regularization import EXPERT_ACTION_GROUP, ExpertLabelledEnv
    from dynpush.policies.scripted import ScriptedPusher
    from dynpush.sim.push_env import PushEnv

    cfg = apply_overrides(tiny(12), ["fine_tune.imitation_weight=(50.0, 10.0)", "ppo.learning_rate=0.003"])
    env = cfg.make_env(cfg.env)
    assert isinstance(env, ExpertLabelledEnv)
    observations = env.get_observations()
    assert isinstance(env.env, PushEnv)
    expert = ScriptedPusher(env.env)  # an expert of its own on the same state
    np.testing.assert_allclose(observations[EXPERT_ACTION_GROUP].numpy(), expert(None), atol=1e-6)
    with pytest.raises(ConfigError, match=r"^fine_tune.imitation_weight must be \(first, last\) with both >= 0"):
        apply_overrides(tiny(), ["fine_tune.imitation_weight=(-1.0, 0.0)"]).validate()
    with pytest.raises(ConfigError, match=r"^fine_tune.expert_object_size must be None or in \(0, 2\] m"):
        apply_overrides(tiny(), ["fine_tune.expert_object_size=0.0"]).validate()
    with pytest.raises(ConfigError, match=r"^fine_tune.expert_object_size must be float \| None, got 'big'"):
        apply_overrides(tiny(), ["fine_tune.expert_object_size=big"])
    assert apply_overrides(tiny(), ["fine_tune.expert_object_size=1",
                                    "fine_tune.expert_object_size=None"]).fine_tune.expert_object_size is None
    assert apply_overrides(tiny(), ["fine_tune.expert_object_size=1"]).fine_tune.expert_object_size == 1.0

    distances, weights, logged = [], [], []
    original = CaTPPO.update

    def update(self):
        storage = self.storage
        batch = storage.observations.flatten(0, 1)
        with torch.no_grad():
            mean = self.actor(batch)
        distances.append(float((mean - batch[EXPERT_ACTION_GROUP]).pow(2).sum(-1).mean()))
        weights.append(self.symmetry.mirror_loss_coeff)
        losses = original(self)
        logged.append(losses)
        return losses

    monkeypatch.setattr(CaTPPO, "update", update)
    train(cfg, tmp_path / "run")
    assert weights[0] == pytest.approx(50.0) and weights[-1] == pytest.approx(10.0)
    assert all("imitation" in losses and "symmetry" not in losses for losses in logged)
    assert distances[-1] < 0.5 * distances[0]  # a random actor moves toward the expert's actions
    assert json.loads((tmp_path / "run" / "config.json").read_text())["fine_tune"]["imitation_weight"] == [50.0, 10.0]


def test_the_imitation_term_can_take_the_nominal_size_teacher_of_a_dagger_student():
    from dynpush.policies.expert_regularization import EXPERT_ACTION_GROUP
    from dynpush.policies.scripted import ScriptedPusher, ScriptedPusherConfig

    cfg = apply_overrides(tiny(), ["fine_tune.imitation_weight=(1.0, 0.0)", "fine_tune.expert_object_size=0.4",
                               "env.num_envs=32"])
    env = cfg.make_env(cfg.validate().env)
    labels = env.get_observations()[EXPERT_ACTION_GROUP].numpy()
    nominal = ScriptedPusher(env.env, ScriptedPusherConfig(object_size=0.4))(None)
    np.testing.assert_allclose(labels, nominal, atol=1e-6)
    assert np.abs(labels - ScriptedPusher(env.env)(None)).max() > 0.05  # not the privileged teacher's
    slower = apply_overrides(cfg, ["fine_tune.expert_overrides=('approach_speed=0.5',)"])  # the robots start away from the object
    slow_env = slower.make_env(slower.validate().env)
    slow_labels = slow_env.get_observations()[EXPERT_ACTION_GROUP].numpy()
    slow = ScriptedPusher(slow_env.env, ScriptedPusherConfig(object_size=0.4, approach_speed=0.5))(None)
    np.testing.assert_allclose(slow_labels, slow, atol=1e-6)
    assert np.abs(slow_labels - ScriptedPusher(slow_env.env, ScriptedPusherConfig(object_size=0.4))(None)).max() > 0.1


def test_a_new_run_starts_from_another_runs_imitation_actor_with_its_own_optimizer_and_noise(tmp_path):
    checkpoint = imitate(tiny(), tiny_imitation(1), tmp_path / "bc")
    cfg = apply_overrides(tiny(2, "fine_tune.critic_warmup_iterations=2"),
                          ["ppo.learning_rate=0.0002", "ppo.schedule=fixed", "network.init_noise_std=0.07"])
    runner = train(cfg, tmp_path / "fine", init_from=checkpoint)  # the actor is held in both iterations
    saved = torch.load(checkpoint, weights_only=False)
    actor = runner.alg.actor.state_dict()
    assert not torch.allclose(saved["actor_state_dict"]["distribution.std_param"], torch.tensor(0.07))
    torch.testing.assert_close(actor["distribution.std_param"], torch.full((runner.env.num_actions,), 0.07))
    held = {name: value for name, value in actor.items() if "std_param" not in name}
    assert any(name.startswith("mlp.") for name in held)
    assert any("normalizer" in name for name in held)  # held too: a run started from another keeps its statistics
    assert json.loads((tmp_path / "fine" / "config.json").read_text())["network"]["hold_actor_normalizer"] is True
    for name, value in held.items():
        torch.testing.assert_close(value, saved["actor_state_dict"][name], msg=name)
    assert runner.alg.learning_rate == 0.0002 and runner.current_learning_iteration == 1
    assert (tmp_path / "fine" / "model_1.pt").exists() and not (tmp_path / "fine" / "imitation.pt").exists()
    launch = json.loads((tmp_path / "fine" / "launches.jsonl").read_text().splitlines()[0])
    assert launch["init_from"] == str(checkpoint.resolve())

    from dynpush.policies.ship import provenance

    record = provenance(tmp_path / "fine", tmp_path / "fine" / "model_1.pt")
    upstream = record["initialised_from"]
    assert upstream["run"] == "bc" and upstream["iterations"] == 0 and upstream["imitation"]["rounds"] == 1
    assert record["commands"] == [*upstream["commands"], launch["command"]]
    assert record["world_steps"] == 2 * 6 * 8 + 8 * 40  # two iterations of 6 steps in 8 worlds + one DAgger round

    from dynpush.policies.progress import plot_learning_curve

    alone = plot_learning_curve(tmp_path / "fine", tmp_path / "alone.png")
    both = plot_learning_curve(tmp_path / "fine", tmp_path / "both.png", imitation_run=tmp_path / "bc")
    assert both["iterations"] == alone["iterations"] == 2  # the shipped curve starts with the upstream DAgger rounds
    assert both["hours"] == pytest.approx(alone["hours"] + upstream["imitation"]["wall_clock_h"])


def test_cli_passes_the_experts_size_and_gains(tmp_path, monkeypatch):
    from dynpush import cli
    from dynpush.policies import imitation

    calls = []
    monkeypatch.setattr(imitation, "imitate", lambda cfg, imitation_cfg, run_dir, **kwargs: calls.append(imitation_cfg))
    common = ["imitate", "--name", "bc", "--runs", str(tmp_path), "--rounds", "3"]
    assert cli.main([*common, "--expert-object-size", "0.4", "--expert-set", "push_speed=1.0"]) == 0
    assert cli.main(common) == 0
    assert [(c.rounds, c.expert_object_size, c.expert_overrides) for c in calls] == [
        (3, 0.4, ("push_speed=1.0",)), (3, None, ())]
