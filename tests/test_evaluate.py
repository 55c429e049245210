"""dynpush eval, scenario, footprints and play: Tables I-II evaluation, scenario files and face switches, footprint
study, rollout pictures."""

import dataclasses
import json

import numpy as np
import pytest
import torch
import yaml

from dynpush.cli import main
from dynpush.policies.actor import build_actor
from dynpush.policies.env_probe import EE_CONTACT_COLUMN
from dynpush.policies.episodes import FirstEpisodes
from dynpush.policies.evaluate import EvalConfig, evaluate
from dynpush.policies.export import export_policy
from dynpush.policies.face_switches import FACE_NAMES, NO_FACE, contact_face, count_face_switches
from dynpush.policies.footprints import FootprintConfig, footprint_study
from dynpush.policies.observers import ContactMotionObserver, GoalErrorObserver
from dynpush.policies.tables import paper_table_i_row
from dynpush.policies.scenario_schema import load_scenario, parse_scenario
from dynpush.policies.train import TrainConfig, apply_overrides
from dynpush.sim.config import ConfigError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    """policy.onnx of an untrained tiny actor (evaluation mechanics do not need a good policy)."""
    run = tmp_path_factory.mktemp("run")
    cfg = apply_overrides(TrainConfig.preset_config("cpu"), ["network.actor_hidden=(16, 16)"])
    (run / "config.json").write_text(json.dumps(cfg.to_dict()))
    torch.manual_seed(0)
    torch.save({"actor_state_dict": build_actor(cfg).state_dict()}, run / "model_0.pt")
    return export_policy(run)


def is_png(path) -> bool:
    return path.read_bytes()[:8] == PNG_SIGNATURE


def test_eval_writes_tables_json_and_png(policy, tmp_path):
    cfg = EvalConfig(episodes=12, num_envs=8, overrides=("env.episode_length_s=0.4",))
    result = evaluate(policy, cfg, tmp_path)
    saved = json.loads((tmp_path / "eval.json").read_text())
    assert saved == json.loads(json.dumps(result))
    for key in ("success_rate", "toppled_rate", "reached_rate", "constraint_violation_percent", "time_to_success_s",
                "by_shape", "episodes", "paper", "runtime", "config"):
        assert key in saved
    assert saved["episodes"] == 12 and saved["runtime"]["rounds"] == 2
    assert sum(s["episodes"] for s in saved["by_shape"].values()) == 12
    assert set(saved["by_shape"]) == {"cuboid", "cylinder"}
    assert saved["paper"]["table_I_row"] == "Ours (with all the above)"
    assert all(0.0 <= v <= 100.0 for v in saved["constraint_violation_percent"].values())
    assert saved["episode_length_s"]["max"] <= 0.4 + 1e-9
    assert set(saved["while_touching"]) == {"ee_vertical_speed_m_s", "object_horizontal_acceleration_m_s2",
                                            "base_commanded_vx_m_s", "base_forward_speed_m_s", "object_sliding_force_n",
                                            "base_speed_by_sliding_force"}
    bins = saved["while_touching"]["base_speed_by_sliding_force"]
    assert sum(row["count"] for row in bins) == saved["while_touching"]["base_forward_speed_m_s"]["count"]
    assert saved["config"]["env"]["randomize_first_episode_length"] is False
    assert saved["rewards"]["gamma"] == 0.99
    assert saved["rewards"]["return_to_go"]["count"] == round(12 * saved["episode_length_s"]["mean"] / 0.02)
    assert set(saved["rewards"]["term_means_per_step"]) == set(saved["rewards"]["weights"]) == {
        "task", "reach", "object_velocity", "action_rate"}
    outcome = saved["goal_error"]["outcome_percent"]
    assert sum(outcome.values()) == pytest.approx(100.0)
    assert outcome["robot_fell"] <= saved["fallen_rate"]
    assert sum(row["episodes"] for row in saved["goal_error"]["success_by_goal_rotation_deg"]) == 12
    assert sum(row["episodes"] for row in saved["goal_error"]["success_by_goal_distance_m"]) == 12
    assert sum(row["episodes"] for row in saved["goal_error"]["success_by_start_side_deg"]) == 12
    assert is_png(tmp_path / "eval.png")


def test_goal_errors_of_hand_made_episodes(small_env):
    """Four worlds, the goal at (1, 0, 0.35) rotated 90 deg about z. The objects slide from the origin toward the
    goal over 10 steps; world 0 ends at the goal rotated right (the success flag decides), world 1 at the goal with
    its start yaw kept, world 2 halfway with the goal's rotation, world 3 halfway with its start yaw but restarts
    (its episode ends) after step 4: its last state before the end is kept."""
    from dynpush.runtime.frames import yaw_quat

    steps = 10
    observer = GoalErrorObserver(small_env, count=4)
    end = np.array([[1.0, 0.0], [1.0, 0.0], [0.5, 0.0], [0.5, 0.0]])
    turns = np.array([True, False, True, False])

    class Probe:
        t = 0

        def base(self):  # behind world 0's object as seen from its goal, beside 1's, between 2's and its goal, 3's at 45 deg
            xy = [[-1.0, 0.0], [0.1, 2.0], [2.0, 0.0], [-0.95, -1.0]]  # the objects start at (0.1, 0) and (0.05, 0)
            return np.array([[x, y, 0.5, 0.0, 0.0, 0.0, 1.0] for x, y in xy])

        def object(self):
            share = self.t / steps
            poses = [np.concatenate([share * end[w], [0.35], yaw_quat(share * np.pi / 2 if turns[w] else 0.0)])
                     for w in range(4)]
            return np.array(poses)

    class Array:  # a Warp array's .numpy()
        def __init__(self, value):
            self.value = value

        def numpy(self):
            return self.value

    task = type("Task", (), {"goal_pos": Array(np.tile([1.0, 0.0, 0.35], (4, 1))),
                             "goal_quat": Array(np.tile(yaw_quat(np.pi / 2), (4, 1)))})()
    observer.env, observer.probe = type("Env", (), {"task": task})(), Probe()
    for step in range(steps):
        observer.probe.t = step + 1
        observer.observe(step, torch.ones(4, dtype=torch.bool), torch.tensor([True, True, True, step < 4]))
    np.testing.assert_allclose(observer.asked_distance, [0.9, 0.9, 0.95, 0.95], atol=1e-9)
    np.testing.assert_allclose(np.degrees(observer.asked_angle), [81.0, 90.0, 81.0, 90.0], atol=1e-6)
    np.testing.assert_allclose(observer.final_distance, [0.0, 0.0, 0.5, 0.8], atol=1e-9)  # world 3: after step 3
    np.testing.assert_allclose(np.degrees(observer.final_angle), [0.0, 90.0, 0.0, 90.0], atol=1e-5)

    episodes = FirstEpisodes(length=np.full(4, steps), success=np.array([True, False, False, False]),
                             toppled=np.zeros(4, dtype=bool), fallen=np.zeros(4, dtype=bool),
                             first_success_step=np.array([10, 0, 0, 0]), shape=np.zeros(4, dtype=int))
    summary = GoalErrorObserver.summary([observer], episodes, 0.1, np.radians(10.0))
    assert summary["outcome_percent"] == {"success": 25.0, "toppled": 0.0, "robot_fell": 0.0, "at_goal_rotation_off": 25.0,
                                          "rotation_right_away_from_goal": 25.0, "away_from_goal_rotation_off": 25.0}
    fell = GoalErrorObserver.summary([observer], dataclasses.replace(episodes, fallen=np.array([True, False, False, True])),
                                     0.1, np.radians(10.0))["outcome_percent"]  # a success that ends fallen stays one
    assert (fell["success"], fell["robot_fell"], fell["away_from_goal_rotation_off"]) == (25.0, 25.0, 0.0)
    assert summary["rotation_error_deg_at_goal_rotation_off"]["median"] == pytest.approx(90.0)
    rotation_bins = summary["success_by_goal_rotation_deg"]
    assert [(row["from"], row["episodes"]) for row in rotation_bins] == [(0.0, 0), (30.0, 2), (90.0, 2), (150.0, 0)]
    assert rotation_bins[1]["success_rate"] == 50.0 and rotation_bins[0]["success_rate"] is None
    assert [row["episodes"] for row in summary["success_by_goal_distance_m"]] == [0, 4, 0, 0]
    np.testing.assert_allclose(np.degrees(observer.start_side), [0.0, 90.0, 180.0, 45.0], atol=1e-6)
    side_bins = summary["success_by_start_side_deg"]
    assert [(row["from"], row["episodes"]) for row in side_bins] == [(0.0, 1), (45.0, 1), (90.0, 1), (135.0, 1)]
    assert [row["success_rate"] for row in side_bins] == [100.0, 0.0, 0.0, 0.0]


def test_start_side_is_nan_for_a_goal_on_the_object():
    from dynpush.policies.observers import start_side

    side = start_side(np.array([[-1.0, 0.0], [2.0, 0.0]]), np.zeros((2, 2)), np.array([[0.0, 0.0], [1.0, 1.0]]))
    assert np.isnan(side[0]) and np.degrees(side[1]) == pytest.approx(135.0)


def test_returns_to_go_of_hand_made_episodes():
    from types import SimpleNamespace

    from dynpush.policies.observers import RewardObserver

    gamma, rewards = 0.5, [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]
    in_episode = [[True, True], [True, False], [True, False]]  # world 1's first episode ends after step 0
    env = SimpleNamespace(num_envs=3, reward_names=("task", "reach"),
                          task=SimpleNamespace(reward_weights=SimpleNamespace(numpy=lambda: np.array([2.0, 1.0]))))
    observers = [RewardObserver(env, count=2)]  # world 2 is beyond the episodes asked for
    for step, (reward, inside) in enumerate(zip(rewards, in_episode)):
        env.reward_t = torch.tensor(reward + [100.0])
        env.reward_terms_t = torch.tensor([[r, 10.0 * r] for r in reward + [100.0]])
        observers[0].observe(step, torch.tensor(inside + [True]), None)
    world_0 = [1 + 0.5 * 3 + 0.25 * 5, 3 + 0.5 * 5, 5.0]
    assert sorted(observers[0].returns_to_go(gamma)) == pytest.approx(sorted(world_0 + [2.0]))
    summary = RewardObserver.summary(observers, gamma)
    assert summary["return_to_go"]["count"] == 4 and summary["return_to_go"]["mean"] == pytest.approx(
        (sum(world_0) + 2.0) / 4)
    assert summary["term_means_per_step"] == pytest.approx({"task": 11.0 / 4, "reach": 110.0 / 4})
    assert summary["weights"] == {"task": 2.0, "reach": 1.0}


def test_constraint_violation_is_the_mean_over_episodes_of_each_ones_share_of_time():
    """Table II: a group violated 10 of 100 steps in one episode and never in a 50-step one is violated 5 % of the time
    (the mean of the episodes' shares, not 10 of 150 pooled steps)."""
    from dynpush.kernels.push.constraints import CONSTRAINT_GROUPS
    from dynpush.policies.tables import ConstraintObserver

    groups = len(CONSTRAINT_GROUPS)
    violated_steps = np.zeros((2, groups), dtype=np.int64)
    violated_steps[0, 0], violated_steps[0, -1], violated_steps[1, -1] = 10, 100, 25
    percent = ConstraintObserver.percent_of_time(violated_steps, np.array([100, 50]))
    assert list(percent) == [name for name, _ in CONSTRAINT_GROUPS]
    assert percent[CONSTRAINT_GROUPS[0][0]] == pytest.approx(5.0)
    assert percent[CONSTRAINT_GROUPS[-1][0]] == pytest.approx(75.0)
    assert percent[CONSTRAINT_GROUPS[1][0]] == 0.0


def test_contact_motion_of_hand_made_trajectories(small_env):
    """Object at constant acceleration (3, 4) m/s^2, end-effector rising at 0.2 m/s, base heading 2.5 rad and
    moving at 0.3 m/s along it and 0.1 m/s across, commanded 0.45 m/s forward. World 0 touches throughout, world 1 touches but its episode restarts after step 2, world 2 never touches, world 3 is
    beyond the recorded count."""
    dt, steps = 0.02, 8
    observer = ContactMotionObserver(small_env, dt, count=3)

    class Probe:
        t = 0

        def object(self):
            xy = 0.5 * np.array([3.0, 4.0]) * (self.t * dt) ** 2 + np.array([0.1, -0.2])
            return np.tile(np.concatenate([xy, [0.3, 0, 0, 0, 1]]), (4, 1))

        def ee_position(self):
            return np.tile([0.0, 0.0, 0.1 + 0.2 * self.t * dt], (4, 1))

        def base(self):
            heading = 2.5
            forward, left = np.array([np.cos(heading), np.sin(heading)]), np.array([-np.sin(heading), np.cos(heading)])
            xy = (0.3 * forward + 0.1 * left) * self.t * dt
            return np.tile(np.concatenate([xy, [0.45, 0.0, 0.0, np.sin(heading / 2), np.cos(heading / 2)]]), (4, 1))

        def base_command(self):
            return np.tile([0.45, 0.1, 0.0, 0.0, 0.0, 0.45], (4, 1))

        def object_sliding_force(self):
            return np.array([20.0, 70.0, 40.0, 100.0])

    contact = torch.zeros(4, small_env.critic_obs_t.shape[1])
    contact[[0, 1, 3], EE_CONTACT_COLUMN] = 1.0
    observer.env, observer.probe = type("Env", (), {"critic_obs_t": contact})(), Probe()
    for step in range(steps):
        observer.probe.t = step + 1  # the state after the step
        continuing = torch.tensor([True, step != 2, True, True])
        observer.observe(step, torch.ones(4, dtype=torch.bool), continuing)
    samples = {name: ContactMotionObserver.pooled([observer], name) for name in ContactMotionObserver.SAMPLES}
    # World 0 from step 2 on (3 poses of its episode), world 1 from step 5 on (three steps after its restart).
    assert {len(v) for v in samples.values()} == {(steps - 2) + (steps - 5)}
    np.testing.assert_allclose(samples["ee_vertical_speed"], 0.2, rtol=1e-6)
    np.testing.assert_allclose(samples["object_acceleration"], 5.0, rtol=1e-6)
    np.testing.assert_allclose(samples["base_forward_speed"], 0.3, rtol=1e-6)
    np.testing.assert_allclose(samples["base_commanded_vx"], 0.45, rtol=0)
    np.testing.assert_array_equal(np.sort(samples["object_sliding_force"]), [20.0] * (steps - 2) + [70.0] * (steps - 5))
    bins = ContactMotionObserver.base_speed_by_sliding_force([observer])
    assert [row["count"] for row in bins] == [steps - 2, 0, steps - 5, 0]
    assert bins[0]["sliding_force_n"] == [0.0, 30.0] and bins[-1]["sliding_force_n"] == [90.0, None]
    assert bins[1]["commanded_vx_median"] is None and bins[1]["forward_speed_median"] is None
    assert bins[2]["commanded_vx_median"] == pytest.approx(0.45) and bins[2]["forward_speed_median"] == pytest.approx(0.3)


def test_object_sliding_force_is_mu_m_g_with_the_randomised_combined_friction(small_env):
    """The probe inverts the sampler's object coefficient (2 mu - floor): mu = F / (m g) lies in the task's range."""
    from dynpush.policies.env_probe import EnvProbe

    small_env.reset()  # sampled episodes: a test before may have started user-chosen ones of one friction
    force = EnvProbe(small_env).object_sliding_force()
    mu = force / (small_env.task.object_mass.numpy() * 9.81)
    low, high = small_env.cfg.randomization.friction
    assert force.shape == (small_env.num_envs,) and np.all((mu >= low - 1e-6) & (mu <= high + 1e-6))
    assert np.ptp(mu) > 0.05  # randomised, not one constant


def test_eval_counts_only_each_worlds_first_episode(policy, tmp_path):
    """Robots 'fall' at once (base below 1 m): every first episode lasts one step, later episodes are masked."""
    cfg = EvalConfig(episodes=4, num_envs=4, noise=False,
                     overrides=("env.episode_length_s=0.2", "env.terminations.base_min_height=1.0"))
    result = evaluate(policy, cfg, tmp_path)
    assert result["episode_length_s"]["max"] == pytest.approx(0.02)
    # One step per world: each group is violated in 0, 1, ... or 4 of the 4 counted steps.
    assert all(min(v % 25.0, 25.0 - v % 25.0) < 1e-9 for v in result["constraint_violation_percent"].values())
    assert result["success_rate"] == 0.0 and result["toppled_rate"] == 0.0
    assert result["config"]["env"]["noise"]["enabled"] is False
    with pytest.raises(ConfigError, match="env.field=value"):
        evaluate(policy, EvalConfig(episodes=4, overrides=("iterations=3",)), tmp_path)


def test_paper_row_follows_the_ablation_of_the_training_config():
    cfg = apply_overrides(TrainConfig(), ["env.sampling.reach_target_on_surface=False",
                                          "disabled_constraint_groups=('object_balance',)"])
    assert paper_table_i_row(cfg.to_dict())[1:] == (88.70, 7.73)
    assert paper_table_i_row(TrainConfig().to_dict())[1:] == (91.35, 3.46)


def test_face_of_the_end_effector_on_a_cuboid():
    dims = np.tile([0.6, 0.4, 0.5], (5, 1))
    ee_o = np.array([[0.35, 0.05, 0.0], [-0.33, 0.1, 0.1], [0.1, 0.25, 0.0], [0.2, -0.24, -0.2], [0.0, 0.0, 0.3]])
    assert [FACE_NAMES[f] if f != NO_FACE else None for f in contact_face(ee_o, dims)] == ["+x", "-x", "+y", "-y", None]


def test_face_switches_of_a_hand_made_contact_sequence():
    x_pos, x_neg, y_pos = (FACE_NAMES.index(n) for n in ("+x", "-x", "+y"))
    gap = NO_FACE
    faces = ([x_pos] * 5 + [gap] * 3 + [x_pos] * 4  # one face, broken contact: no switch
             + [y_pos] * 2 + [gap] + [y_pos] * 2  # grazing +y, never held 3 steps: no switch
             + [x_pos] * 2 + [x_neg] * 3  # to -x: switch 1
             + [gap] * 10 + [x_pos] * 3)  # back to +x after a gap: switch 2
    assert count_face_switches(faces, hold_steps=3) == 2
    assert count_face_switches(faces, hold_steps=1) == 4  # +x, +y, +x, -x, +x
    assert count_face_switches([gap] * 5, hold_steps=1) == 0


def valid_scenario() -> dict:
    return {"name": "t", "trials": 1, "goal_timeout_s": 0.1, "objects": [
        {"name": "box", "shape": "cuboid", "size": [0.5, 0.4, 0.6], "mass": 5.0, "friction": 0.8,
         "goals": [{"position": [0.0, 0.0]}, {"position": [0.0, 0.0], "yaw_change_deg": 0},
                   {"position": [1.5, 0.0], "yaw_change_deg": 90}]},
        {"name": "can", "shape": "cylinder", "size": [0.3, 0.4], "mass": 2.0, "friction": 0.8,
         "goals": [{"position": [1.0, 1.0]}], "paper": {"success_rate": 83.3}}]}


@pytest.mark.parametrize("edit, field", [
    (lambda d: d["objects"][0].update(mass=-1.0), r"t\.objects\[0\]\.mass"),
    (lambda d: d["objects"][0].update(sise=[1, 1, 1]), r"t\.objects\[0\]\.sise is not a known field"),
    (lambda d: d["objects"][1].update(size=[0.3, 0.3, 0.4]), r"t\.objects\[1\]\.size of a cylinder must be 2 lengths"),
    (lambda d: d["objects"][0]["goals"][1].update(position=[1.0]), r"t\.objects\[0\]\.goals\[1\]\.position"),
    (lambda d: d["objects"][0].update(shape="sphere"), r"t\.objects\[0\]\.shape must be one of"),
    (lambda d: d["objects"][0].pop("friction"), r"t\.objects\[0\]\.friction is required"),
    (lambda d: d.update(trials=2.5), r"t\.trials must be an integer"),
    (lambda d: d["objects"][1].update(name="box"), r"t\.objects\[\]\.name must be unique"),
    (lambda d: d["objects"][1]["paper"].update(success=1), r"t\.objects\[1\]\.paper\.success is not a known field"),
])
def test_scenario_errors_name_the_field(edit, field):
    data = valid_scenario()
    edit(data)
    with pytest.raises(ConfigError, match=field):
        parse_scenario(data, where="t")


def test_example_scenario_files_are_valid():
    from pathlib import Path

    files = sorted((Path(__file__).parents[1] / "scenarios").glob("*.yaml"))
    assert files
    for path in files:
        scenario = load_scenario(path)
        assert scenario.objects and all(o.goals for o in scenario.objects)


def test_scenario_runs_goal_sequences(policy, tmp_path, capsys):
    """``dynpush scenario``: goals at the object's own pose succeed at once and the next goal follows; an unreachable
    one times out."""
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump(valid_scenario()))
    assert main(["scenario", str(policy), str(path), "--out", str(tmp_path), "--no-noise"]) == 0
    assert f"wrote {tmp_path / 'scenario.json'} and {tmp_path / 'scenario.png'}" in capsys.readouterr().out
    result = json.loads((tmp_path / "scenario.json").read_text())
    box = [(g["goal"], g["outcome"]) for g in result["goals"] if g["object"] == "box"]
    assert box == [(0, "success"), (1, "success"), (2, "timeout")]
    assert result["goals"][0]["time_s"] == pytest.approx(0.02)
    assert result["objects"]["box"]["success_rate"] == pytest.approx(200 / 3)
    assert result["objects"]["box"]["face_switches_per_goal"] == 0.0
    assert result["objects"]["can"]["face_switches_per_goal"] is None
    assert result["objects"]["can"]["outcomes"]["timeout"] == 1
    assert is_png(tmp_path / "scenario.png") and (tmp_path / "scenario.json").exists()


def test_scenario_friction_below_half_the_floor_is_refused_before_anything_is_written(policy, tmp_path, capsys):
    data = valid_scenario()
    data["objects"][1].update(friction=0.1)
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    assert main(["scenario", str(policy), str(path), "--out", str(out)]) == 2
    assert "t.objects[1].friction must be >= 0.2 (half the floor's coefficient in ground.usda), got 0.1" in (
        capsys.readouterr().err)
    assert not out.exists()


def test_footprint_study_on_a_tiny_setting(policy, tmp_path):
    """Goal at the object's start pose: every episode succeeds, so the study completes."""
    cfg = FootprintConfig(sides=(0.3, 0.6), successful_episodes=3, max_rounds=2, num_envs=2,
                          overrides=("env.episode_length_s=0.2", "env.sampling.goal_radius=(0.0, 0.0)",
                                     "env.sampling.object_yaw=(0.0, 0.0)", "env.sampling.goal_yaw=(0.0, 0.0)"))
    result = footprint_study(policy, cfg, tmp_path)
    rows = result["footprints"]
    assert [r["side_m"] for r in rows] == [0.3, 0.6]
    assert all(r["successful_episodes"] == 3 and r["episodes"] == 4 for r in rows)
    assert "count" in rows[0]["ee_height_in_contact_m"]
    assert json.loads((tmp_path / "footprints.json").read_text())["config"]["sides"] == [0.3, 0.6]
    assert is_png(tmp_path / "footprints.png")


def test_footprints_command_collects_the_episodes_of_every_footprint(policy, tmp_path, capsys):
    """``dynpush footprints`` with goals at the object's start pose: one round per footprint completes the study."""
    assert main(["footprints", str(policy), "--episodes-per-footprint", "2", "--num-envs", "2", "--out", str(tmp_path),
                 "--set", "env.episode_length_s=0.2", "env.sampling.goal_radius=(0.0, 0.0)",
                 "env.sampling.object_yaw=(0.0, 0.0)", "env.sampling.goal_yaw=(0.0, 0.0)"]) == 0
    saved = json.loads((tmp_path / "footprints.json").read_text())
    assert saved["config"]["successful_episodes"] == 2 and saved["config"]["num_envs"] == 2
    assert [row["successful_episodes"] for row in saved["footprints"]] == [2] * len(FootprintConfig().sides)
    assert f"wrote {tmp_path / 'footprints.json'} and {tmp_path / 'footprints.png'}" in capsys.readouterr().out


def test_play_writes_a_picture_and_a_usd_animation(policy, tmp_path):
    from pxr import Usd, UsdGeom

    png, usd = tmp_path / "play.png", tmp_path / "play.usda"
    assert main(["play", str(policy), "--episodes", "2", "--out", str(png), "--usd", str(usd),
                 "--set", "env.episode_length_s=0.2"]) == 0
    assert is_png(png)
    rows = json.loads(png.with_suffix(".json").read_text())["episodes"]
    assert len(rows) == 2 and all(r["length_s"] <= 0.2 + 1e-9 for r in rows)
    stage = Usd.Stage.Open(str(usd))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert stage.GetEndTimeCode() == 10  # 0.2 s at 50 frames per second
    animated = [a for p in stage.Traverse() for a in p.GetAttributes() if a.GetNumTimeSamples() > 1]
    assert animated


def test_legged_evaluation_of_a_tracked_base_policy_uses_todays_legged_settings(tmp_path):
    """A policy trained on the tracked base carries the legged-mode section of its time in its training config;
    evaluating it in legged mode must not inherit those simulator buffers (24 / 64 dropped contacts)."""
    from dynpush.policies.onnx_policy import OnnxPolicy
    from dynpush.policies.trained_env import env_config_for
    from dynpush.sim.config import LeggedModeConfig

    run = tmp_path / "old"
    run.mkdir()
    cfg = apply_overrides(TrainConfig.preset_config("cpu"), ["network.actor_hidden=(16, 16)"])
    saved = cfg.to_dict()
    saved["env"]["legged"]["mujoco"] |= {"nconmax": 24, "njmax": 64}
    (run / "config.json").write_text(json.dumps(saved))
    torch.save({"actor_state_dict": build_actor(cfg).state_dict()}, run / "model_0.pt")
    policy = OnnxPolicy(export_policy(run))
    with pytest.raises(ConfigError, match="env.legged.locomotion_policy must name a locomotion.onnx in legged mode"):
        env_config_for(policy, num_envs=2, overrides=["env.legged.enabled=True"])
    env_cfg = env_config_for(policy, num_envs=2, overrides=["env.legged.enabled=True"], legs_from_outside=True)
    assert env_cfg.legged.enabled and env_cfg.legged.mujoco == LeggedModeConfig().mujoco
