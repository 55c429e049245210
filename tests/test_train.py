"""dynpush train: config overrides, exact resume, interrupted runs, the learning curve (corrupted checkpoints:
test_run_folder.py)."""

import json

import numpy as np
import pytest
import torch

from dynpush.policies.train import TrainConfig, apply_overrides, train
from dynpush.sim.config import ConfigError

from train_helpers import tiny


def actor_parameters(runner):
    return [p.detach().clone() for p in runner.alg.actor.parameters()]


def test_overrides_are_typed_and_checked():
    cfg = apply_overrides(TrainConfig.preset_config("cpu"), ["env.num_envs=64", "ppo.learning_rate=3e-4"])
    assert cfg.env.num_envs == 64 and cfg.ppo.learning_rate == 3e-4
    with pytest.raises(ConfigError, match="env.num_env"):
        apply_overrides(cfg, ["env.num_env=3"])
    with pytest.raises(ConfigError, match="iterations must be of type int"):
        apply_overrides(cfg, ["iterations=many"])
    with pytest.raises(ConfigError, match="preset"):
        TrainConfig.preset_config("laptop")


def test_only_a_push_run_with_a_critic_warmup_starts_from_an_onnx_actor(tmp_path):
    from dynpush.policies.locomotion_train import LocomotionTrainConfig
    from dynpush.policies.training import read_onnx_actor

    onnx = tmp_path / "policy.onnx"  # refused before the file is read
    with pytest.raises(ConfigError, match="an ONNX file can start a push run only"):
        read_onnx_actor(LocomotionTrainConfig(), onnx)
    with pytest.raises(ConfigError, match=r"set fine_tune.critic_warmup_iterations > 0"):
        read_onnx_actor(TrainConfig(), onnx)


def test_tuple_overrides_keep_their_element_type():
    cfg = apply_overrides(TrainConfig.preset_config("cpu"), ["env.constraints.leg_nominal_torque=(80, 80, 80.5)"])
    assert cfg.env.constraints.leg_nominal_torque == (80.0, 80.0, 80.5)
    assert all(type(t) is float for t in cfg.env.constraints.leg_nominal_torque)
    for bad in ("network.actor_hidden=(32.5, 'x')", "network.actor_hidden=(64, True)",
                "env.constraints.leg_nominal_torque=(80, 'x', 80)"):
        with pytest.raises(ConfigError, match="must be a tuple of"):
            apply_overrides(TrainConfig.preset_config("cpu"), [bad])



def test_fine_tuning_fields_are_one_section_and_old_configs_read_into_it(tmp_path, capsys):
    from pathlib import Path

    from dynpush.cli import main
    from dynpush.policies.fine_tune import FineTuneConfig

    cfg = apply_overrides(TrainConfig.preset_config("cpu"), [
        "fine_tune.critic_warmup_iterations=60", "fine_tune.critic_warmup_learning_rate=1e-3",
        "fine_tune.imitation_weight=(1, 0.5)", "fine_tune.expert_object_size=0.4",
        "fine_tune.expert_overrides=('push_speed=0.9',)"]).validate()
    assert cfg.fine_tune == FineTuneConfig(60, 1e-3, (1.0, 0.5), 0.4, ("push_speed=0.9",))
    # A config.json written before the section existed holds the fields flat; it reads with the same values.
    old = json.loads(json.dumps(cfg.to_dict()))
    old.update(old.pop("fine_tune"))
    assert TrainConfig.from_dict(old) == cfg and "fine_tune" not in old and old["critic_warmup_iterations"] == 60
    with pytest.raises(ConfigError, match="config holds both imitation_weight and fine_tune.imitation_weight"):
        TrainConfig.from_dict({**old, "fine_tune": {"imitation_weight": [1.0, 1.0]}})
    # The long run's config.json as its first launches wrote it (a later --resume rewrites it in the new format).
    long1 = json.loads((Path(__file__).resolve().parent / "data" / "long1_config_flat.json").read_text())
    assert "critic_warmup_iterations" in long1 and "fine_tune" not in long1
    loaded = TrainConfig.from_dict(long1)
    assert loaded.fine_tune == FineTuneConfig() and (loaded.iterations, loaded.env.num_envs) == (20000, 1024)
    assert loaded.p_max_overrides == {"collision": [0.1, 1.0]} and loaded.keep_checkpoints == 1
    # Runs started before the critic read object_at_goal, or before contacts were those of a step's end state, resume
    # as they trained; new runs have both.
    assert loaded.env.critic_reads_object_at_goal is False and cfg.env.critic_reads_object_at_goal is True
    assert loaded.env.constraints.contacts_at_step_end is False and cfg.env.constraints.contacts_at_step_end is True
    assert TrainConfig.from_dict({"env": {"num_envs": 8}}).env.constraints.contacts_at_step_end is True
    # --resume reads an old run folder's config.json through the same loader.
    run = tmp_path / "old"
    run.mkdir()
    (run / "config.json").write_text(json.dumps(old))
    from dynpush.policies.training import run_config

    assert run_config(TrainConfig(), run, resume=True) == cfg
    # The flat names are no override any more: one line naming the new field.
    with pytest.raises(ConfigError, match=r"^critic_warmup_iterations is now fine_tune.critic_warmup_iterations: set"
                                          r" fine_tune.critic_warmup_iterations=60$"):
        apply_overrides(TrainConfig(), ["critic_warmup_iterations=60"])
    assert main(["train", "--runs", str(tmp_path), "--name", "r", "--set", "imitation_weight=(1.0, 1.0)"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "imitation_weight is now fine_tune.imitation_weight" in err, err
    assert not (tmp_path / "r").exists()
    with pytest.raises(ConfigError, match=r"^fine_tune.critic_warmup_learning_rate must be None or in \(0, 0.01\]"):
        apply_overrides(TrainConfig(), ["fine_tune.critic_warmup_learning_rate=0.5"]).validate()

def interrupt_update_call(monkeypatch, call: int) -> None:
    """Makes the ``call``-th PPO update raise KeyboardInterrupt (as Ctrl-C during an update would)."""
    from dynpush.policies.cat_ppo import CaTPPO

    calls = {"n": 0}
    original = CaTPPO.update

    def update(self):
        calls["n"] += 1
        if calls["n"] == call:
            raise KeyboardInterrupt
        return original(self)

    monkeypatch.setattr(CaTPPO, "update", update)


def test_interrupted_then_resumed_run_equals_the_uninterrupted_run(tmp_path, monkeypatch):
    torch.manual_seed(0)
    straight = train(tiny(4), tmp_path / "straight")

    torch.manual_seed(0)
    with monkeypatch.context() as patch:
        interrupt_update_call(patch, 3)  # Ctrl-C during the update of iteration 2
        train(tiny(4), tmp_path / "split")
    saved = torch.load(tmp_path / "split" / "model_2.pt", weights_only=False)
    assert saved["iter"] == 2 and "env_state" in saved["infos"]  # the boundary before iteration 2

    torch.manual_seed(123)  # the checkpoint's RNG state must win over whatever the new process has
    resumed = train(tiny(4), tmp_path / "split", resume=True)
    assert resumed.current_learning_iteration == straight.current_learning_iteration == 3
    for a, b in zip(actor_parameters(straight), actor_parameters(resumed)):
        assert torch.equal(a, b)
    assert torch.equal(straight.alg.c_max, resumed.alg.c_max)


def test_a_finished_run_continues_to_more_iterations_and_other_ppo_settings_in_a_later_sitting(tmp_path, capsys):
    from dynpush.cli import main

    tiny_set = ["env.num_envs=8", "num_steps_per_env=6", "network.actor_hidden=(32,)", "network.critic_hidden=(32,)"]
    assert main(["train", "--runs", str(tmp_path), "--name", "run", "--set", *tiny_set, "iterations=2"]) == 0
    assert main(["train", "--runs", str(tmp_path), "--name", "run", "--resume", "--set", "env.num_envs=16"]) == 2
    assert ("only iterations, ppo.* (not ppo.returns_per_step), network.min_noise_std, "
            "env.constraints.contacts_at_step_end and "
            "CURRICULUM.promote_above / .demote_below") in capsys.readouterr().err
    for fixed in ("ppo.returns_per_step=False", "curriculum.step=0.1", "curriculum_window_episodes=10"):
        assert main(["train", "--runs", str(tmp_path), "--name", "run", "--resume", "--set", fixed]) == 2
        assert f"got ['{fixed.split('=')[0]}']" in capsys.readouterr().err
    assert len((tmp_path / "run" / "launches.jsonl").read_text().splitlines()) == 1  # refused launches wrote nothing
    resumed_set = ["iterations=4", "ppo.lam=1.0", "mass_curriculum.demote_below=0.0", "behind_starts.promote_above=0.5",
                   "env.constraints.contacts_at_step_end=False"]
    assert main(["train", "--runs", str(tmp_path), "--name", "run", "--resume", "--set", *resumed_set]) == 0
    saved = torch.load(tmp_path / "run" / "model_3.pt", weights_only=False)
    assert saved["iter"] == 4
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["iterations"] == 4 and config["env"]["num_envs"] == 8 and config["ppo"]["lam"] == 1.0
    assert config["mass_curriculum"]["demote_below"] == 0.0 and config["behind_starts"]["promote_above"] == 0.5
    assert config["env"]["constraints"]["contacts_at_step_end"] is False
    launches = [json.loads(line) for line in (tmp_path / "run" / "launches.jsonl").read_text().splitlines()]
    assert [launch["resume"] for launch in launches] == [False, True]
    assert launches[1]["command"].endswith("--resume --set " + " ".join(resumed_set))


def test_a_resumed_run_samples_its_actions_above_a_new_noise_floor(tmp_path):
    from dynpush.policies.training import set_action_std

    train(tiny(2), tmp_path / "run")
    resumed = train(tiny(2), tmp_path / "run", resume=True,
                    resume_overrides=["iterations=3", "network.min_noise_std=0.45"])
    assert json.loads((tmp_path / "run" / "config.json").read_text())["network"]["min_noise_std"] == 0.45
    actor = resumed.alg.actor
    set_action_std(actor, 0.1)  # a learnt std below the floor, as a long run's shrinks
    actor.distribution.update(torch.zeros(1, actor.distribution.std_param.numel()))
    assert torch.allclose(actor.output_std, torch.full_like(actor.output_std, 0.45))


def test_the_resumable_curricula_are_the_success_gated_levels_of_the_config():
    from dynpush.policies.curriculum import SuccessGatedLevel
    from dynpush.policies.train import TrainConfig
    from dynpush.policies.training import CURRICULA

    levels = {name for name, value in vars(TrainConfig()).items() if isinstance(value, SuccessGatedLevel)}
    assert levels == set(CURRICULA)


def test_goal_curriculum_steps_with_the_success_rate():
    from dynpush.policies.curriculum import GoalCurriculumConfig

    cfg = GoalCurriculumConfig(enabled=True, initial=0.1, step=0.05, promote_above=0.5, demote_below=0.2)
    assert cfg.next_difficulty(0.3, 0.8) == pytest.approx(0.35)
    assert cfg.next_difficulty(0.3, 0.1) == pytest.approx(0.25)
    assert cfg.next_difficulty(0.3, 0.3) == 0.3 and cfg.next_difficulty(0.3, None) == 0.3
    assert cfg.next_difficulty(1.0, 0.9) == 1.0 and cfg.next_difficulty(0.1, 0.0) == 0.1
    with pytest.raises(ConfigError, match="curriculum.step"):
        GoalCurriculumConfig(step=2.0).validate()


def test_curriculum_run_starts_easy_and_eval_envs_stay_at_the_papers_task(tmp_path):
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    cfg = apply_overrides(tiny(2), ["curriculum.enabled=True", "curriculum.initial=0.2"])
    runner = train(cfg, tmp_path / "run")
    assert 0.2 <= runner.env.goal_difficulty_value <= 0.25
    assert PushEnv(PushEnvConfig(num_envs=1)).goal_difficulty_value == 1.0


def test_goal_curriculum_widens_the_success_angle_at_low_levels(tmp_path):
    from dynpush.policies.curriculum import GoalCurriculumConfig
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    cfg = GoalCurriculumConfig(enabled=True, initial_success_angle_deg=180.0)
    assert cfg.success_angle_deg(0.0, 10.0) == 180.0 and cfg.success_angle_deg(1.0, 10.0) == 10.0
    assert cfg.success_angle_deg(0.5, 10.0) == 95.0 and GoalCurriculumConfig().success_angle_deg(0.0, 10.0) == 10.0
    with pytest.raises(ConfigError, match=r"^curriculum.initial_success_angle_deg must lie in \[env.rewards.success_angle_deg"
                                          r" = 10, 180\], got 5.0$"):
        apply_overrides(tiny(1), ["curriculum.initial_success_angle_deg=5.0"]).validate()
    overrides = ["curriculum.enabled=True", "curriculum.initial=0.5", "curriculum.initial_success_angle_deg=170.0"]
    runner = train(apply_overrides(tiny(2), overrides), tmp_path / "run")
    assert runner.env.success_angle_deg_value == pytest.approx(90.0, abs=1e-4)  # no episode ended: the level holds
    rows = [json.loads(line) for line in (tmp_path / "run" / "progress.jsonl").read_text().splitlines()]
    assert [row["/curriculum/success_angle_deg"] for row in rows] == pytest.approx([90.0, 90.0])
    assert PushEnv(PushEnvConfig(num_envs=1)).success_angle_deg_value == pytest.approx(10.0)
    with pytest.raises(ConfigError, match=r"^success angle must lie in \[rewards.success_angle_deg = 10, 180\] deg"):
        runner.env.set_success_angle(5.0)


def test_curricula_move_on_a_window_of_ended_episodes(tmp_path):
    """The levels judge the success of at least ``curriculum_window_episodes`` ended episodes, summed over the
    iterations since they last moved; until then they hold. After a move, the episodes that end within one episode
    length (which may have started before it) are not counted, and a resumed run goes on with the same tally."""
    runner = train(apply_overrides(tiny(1), ["curriculum_window_episodes=10"]), tmp_path / "run")
    counts = iter([(4, 1), (4, 3), (4, 0), (0, 0), (12, 12)])
    runner.env.take_episode_counts = lambda: next(counts)
    rates = [runner.training_success_rate(iteration) for iteration in range(5)]
    assert rates[:2] == [None, None] and rates[2] == pytest.approx(4 / 12) and rates[3] is None and rates[4] == 1.0

    run = tmp_path / "moving"
    overrides = ["curriculum_window_episodes=10", "mass_curriculum.enabled=True", "mass_curriculum.promote_above=0.5"]
    runner = train(apply_overrides(tiny(1), overrides), run)
    assert runner.episode_iterations == 167  # 20 s at 50 Hz in rollouts of 6 steps
    runner.env.take_episode_counts = lambda: (10, 9)
    runner.apply_curricula(iteration=5, fresh_run=False)  # 90 % of 10 episodes: promoted
    assert runner.mass_difficulty == runner.mass_curriculum.step
    for iteration in range(6, 5 + runner.episode_iterations):  # episodes that may have started at the old level
        runner.apply_curricula(iteration, fresh_run=False)
    assert runner.mass_difficulty == runner.mass_curriculum.step and runner._episode_tally.sum() == 0
    runner.env.take_episode_counts = lambda: (6, 6)
    runner.apply_curricula(5 + runner.episode_iterations, fresh_run=False)  # counted, but fewer than 10
    assert runner.mass_difficulty == runner.mass_curriculum.step
    saved = runner.training_state(next_iteration=6 + runner.episode_iterations)["infos"]
    assert saved["curriculum_tally"] == [6.0, 6.0] and saved["count_episodes_from"] == 5 + runner.episode_iterations
    with pytest.raises(ConfigError, match=r"^curriculum_window_episodes must be an integer >= 1, got 0$"):
        apply_overrides(tiny(1), ["curriculum_window_episodes=0"]).validate()


def test_near_goal_start_config_is_checked():
    from dynpush.policies.curriculum import NearGoalStartConfig

    NearGoalStartConfig(share=1.0, goal_radius=2.0, max_yaw=np.pi).validate()
    for field, value, message in (("share", 1.5, r"near_goal_starts.share must lie in \[0, 1\], got 1.5"),
                                  ("goal_radius", -0.1, r"near_goal_starts.goal_radius must lie in \[0, 2\]"),
                                  ("max_yaw", 4.0, r"near_goal_starts.max_yaw must lie in \[0, 3.14159\]")):
        with pytest.raises(ConfigError, match=message):
            apply_overrides(tiny(2), [f"near_goal_starts.{field}={value}"]).validate()


def test_behind_start_run_logs_its_share_and_eval_envs_never_start_behind(tmp_path):
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    with pytest.raises(ConfigError, match=r"behind_starts.spread must lie in \[0, 3.14159\], got 4.0"):
        apply_overrides(tiny(2), ["behind_starts.spread=4.0"]).validate()
    runner = train(apply_overrides(tiny(2), ["behind_starts.share=1.0", "behind_starts.spread=0.2"]), tmp_path / "run")
    np.testing.assert_allclose(runner.env.behind_start.numpy()[0], (1.0, 0.2), rtol=1e-6)
    rows = [json.loads(line) for line in (tmp_path / "run" / "progress.jsonl").read_text().splitlines()]
    assert [row["/curriculum/behind_share"] for row in rows] == [1.0, 1.0]
    runner.env.reset()
    base, goal = runner.env.spec.base.numpy(), runner.env.spec.goal.numpy()
    off = np.angle(np.exp(1j * (np.arctan2(base[:, 1], base[:, 0]) - np.arctan2(goal[:, 1], goal[:, 0]) - np.pi)))
    assert (np.abs(off) <= 0.2 + 1e-5).all()
    np.testing.assert_array_equal(PushEnv(PushEnvConfig(num_envs=1)).behind_start.numpy()[0], (0.0, 0.0))


def test_behind_start_spread_follows_the_success_and_resumes_its_level(tmp_path):
    """With ``behind_starts.enabled`` the spread is ``spread`` + level x (pi - ``spread``), the level following the
    training success; it is set in the environment, logged, saved in checkpoints and read back by a resumed run."""
    from dynpush.policies.curriculum import BehindStartConfig

    cfg = BehindStartConfig(share=1.0, spread=0.5, enabled=True)
    assert cfg.spread_at(0.0) == 0.5 and cfg.spread_at(1.0) == pytest.approx(np.pi)
    assert cfg.spread_at(0.5) == pytest.approx(0.5 + 0.5 * (np.pi - 0.5))
    with pytest.raises(ConfigError, match=r"^behind_starts.enabled widens the spread .*: set behind_starts.share > 0$"):
        apply_overrides(tiny(1), ["behind_starts.enabled=True"]).validate()
    run = tmp_path / "run"
    overrides = ["behind_starts.share=1.0", "behind_starts.spread=0.3", "behind_starts.enabled=True",
                 "behind_starts.initial=0.5"]
    runner = train(apply_overrides(tiny(2), overrides), run)
    spread = BehindStartConfig(spread=0.3).spread_at(0.5)
    assert runner.behind_difficulty == 0.5  # too short for an episode to end: the level holds
    np.testing.assert_allclose(runner.env.behind_start.numpy()[0], (1.0, spread), rtol=1e-6)
    rows = [json.loads(line) for line in (run / "progress.jsonl").read_text().splitlines()]
    assert [row["/curriculum/behind_spread"] for row in rows] == pytest.approx([spread, spread])
    saved = torch.load(run / "model_1.pt", weights_only=False)
    assert saved["infos"]["behind_difficulty"] == 0.5
    saved["infos"]["behind_difficulty"] = 0.75
    torch.save(saved, run / "model_1.pt")
    resumed = train(apply_overrides(tiny(2), overrides), run, resume=True, resume_overrides=["iterations=3"])
    assert resumed.behind_difficulty == 0.75
    np.testing.assert_allclose(resumed.env.behind_start.numpy()[0], (1.0, BehindStartConfig(spread=0.3).spread_at(0.75)),
                               rtol=1e-6)


def test_near_goal_run_starts_near_and_eval_envs_never_do(tmp_path):
    """A 2-iteration run with every training reset near the goal: the share is logged per iteration and the episodes
    drawn after the first rollout start are near; a fresh environment (evaluation, export: built from ``env`` alone)
    has share 0."""
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    cfg = apply_overrides(tiny(2), ["near_goal_starts.share=1.0", "near_goal_starts.goal_radius=0.05",
                                    "near_goal_starts.max_yaw=0.3"])
    runner = train(cfg, tmp_path / "run")
    env = runner.env
    np.testing.assert_allclose(env.near_goal.numpy()[0], (1.0, 0.05, 0.3), rtol=1e-6)
    rows = [json.loads(line) for line in (tmp_path / "run" / "progress.jsonl").read_text().splitlines()]
    assert [row["/curriculum/near_goal_share"] for row in rows] == [1.0, 1.0]
    env.reset()
    goal, object_yaw = env.spec.goal.numpy(), env.spec.object_yaw.numpy()
    assert (np.linalg.norm(goal[:, :2], axis=1) <= 0.05 + 1e-6).all()
    assert (np.abs(goal[:, 2] - object_yaw) <= 0.3 + 1e-6).all()
    np.testing.assert_array_equal(env.near_goal_start.numpy(), 1)
    np.testing.assert_array_equal(PushEnv(PushEnvConfig(num_envs=1)).near_goal.numpy(), 0.0)


def test_episode_success_is_split_by_near_goal_starts():
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    env = PushEnv(PushEnvConfig(num_envs=4))
    env.episode_success_t[:] = torch.tensor([1, 0, 1, -1], dtype=env.episode_success_t.dtype)
    env.near_goal_ended_t[:] = torch.tensor([1, 1, 0, 1], dtype=env.near_goal_ended_t.dtype)
    ended = env.episode_success_t >= 0
    succeeded = (env.episode_success_t[ended] == 1).float()
    assert env._near_goal_log(ended, succeeded) == {}, "a plain run logs no split"
    env.set_near_goal_starts(0.5, 0.1, 0.6)
    log = env._near_goal_log(ended, succeeded)
    assert log["/episode/near_goal/success"].tolist() == [1.0, 0.0]
    assert log["/episode/other/success"].tolist() == [1.0]
    with pytest.raises(ConfigError, match="near-goal starts need share in"):
        env.set_near_goal_starts(1.5, 0.1, 0.6)


def test_learning_curve_counts_pauses_between_sittings_as_the_iteration_only(tmp_path):
    from dynpush.cli import main
    from dynpush.policies.progress import read_progress, wall_clock_hours

    run = tmp_path / "run"
    run.mkdir()
    rows = [  # iteration 2 was interrupted and re-run after a 2-hour pause
        {"iteration": 0, "time": 100.0, "collect_s": 1.0, "learn_s": 1.0, "/episode/success": 0.0},
        {"iteration": 1, "time": 103.0, "collect_s": 1.0, "learn_s": 1.0, "/episode/success": 0.5},
        {"iteration": 2, "time": 106.0, "collect_s": 1.0, "learn_s": 1.0},
        {"iteration": 2, "time": 7306.0, "collect_s": 1.5, "learn_s": 1.0, "/episode/success": 1.0},
        {"iteration": 3, "time": 7309.0, "collect_s": 1.0, "learn_s": 1.0, "/episode/success": 1.0},
    ]
    (run / "progress.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    records = read_progress(run)
    assert [r["iteration"] for r in records] == [0, 1, 2, 3] and records[2]["time"] == 7306.0
    np.testing.assert_allclose(wall_clock_hours(records) * 3600.0, [2.0, 5.0, 7.5, 10.5])
    assert main(["curve", str(run), "--out", str(tmp_path / "curve.png")]) == 0
    assert (tmp_path / "curve.png").read_bytes()[:4] == b"\x89PNG"
    (run / "progress.jsonl").write_text("{not json\n")
    with pytest.raises(ValueError, match="progress.jsonl:1: not a JSON record"):
        read_progress(run)


def test_p_max_overrides_replace_the_papers_curriculum_of_a_group():
    from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS
    from dynpush.policies.schedules import ScheduleConfig, p_max_at

    cfg = apply_overrides(TrainConfig.preset_config("cpu"), ["p_max_overrides={'collision': (0.1, 1.0)}"]).validate()
    schedule = ScheduleConfig.from_dict(cfg.runner_cfg()["schedule"])
    names = [name for name, dim in CONSTRAINT_GROUPS for _ in range(dim)]
    start, middle, end = (p_max_at(it, 5000, schedule) for it in (0, 1500, 3000))  # ramp: 12000 * 5000 / 20000
    collision = [i for i, name in enumerate(names) if name == "collision"]
    assert torch.allclose(start[collision], torch.tensor(0.1)) and torch.allclose(middle[collision], torch.tensor(0.55))
    assert torch.allclose(end[collision], torch.tensor(1.0))
    balance = names.index("object_balance")
    assert start[balance] == end[balance] == pytest.approx(0.25)  # the other groups keep the paper's values
    with pytest.raises(ConfigError, match=r"p_max_overrides: unknown \['colision'\]"):
        apply_overrides(TrainConfig.preset_config("cpu"), ["p_max_overrides={'colision': (0.1, 1.0)}"]).validate()
    with pytest.raises(ConfigError, match=r"p_max_overrides\['collision'\] must be \(initial, final\) within \[0, 1\]"):
        apply_overrides(TrainConfig.preset_config("cpu"), ["p_max_overrides={'collision': (0.1, 2.0)}"]).validate()


def test_mass_curriculum_maps_its_level_onto_the_configured_masses():
    from dynpush.policies.curriculum import ObjectMassCurriculumConfig

    cfg = ObjectMassCurriculumConfig(enabled=True, initial_max=2.0)
    assert cfg.mass_range(0.0, (1.0, 10.0)) == (1.0, 2.0)
    assert cfg.mass_range(0.5, (1.0, 10.0)) == (1.0, 6.0)
    assert cfg.mass_range(1.0, (1.0, 10.0)) == (1.0, 10.0)
    assert cfg.next_difficulty(0.5, 0.25) == pytest.approx(0.525)  # promoted above 0.2
    with pytest.raises(ConfigError, match=r"mass_curriculum.initial_max must lie in env.randomization.mass \(1.0, 10.0\)"):
        apply_overrides(tiny(1), ["mass_curriculum.enabled=True", "mass_curriculum.initial_max=0.5"]).validate()


def test_min_noise_std_is_a_floor_under_the_learnt_action_noise():
    from dynpush.policies.actor import build_actor
    from dynpush.policies.training import set_action_std

    cfg = apply_overrides(tiny(1), ["network.init_noise_std=0.5", "network.min_noise_std=0.3"]).validate()
    actor = build_actor(cfg)
    set_action_std(actor, 0.1)  # as if PPO had shrunk it
    actor.distribution.update(torch.zeros(2, 11))
    assert torch.allclose(actor.distribution.std, torch.full((2, 11), 0.3))
    set_action_std(actor, 0.45)
    actor.distribution.update(torch.zeros(2, 11))
    assert torch.allclose(actor.distribution.std, torch.full((2, 11), 0.45))
    with pytest.raises(ConfigError, match=r"^network.min_noise_std must lie in \[0, network.init_noise_std = 0.5\], got 0.6$"):
        apply_overrides(tiny(1), ["network.init_noise_std=0.5", "network.min_noise_std=0.6"]).validate()


def test_distance_curriculum_moves_its_band_to_the_configured_goals_and_resumes_its_level(tmp_path):
    from dynpush.policies.curriculum import GoalDistanceCurriculumConfig
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    cfg = GoalDistanceCurriculumConfig(enabled=True, initial_radius=(0.4, 0.6))
    assert cfg.radius_range(0.0, (0.0, 2.0)) == (0.4, 0.6)
    assert cfg.radius_range(0.5, (0.0, 2.0)) == pytest.approx((0.2, 1.3))
    assert cfg.radius_range(1.0, (0.0, 2.0)) == (0.0, 2.0)
    run = tmp_path / "run"
    overrides = ["distance_curriculum.enabled=True", "distance_curriculum.initial_radius=(0.5, 0.7)"]
    runner = train(apply_overrides(tiny(2), overrides), run)
    assert runner.env.goal_radius_range_value == pytest.approx((0.5, 0.7))
    runner.env.reset()  # episodes drawn from now on
    goals = runner.env.spec.goal.numpy()
    assert np.all(np.abs(np.linalg.norm(goals[:, :2], axis=1) - 0.6) <= 0.1 + 1e-5)
    assert PushEnv(PushEnvConfig(num_envs=1)).goal_radius_range_value == (0.0, 2.0)
    with pytest.raises(ConfigError, match="goal radius range must lie within sampling.goal_radius"):
        runner.env.set_goal_radius_range(0.5, 2.5)
    rows = [json.loads(line) for line in (run / "progress.jsonl").read_text().splitlines()]
    assert [row["/curriculum/goal_radius_max"] for row in rows] == pytest.approx([0.7, 0.7])
    saved = torch.load(run / "model_1.pt", weights_only=False)
    saved["infos"]["distance_difficulty"] = 0.5  # a level reached later in a run
    torch.save(saved, run / "model_1.pt")
    resumed = train(apply_overrides(tiny(2), overrides), run, resume=True, resume_overrides=["iterations=3"])
    assert resumed.distance_difficulty == 0.5 and resumed.env.goal_radius_range_value == pytest.approx((0.25, 1.35))


def test_p_max_follows_the_curricula_mean_level(tmp_path):
    """With ``p_max_follows_curricula`` CaT's p_max sits at the mean progress of the enabled curricula from their initial
    levels to the paper's task, whatever the iteration; without an enabled curriculum the config is refused."""
    from dynpush.policies.schedules import p_max_at_progress

    with pytest.raises(ConfigError, match=r"^p_max_follows_curricula needs an enabled curriculum"):
        apply_overrides(tiny(1), ["p_max_follows_curricula=True"]).validate()
    overrides = ["p_max_follows_curricula=True", "mass_curriculum.enabled=True", "mass_curriculum.initial=0.5",
                 "distance_curriculum.enabled=True", "p_max_overrides={'collision': (0.0, 1.0)}"]
    runner = train(apply_overrides(tiny(2), overrides), tmp_path / "run")
    assert runner.curricula_progress() == pytest.approx(0.0)  # both at their initial levels: CaT at its initial p_max
    torch.testing.assert_close(runner.alg.p_max, p_max_at_progress(0.0, runner.schedule_cfg))
    runner.mass_difficulty, runner.distance_difficulty = 0.75, 0.8  # progress 0.5 and 0.8
    runner.apply_schedules(iteration=1, total_iterations=2)
    expected = p_max_at_progress(0.65, runner.schedule_cfg)
    torch.testing.assert_close(runner.alg.p_max, expected)
    assert not torch.equal(expected, p_max_at_progress(0.0, runner.schedule_cfg))
    rows = [json.loads(line) for line in (tmp_path / "run" / "progress.jsonl").read_text().splitlines()]
    assert [row["/curriculum/p_max_progress"] for row in rows] == [0.0, 0.0]


@pytest.mark.parametrize("overrides, message", [
    (["distance_curriculum.initial_radius=(0.6, 0.4)"], r"^distance_curriculum.initial_radius must be \(low, high\)"),
    (["distance_curriculum.enabled=True", "env.sampling.goal_radius=(0.0, 0.5)"],
     r"^distance_curriculum.initial_radius must be \(low, high\) with low <= high within env.sampling.goal_radius"),
    (["distance_curriculum.step=1.5"], r"^distance_curriculum.step must lie in \[0, 1\], got 1.5$"),
    (["curriculum.initial=-0.1"], r"^curriculum.initial must lie in \[0, 1\], got -0.1$"),
    (["curriculum.demote_below=0.5"], r"^curriculum.demote_below must be <= curriculum.promote_above$"),
    (["mass_curriculum.promote_above=1.5"], r"^mass_curriculum.promote_above must lie in \[0, 1\], got 1.5$"),
    (["mass_curriculum.enabled=True", "mass_curriculum.initial_max=12.0"],
     r"^mass_curriculum.initial_max must lie in env.randomization.mass"),
])
def test_curriculum_config_errors_name_the_field(overrides, message):
    with pytest.raises(ConfigError, match=message):
        apply_overrides(tiny(1), overrides).validate()


def test_a_disabled_curriculum_accepts_any_task_ranges():
    """A reduced task (the goal 0.4 m ahead, objects of one mass) with the curricula off: nothing to check."""
    apply_overrides(tiny(1), ["env.sampling.goal_radius=(0.4, 0.4)", "env.randomization.mass=(1.0, 1.5)"]).validate()


def test_mass_curriculum_run_starts_light_resumes_its_level_and_eval_envs_keep_the_masses(tmp_path):
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    run = tmp_path / "run"
    cfg = apply_overrides(tiny(2), ["mass_curriculum.enabled=True", "mass_curriculum.initial_max=3.0"])
    runner = train(cfg, run)
    assert runner.env.object_mass_range_value == (1.0, 3.0)
    assert PushEnv(PushEnvConfig(num_envs=1)).object_mass_range_value == (1.0, 10.0)
    with pytest.raises(ConfigError, match="object mass range must lie within randomization.mass"):
        runner.env.set_object_mass_range(0.5, 2.0)
    checkpoint = run / "model_1.pt"
    saved = torch.load(checkpoint, weights_only=False)
    saved["infos"]["mass_difficulty"] = 0.5  # a level reached later in a run
    torch.save(saved, checkpoint)
    resumed = train(cfg, run, resume=True, resume_overrides=["iterations=3"])  # too short for an episode to end: the level holds
    assert resumed.mass_difficulty == 0.5 and resumed.env.object_mass_range_value == (1.0, 6.5)


def test_resume_with_another_env_layout_starts_fresh_episodes(tmp_path, capsys):
    """A run resumed with another number of worlds per process cannot restore the saved episodes."""
    run = tmp_path / "run"
    train(tiny(2), run)
    config = json.loads((run / "config.json").read_text())
    config["env"]["num_envs"] = 4  # as the shard of a 2-process run of 8 worlds would have saved
    (run / "config.json").write_text(json.dumps(config))
    checkpoint = run / "model_1.pt"
    saved = torch.load(checkpoint, weights_only=False)
    saved["infos"]["env_state"]["goal_difficulty"][:] = 0.35  # a curriculum run's difficulty survives
    torch.save(saved, checkpoint)
    resumed = train(tiny(2), run, resume=True, resume_overrides=["iterations=3", "ppo.lam=1.0"])
    assert resumed.current_learning_iteration == 2 and resumed.env.num_envs == 4
    assert resumed.alg.lam == 1.0  # the PPO update trains with the resumed launch's setting
    assert resumed.env.goal_difficulty_value == pytest.approx(0.35)
    assert "fresh episodes, the saved environment state does not fit" in capsys.readouterr().out
    # Fresh episodes start together and end together: the curricula judge from one episode length on.
    resumed_state = torch.load(run / "model_2.pt", weights_only=False)["infos"]
    assert resumed_state["count_episodes_from"] == 2 + resumed.episode_iterations
