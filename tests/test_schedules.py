"""Training schedules: the push task's p_max curricula and reach-reward weight (Table "Rewards and constraints"),
the locomotion task's disturbance ramp."""

import pytest
import torch

from dynpush.policies.locomotion_train import LocomotionTrainConfig
from dynpush.policies.overrides import apply_overrides
from dynpush.policies.schedules import (CONSTRAINT_GROUPS, DisturbanceRampConfig, ScheduleConfig, disturbance_scale_at,
                                        p_max_at, p_max_at_progress, reach_weight_at)
from dynpush.policies.train import TrainConfig
from dynpush.sim.config import ConfigError

torch.set_num_threads(1)

PAPER = {  # Table "Rewards and constraints": (dim, initial p_max, final p_max)
    "base_command": (6, 0.01, 0.2),
    "arm_command": (5, 0.05, 0.9),
    "arm_action_rate": (5, 0.0, 0.05),
    "arm_joint_position": (5, 0.05, 0.9),
    "arm_joint_velocity": (5, 0.05, 0.9),
    "arm_joint_torque": (5, 0.0, 0.015),
    "leg_joint_torque": (12, 0.0, 0.01),
    "collision": (18, 1.0, 1.0),
    "object_balance": (1, 0.25, 0.25),
}


def _expected(progress: float) -> torch.Tensor:
    values = []
    for _, (dim, initial, final) in PAPER.items():
        values += [initial + (final - initial) * progress] * dim
    return torch.tensor(values)


def _group(p_max: torch.Tensor, name: str) -> torch.Tensor:
    start = 0
    for group, dim in CONSTRAINT_GROUPS:
        if group == name:
            return p_max[start : start + dim]
        start += dim
    raise KeyError(name)


def test_groups_match_paper_table():
    assert [(name, dim) for name, (dim, _, _) in PAPER.items()] == list(CONSTRAINT_GROUPS)
    assert sum(dim for _, dim in CONSTRAINT_GROUPS) == 62


def test_paper_run_endpoints_and_midpoints():
    total = 20000
    torch.testing.assert_close(p_max_at(0, total), _expected(0.0))
    torch.testing.assert_close(p_max_at(12000, total), _expected(1.0))
    torch.testing.assert_close(p_max_at(19999, total), _expected(1.0))
    torch.testing.assert_close(p_max_at(6000, total), _expected(0.5))
    torch.testing.assert_close(p_max_at(3000, total), _expected(0.25))
    mid = _group(p_max_at(6000, total), "arm_command")
    torch.testing.assert_close(mid, torch.full((5,), 0.475))
    for it in (0, 6000, 20000):  # no curriculum for collisions and object balance
        assert torch.all(_group(p_max_at(it, total), "collision") == 1.0)
        assert torch.all(_group(p_max_at(it, total), "object_balance") == 0.25)


def test_p_max_at_progress_goes_from_initial_to_final_and_clips():
    for progress in (0.0, 0.3, 1.0):
        torch.testing.assert_close(p_max_at_progress(progress), _expected(progress))
    torch.testing.assert_close(p_max_at_progress(-0.5), _expected(0.0))
    torch.testing.assert_close(p_max_at_progress(1.5), _expected(1.0))


def test_short_run_scales_with_length():
    total = 2000  # ramp over 1200 iterations, w2 switch at 150
    torch.testing.assert_close(p_max_at(600, total), _expected(0.5))
    torch.testing.assert_close(p_max_at(1200, total), _expected(1.0))
    torch.testing.assert_close(p_max_at(300, total), _expected(0.25))
    assert reach_weight_at(149, total) == 1.25
    assert reach_weight_at(150, total) == pytest.approx(1.25 / 4)


def test_paper_absolute_iterations_flag():
    cfg = ScheduleConfig(scale_with_run_length=False)
    torch.testing.assert_close(p_max_at(600, 2000, cfg), _expected(0.05))
    assert reach_weight_at(1499, 2000, cfg) == 1.25
    assert reach_weight_at(1500, 2000, cfg) == pytest.approx(0.3125)


def test_long_run_keeps_paper_iterations():
    torch.testing.assert_close(p_max_at(6000, 40000), _expected(0.5))
    assert reach_weight_at(1500, 40000) == pytest.approx(0.3125)


def test_reach_weight_switch_paper_run():
    assert reach_weight_at(0, 20000) == 1.25
    assert reach_weight_at(1499, 20000) == 1.25
    assert reach_weight_at(1500, 20000) == pytest.approx(0.3125)
    assert reach_weight_at(19999, 20000) == pytest.approx(0.3125)


def test_from_dict_overrides_and_custom_groups():
    cfg = ScheduleConfig.from_dict(
        {"constraints": {"p_max": {"a": [0.0, 1.0]}, "ramp_iterations": 10}, "reach": {"weight": 2.0}}
    )
    assert cfg.scale_with_run_length and cfg.paper_iterations == 20000
    torch.testing.assert_close(p_max_at(5, 20000, cfg, groups=[("a", 2)]), torch.tensor([0.5, 0.5]))
    assert reach_weight_at(0, 20000, cfg) == 2.0


def test_disturbance_ramp():
    ramp = DisturbanceRampConfig(start_iteration=100, end_iteration=300)
    assert [disturbance_scale_at(i, ramp) for i in (0, 99, 100, 200, 250, 299, 300, 5000)] == \
        [0.0, 0.0, 0.0, 0.5, 0.75, pytest.approx(0.995), 1.0, 1.0]
    assert disturbance_scale_at(0, DisturbanceRampConfig()) == 1.0, "(0, 0): full disturbances from the start"
    assert ScheduleConfig.from_dict({"disturbance": {"start_iteration": 1, "end_iteration": 2}}).disturbance == \
        DisturbanceRampConfig(1, 2)
    assert ScheduleConfig.from_dict({}).disturbance is None


def test_disturbance_ramp_in_the_locomotion_config():
    cfg = LocomotionTrainConfig(disturbance_ramp=(300, 600)).validate()
    assert ScheduleConfig.from_dict(cfg.runner_cfg()["schedule"]).disturbance == DisturbanceRampConfig(300, 600)
    with pytest.raises(ConfigError, match=r"disturbance_ramp must be \(start, end\) iterations with 0 <= start <= end"):
        LocomotionTrainConfig(disturbance_ramp=(600, 300)).validate()
    old_run = cfg.to_dict()
    del old_run["disturbance_ramp"]
    old_run["env"]["randomization"]["arm_amplitude"] = 0.8
    del old_run["p_max"]["foot_contact_force"]
    del old_run["env"]["rewards"]["action_rate_weight"]
    del old_run["env"]["randomization"]["ee_force_max"]
    old = LocomotionTrainConfig.from_dict(old_run)
    assert old.p_max["foot_contact_force"] == (0.0, 0.0) and "foot_contact_force" not in old_run["p_max"], \
        "runs from before the foot contact force constraint never terminated on it"
    assert old_run["env"]["randomization"]["arm_amplitude"] == 0.8, "the saved config it read is left unchanged"
    assert old.disturbance_ramp == (0, 0), "runs from before the ramp had it off"
    assert old.env.randomization.arm_amplitude == (0.8,) * 5, "and one arm amplitude for all joints"
    assert cfg.env.rewards.action_rate_weight > 0.0 and old.env.rewards.action_rate_weight == 0.0, \
        "runs from before the action-rate penalty had none"
    assert "action_rate_weight" not in old_run["env"]["rewards"]
    assert cfg.env.randomization.ee_force_max > 0.0 and old.env.randomization.ee_force_max == 0.0, \
        "runs from before the end-effector forces had none"
    assert "ee_force_max" not in old_run["env"]["randomization"]


def test_the_trained_reach_weight_is_the_environments():
    """The runner's schedule starts from ``env.rewards.reach_weight``, not from a default of its own."""
    cfg = apply_overrides(TrainConfig(), ["env.rewards.reach_weight=0.0", "iterations=100"])
    schedule = ScheduleConfig.from_dict(cfg.runner_cfg()["schedule"])
    assert [reach_weight_at(it, 100, schedule) for it in (0, 99)] == [0.0, 0.0]
    cfg = apply_overrides(TrainConfig(), ["env.rewards.reach_weight=2.0", "iterations=20000"])
    schedule = ScheduleConfig.from_dict(cfg.runner_cfg()["schedule"])
    assert [reach_weight_at(it, 20000, schedule) for it in (1499, 1500)] == [2.0, 0.5]
