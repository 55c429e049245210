"""PushEnv as an rsl_rl VecEnv: shapes, zero-copy views, episodes, contacts, success, bad input."""

import math

import numpy as np
import pytest
import torch

from dynpush.sim.config import ConfigError, PushEnvConfig, RandomizationConfig, SimConfig
from dynpush.sim.episode import EpisodeSpec
from dynpush.sim.push_env import PushEnv


def test_vecenv_interface_and_zero_copy(small_env):
    env = small_env
    obs = env.reset()
    assert obs["policy"].shape == (4, 54) and obs["critic"].shape == (4, 63)
    assert obs["policy"].dtype == torch.float32
    obs, reward, dones, extras = env.step(torch.zeros(4, 11))
    assert reward.shape == (4,) and dones.shape == (4,)
    assert extras["time_outs"].dtype == torch.bool
    assert extras["constraints"].shape == (4, sum(size for _, size in env.constraint_groups)) == (4, 62)
    # zero-copy: the torch views are the Warp buffers; observations handed out are copies, since the
    # trainer holds on to the observation it acted on while the next step overwrites the buffer
    assert env.policy_obs_t.data_ptr() == env.policy_obs.ptr
    assert extras["constraints"].data_ptr() == env.constraints.ptr
    before = obs["policy"].clone()
    env.step(torch.ones(4, 11))
    assert torch.equal(obs["policy"], before)
    # critic = noiseless policy terms (without the last actions) + privileged terms: noise makes them differ, but
    # only by the table's widths
    assert (obs["policy"][:, :43] - obs["critic"][:, :43]).abs().max() <= 0.5 + 1e-6


def test_the_critic_reads_no_sampled_action(small_env):
    """Regression: the critic's input holds every critic term but the previous (sampled) action, whose noise a
    critic otherwise credits with the value of a state (kernels/push/observations.py); the actor still reads it."""
    env = small_env
    env.reset()
    actions = torch.linspace(-0.9, 0.9, 44).reshape(4, 11)  # distinct, within every clip
    obs, _, _, _ = env.step(actions)
    assert torch.equal(obs["policy"][:, 43:54], actions)
    columns = [c for c in range(74) if c not in range(43, 54)]
    assert torch.equal(obs["critic"], env.critic_obs_t[:, columns])
    for a in actions.flatten():
        assert not (obs["critic"] == a).any(), "a sampled action reached the critic's input"


def test_the_critic_reads_whether_the_object_is_at_its_goal():
    """The critic's last input applies the success rule to the state it observes: it equals the step's success flag
    except where a world started a new episode. A run started before the critic read it keeps its 62 inputs."""
    cfg = PushEnvConfig(num_envs=16, seed=2)
    cfg.sampling.goal_radius, cfg.sampling.object_yaw, cfg.sampling.goal_yaw = (0.0, 0.1), (0.0, 0.0), (-0.6, 0.6)
    env = PushEnv(cfg)
    env.reset()
    generator = torch.Generator().manual_seed(0)
    seen = []
    for _ in range(20):
        obs, _, dones, _ = env.step(0.3 * torch.randn(16, 11, generator=generator))
        at_goal = obs["critic"][:, -1]
        assert ((at_goal == env.success_t.float()) | dones.bool()).all()
        seen.append(at_goal)
    assert 0.0 < torch.cat(seen).mean() < 1.0, "objects at their goals and beside them"
    before = PushEnv(PushEnvConfig(num_envs=2, critic_reads_object_at_goal=False))
    assert before.get_observations()["critic"].shape == (2, 62)
    with pytest.raises(ConfigError, match="critic_reads_object_at_goal must be True or False"):
        PushEnvConfig(critic_reads_object_at_goal=1).validate()


def test_a_state_saved_before_object_at_goal_continues_exactly(small_env):
    """An environment state that an older version saved (the critic buffer one column short, without
    ``object_at_goal``) loads: the saved columns as they were, the new one 0, and the steps that follow are those of
    the full state."""
    env = small_env
    env.reset()
    env.step(torch.zeros(4, 11))
    state = env.state_dict()
    older = dict(state, critic_obs=state["critic_obs"][:, :-1])
    assert env.state_mismatch(older) is None
    actions = 0.5 * torch.randn(4, 11, generator=torch.Generator().manual_seed(3))
    env.load_state_dict(older)
    np.testing.assert_array_equal(env.critic_obs.numpy()[:, :-1], state["critic_obs"][:, :-1])
    assert (env.critic_obs.numpy()[:, -1] == 0.0).all()
    obs_older, reward_older, dones_older, _ = env.step(actions)
    env.load_state_dict(state)
    obs_full, reward_full, dones_full, _ = env.step(actions)
    assert torch.equal(obs_older["policy"], obs_full["policy"]) and torch.equal(obs_older["critic"], obs_full["critic"])
    assert torch.equal(reward_older, reward_full) and torch.equal(dones_older, dones_full)
    assert "critic_obs" in env.state_mismatch(dict(state, critic_obs=state["critic_obs"][:, :-2]))


def test_time_out_resets_and_reports(tmp_path):
    env = PushEnv(PushEnvConfig(num_envs=2, episode_length_s=0.2, seed=3))
    env.set_episodes({0: EpisodeSpec(base=(-2.0, 0.0, 0.0)), 1: EpisodeSpec(base=(-2.0, 0.0, 0.0))})
    for step in range(1, 11):
        _, _, dones, extras = env.step(torch.zeros(2, 11))
        if step < 10:
            assert not dones.any()
    assert dones.all() and extras["time_outs"].all()
    assert (env.episode_length_buf == 0).all()  # a new episode started inside the same step
    assert extras["log"]["/episode/success"].shape == (2,)


def test_success_gives_task_reward_two(small_env):
    env = small_env
    # Object already at its goal (same position and yaw): success from the first step.
    env.set_episodes({w: EpisodeSpec(goal=(0.0, 0.0, 0.3), object_yaw=0.3, base=(-2.2, 0.0, 0.0)) for w in range(4)})
    env.step(torch.zeros(4, 11))
    assert (env.success_t == 1).all()
    np.testing.assert_allclose(env.reward_terms_t[:, 0].numpy(), 2.0)  # r1 = 2 on success
    np.testing.assert_allclose(env.reward_terms_t[:, 2].numpy(), 0.0)  # r3 = 0 on success
    # 8 cm away and 8 deg off: still success; 12 cm away: not.
    env.set_episodes({0: EpisodeSpec(goal=(0.08, 0.0, math.radians(8.0)), base=(-2.2, 0.0, 0.0)),
                      1: EpisodeSpec(goal=(0.12, 0.0, 0.0), base=(-2.2, 0.0, 0.0)),
                      2: EpisodeSpec(goal=(0.0, 0.0, math.radians(12.0)), base=(-2.2, 0.0, 0.0))})
    env.step(torch.zeros(4, 11))
    assert env.success_t[:3].tolist() == [1, 0, 0]


def test_contacts_end_effector_and_base_collision(small_env):
    env = small_env
    up = (0.0, 0.0, 0.0, 0.0, 0.0)  # arm straight up: the base meets the object first
    env.set_episodes({0: EpisodeSpec(base=(-1.3, 0.0, 0.0)), 1: EpisodeSpec(base=(-0.8, 0.0, 0.0), arm_q=up),
                      2: EpisodeSpec(base=(-2.4, 0.0, 0.0)), 3: EpisodeSpec(base=(-2.4, 0.0, 0.0))})
    actions = torch.zeros(4, 11)
    actions[:2, 0] = 0.3  # forward at 0.3 m/s
    arm_default = torch.tensor(env.scene.robot.arm_default[:5], dtype=torch.float32)
    actions[1, 6:] = -arm_default / env.cfg.actions.arm_scale
    ee_contact, collisions = np.zeros(4, bool), np.zeros((4, 18), bool)
    for _ in range(150):
        obs, _, _, extras = env.step(actions)
        ee_contact |= env.critic_obs_t[:, 54].numpy() > 0.5
        collisions |= extras["constraints"][:, 43:61].numpy() > 0.5
    assert ee_contact[0] and not collisions[0].any(), "the end-effector reaches the object first, without collisions"
    assert collisions[1, :9].any(), "driving into the object with the arm up hits the base or a leg"
    assert not ee_contact[2:].any() and not collisions[2:].any(), "robots far away touch nothing"


def test_a_step_that_ends_a_contact_violates_nothing():
    """Contacts are those of the state a step ends in (``env.constraints.contacts_at_step_end``), so the step whose
    action leaves a contact is no collision; counted over the substeps (runs started before the field), it is one,
    since its first substep starts in contact whatever the action. The physics is the same either way."""
    collided, observations = {}, {}
    for at_step_end in (False, True):
        cfg = PushEnvConfig(num_envs=1, seed=1)
        cfg.constraints.contacts_at_step_end = at_step_end
        env = PushEnv(cfg)
        env.set_episodes({0: EpisodeSpec(base=(-0.8, 0.0, 0.0), arm_q=(0.0,) * 5)})  # arm up: the base meets the box
        actions = torch.zeros(1, 11)
        actions[0, 6:] = -torch.tensor(env.scene.robot.arm_default[:5], dtype=torch.float32) / cfg.actions.arm_scale
        steps = []
        for t in range(130):
            actions[0, 0] = 0.3 if t < 100 else -1.0  # drive into the object, then back off at full speed
            obs, _, _, extras = env.step(actions)
            steps.append(bool((extras["constraints"][0, 43:61] > 0.5).any()))
        collided[at_step_end], observations[at_step_end] = np.array(steps), obs["critic"]
    assert torch.equal(observations[False], observations[True])
    at_end, over_substeps = np.flatnonzero(collided[True]), np.flatnonzero(collided[False])
    assert 20 < len(at_end) and at_end[0] == over_substeps[0] and at_end[-1] >= 100, "one contact while pushing"
    assert np.array_equal(over_substeps, np.append(at_end, at_end[-1] + 1)), "the step that leaves it differs"


def test_same_seed_same_rollout():
    def rollout(seed):
        env = PushEnv(PushEnvConfig(num_envs=3, seed=seed))
        generator = torch.Generator().manual_seed(0)
        for _ in range(20):
            obs, reward, _, _ = env.step(torch.randn(3, 11, generator=generator))
        return obs["policy"].clone(), reward.clone()

    a, b, c = rollout(5), rollout(5), rollout(6)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    assert not torch.equal(a[0], c[0])


@pytest.mark.parametrize(
    "cfg, field",
    [
        (PushEnvConfig(device="tpu"), "device"),
        (PushEnvConfig(num_envs=0), "num_envs"),
        (PushEnvConfig(sim=SimConfig(solver="bullet")), "sim.solver"),
        (PushEnvConfig(sim=SimConfig(substeps=3)), "sim.substeps"),
        (PushEnvConfig(randomization=RandomizationConfig(mass=(10.0, 1.0))), "randomization.mass"),
        (PushEnvConfig(randomization=RandomizationConfig(size_x=(-0.5, 0.75))), "randomization.size_x"),
    ],
)
def test_invalid_config_names_the_field(cfg, field):
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        cfg.validate()


def test_friction_range_below_half_the_floor_is_refused():
    with pytest.raises(ConfigError, match=r"randomization\.friction\[0\] must be >= 0\.2 \(half the floor's"):
        PushEnv(PushEnvConfig(num_envs=1, randomization=RandomizationConfig(friction=(0.1, 1.0))))


def test_invalid_episode_names_the_field(small_env):
    with pytest.raises(ConfigError, match="episode.shape"):
        small_env.set_episodes({0: EpisodeSpec(shape="sphere")})
    with pytest.raises(ConfigError, match="episode.dims"):
        small_env.set_episodes({0: EpisodeSpec(dims=(0.5, -0.5, 0.7))})
    with pytest.raises(ConfigError, match="episode.friction"):
        small_env.set_episodes({0: EpisodeSpec(friction=0.1)})
    with pytest.raises(IndexError, match="world index"):
        small_env.set_episodes({7: EpisodeSpec()})


def test_set_goals_keeps_the_bodies_and_restarts_the_clock(small_env):
    env = small_env
    env.set_episodes({w: EpisodeSpec(base=(-2.2, 0.0, 0.0)) for w in range(4)})
    for _ in range(5):
        env.step(torch.zeros(4, 11))
    bodies = env.state_0.body_q.numpy().copy()
    obs = env.set_goals({1: (0.0, 0.0, 0.0)})  # the object, at rest at the origin, meets this goal
    np.testing.assert_array_equal(env.state_0.body_q.numpy(), bodies)
    assert env.episode_length_buf.tolist() == [5, 0, 5, 5]
    np.testing.assert_allclose(env.critic_obs_t[1, 31:34].numpy(), 0.0, atol=0.01)  # object-to-goal in the base frame
    env.step(torch.zeros(4, 11))
    assert env.success_t.tolist()[1] == 1
    with pytest.raises(ConfigError, match="goal of world 0"):
        env.set_goals({0: (0.0, float("nan"), 0.0)})


def test_episode_metrics_report_the_fraction_of_violated_steps():
    env = PushEnv(PushEnvConfig(num_envs=2, episode_length_s=0.2, seed=3))
    env.set_episodes({0: EpisodeSpec(base=(-2.0, 0.0, 0.0)), 1: EpisodeSpec(base=(-2.0, 0.0, 0.0))})
    actions = torch.zeros(2, 11)
    actions[0, 0] = 5.0  # vx command 5 m/s: beyond the base command limit (1 m/s) in every step
    for _ in range(10):
        _, _, _, extras = env.step(actions)
    log = extras["log"]
    assert log["/episode/violated/base_command"].tolist() == [1.0, 0.0]
    assert log["/episode/violated/collision"].tolist() == [0.0, 0.0]


def test_step_commands_is_step_on_the_mapped_actions(small_env):
    """``step_commands`` with the commands that the action mapping (``dynpush.runtime.actions``) makes of some actions
    is ``step`` on those actions, from the same state: observations, rewards and constraints (sim-to-sim hands the
    runtime's commands to the environment this way, without inverting the mapping)."""
    env = small_env
    env.reset()
    start = env.state_dict()
    generator = torch.Generator().manual_seed(7)
    actions = [1.5 * torch.randn(4, 11, generator=generator) for _ in range(4)]  # some beyond the clip
    stepped = []
    for a in actions:
        obs, reward, dones, extras = env.step(a)
        stepped.append((obs["policy"], obs["critic"], reward, dones, extras["constraints"].clone()))
    env.load_state_dict(start)
    for a, expected in zip(actions, stepped):
        base_command, arm_targets = env.action_mapping.commands(a.numpy())
        obs, reward, dones, extras = env.step_commands(base_command, arm_targets, a)
        got = (obs["policy"], obs["critic"], reward, dones, extras["constraints"])
        for x, y in zip(got, expected):
            torch.testing.assert_close(x, y, rtol=1e-4, atol=1e-4)
        torch.testing.assert_close(env.task.base_command.numpy(), base_command.astype(np.float32))
    # without the policy's actions, the commands still go where the mapping writes its own; the history records zeros
    base_command, arm_targets = env.action_mapping.commands(actions[0].numpy())
    obs, _, _, _ = env.step_commands(base_command, arm_targets)
    torch.testing.assert_close(env.task.arm_command.numpy(), arm_targets.astype(np.float32))
    assert not obs["policy"][:, 43:54].any()
    with pytest.raises(ValueError, match="finite"):
        env.step_commands(np.full((4, 6), np.nan), arm_targets)


def test_the_robot_receives_what_the_runtime_sends(small_env):
    """Commands beyond their limits move the robot as the runtime's clamped commands do: ``step`` on actions and
    ``step_commands`` on the commands the runtime's safety layer sends for them (clamped to the exported contract's
    limits) give the same observations and rewards; the constraints still judge the commands as asked."""
    from dynpush.policies.export import build_contract
    from dynpush.policies.train import TrainConfig
    from dynpush.runtime.safety import CommandLimits

    env = small_env
    contract = build_contract(TrainConfig(env=env.cfg))
    limits = CommandLimits(np.array(contract.base_command_lower), np.array(contract.base_command_upper),
                           np.array(contract.arm_joint_lower), np.array(contract.arm_joint_upper), np.zeros(0), np.zeros(0))
    env.reset()
    start = env.state_dict()
    generator = torch.Generator().manual_seed(8)
    actions = [2.0 * torch.randn(4, 11, generator=generator) for _ in range(6)]
    stepped = []
    for a in actions:
        obs, reward, _, extras = env.step(a)
        stepped.append((obs["critic"], reward, extras["constraints"][:, :11].clone()))
    env.load_state_dict(start)
    clamped = 0
    for a, (critic, reward, asked_violations) in zip(actions, stepped):
        base_command, arm_targets = env.action_mapping.commands(a.numpy())
        sent_base, sent_arm = base_command.copy(), arm_targets.copy()
        for row in range(4):
            assert limits.clamp(sent_base[row], sent_arm[row], np.zeros(0)) is None
        clamped += int((sent_base != base_command).any(axis=1).sum() + (sent_arm != arm_targets).any(axis=1).sum())
        obs, got_reward, _, extras = env.step_commands(sent_base, sent_arm, a)
        torch.testing.assert_close(obs["critic"], critic, rtol=1e-4, atol=1e-4)
        torch.testing.assert_close(got_reward, reward, rtol=1e-4, atol=1e-4)
        assert (asked_violations > 0).any() and not (extras["constraints"][:, :11] > 0).any()
    assert clamped > 0


def test_a_diverged_world_ends_its_episode_and_starts_afresh():
    """A non-finite velocity in one world's object (a diverged solver) ends that world's episode as diverged, a
    failure that is not a time-out, and its next episode starts from finite state: the observations stay finite
    (rsl_rl stops a run on a NaN observation) and the other world runs on."""
    env = PushEnv(PushEnvConfig(num_envs=2, seed=3))
    env.reset()
    env.step(torch.zeros(2, 11))
    body_qd = env.state_0.body_qd.numpy()
    body_qd[int(env.object_body.numpy()[1])] = np.nan
    env.state_0.body_qd.assign(body_qd)
    _, _, dones, extras = env.step(torch.zeros(2, 11))
    assert dones.tolist() == [False, True] and not extras["time_outs"].any()
    assert extras["log"]["/episode/diverged"].tolist() == [1.0]
    assert extras["log"]["/episode/success"].tolist() == [0.0]
    for _ in range(3):
        obs, _, dones, _ = env.step(torch.zeros(2, 11))
        assert not dones.any()
    assert all(bool(torch.isfinite(obs[key]).all()) for key in obs.keys())
