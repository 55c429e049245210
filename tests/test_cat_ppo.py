"""CaT-PPO (Constraints as Terminations) on rsl_rl 5.5: returns, CaT state, checkpoints and the runner."""

import copy
import os

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from rsl_rl.algorithms import PPO
from rsl_rl.env import VecEnv

from dynpush.policies.cat_ppo import CaTPPO, explained_variance
from dynpush.policies.progress import read_progress
from dynpush.policies.runner import CaTOnPolicyRunner
from dynpush.policies.schedules import CONSTRAINT_GROUPS, p_max_at

torch.set_num_threads(1)


class FakePushEnv(VecEnv):
    """Random stand-in for the push environment: obs groups "policy" (54) and "critic" (73), 11 actions."""

    def __init__(self, num_envs=8, episode_length=3, groups=CONSTRAINT_GROUPS, violation_shift=-0.5, seed=0):
        self.num_envs = num_envs
        self.num_actions = 11
        self.max_episode_length = episode_length
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long)
        self.device = "cpu"
        self.cfg = {}
        self.constraint_groups = list(groups)
        self.violation_shift = violation_shift
        self.generator = torch.Generator().manual_seed(seed)
        self.reward_weights = []

    def _randn(self, *shape):
        return torch.randn(*shape, generator=self.generator)

    def state_dict(self):
        return {"generator": self.generator.get_state(), "episode_length_buf": self.episode_length_buf.clone()}

    def state_mismatch(self, state):
        return None if len(state["episode_length_buf"]) == self.num_envs else "other num_envs"

    def load_state_dict(self, state):
        self.generator.set_state(state["generator"])
        self.episode_length_buf.copy_(state["episode_length_buf"])

    def get_observations(self):
        n = self.num_envs
        return TensorDict({"policy": self._randn(n, 54), "critic": self._randn(n, 73)}, batch_size=[n])

    def step(self, actions):
        self.episode_length_buf += 1
        time_outs = self.episode_length_buf >= self.max_episode_length
        terminated = torch.rand(self.num_envs, generator=self.generator) < 0.1
        dones = time_outs | terminated
        self.episode_length_buf[dones] = 0
        num_constraints = sum(dim for _, dim in self.constraint_groups)
        constraints = 0.3 * self._randn(self.num_envs, num_constraints) + self.violation_shift
        extras = {"time_outs": time_outs, "constraints": constraints}
        return self.get_observations(), self._randn(self.num_envs), dones.long(), extras

    def set_reward_weight(self, name, weight):
        self.reward_weights.append((name, weight))


def make_cfg(class_name="dynpush.policies.cat_ppo:CaTPPO", num_steps=4, **alg):
    """rsl_rl 5.5 runner config as `dynpush train` builds it (tiny networks)."""
    return {
        "num_steps_per_env": num_steps,
        "save_interval": 1,
        "multi_gpu": None,
        "obs_groups": {"actor": ["policy"], "critic": ["policy", "critic"]},
        "algorithm": {"class_name": class_name, "num_learning_epochs": 2, "num_mini_batches": 2, **alg},
        "actor": {
            "class_name": "MLPModel",
            "hidden_dims": [16, 16],
            "activation": "elu",
            "obs_normalization": True,
            "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": 1.0},
        },
        "critic": {"class_name": "MLPModel", "hidden_dims": [16, 16], "activation": "elu", "obs_normalization": True},
    }


def build(env, cfg, seed=0):
    torch.manual_seed(seed)
    alg_class = CaTPPO if cfg["algorithm"]["class_name"].endswith("CaTPPO") else PPO
    return alg_class.construct_algorithm(env.get_observations(), env, cfg, "cpu")


def rollout(alg, env, obs, steps, seed=1):
    torch.manual_seed(seed)
    with torch.inference_mode():
        for _ in range(steps):
            actions = alg.act(obs)
            obs, rewards, dones, extras = env.step(actions)
            alg.process_env_step(obs, rewards, dones, extras)
        alg.compute_returns(obs)
    return obs


class ScriptedEnv(FakePushEnv):
    """Replays given rewards, dones, time-outs and constraints."""

    def __init__(self, rewards, dones, time_outs, constraints, groups):
        super().__init__(num_envs=len(rewards[0]), groups=groups)
        self.script = list(zip(rewards, dones, time_outs, constraints))

    def step(self, actions):
        rewards, dones, time_outs, constraints = self.script.pop(0)
        extras = {"time_outs": torch.tensor(time_outs), "constraints": torch.tensor(constraints)}
        return self.get_observations(), torch.tensor(rewards), torch.tensor(dones), extras


@pytest.mark.parametrize("returns_per_step", [True, False])
def test_hand_computed_returns_with_delta_timeout_and_done(returns_per_step):
    gamma, lam, tau = 0.9, 0.8, 0.95
    reward_scale = 1 - gamma if returns_per_step else 1.0
    groups = [("a", 1), ("b", 2)]
    p_max = [0.5, 0.2, 0.8]
    rewards = [[1.0, 0.5], [0.2, -0.3], [0.7, 0.4]]
    dones = [[0, 0], [0, 1], [1, 0]]  # env 1: real termination at t=1; env 0: time-out at t=2
    time_outs = [[0, 0], [0, 0], [1, 0]]
    constraints = [
        [[0.5, -1.0, 0.2], [1.0, -1.0, -1.0]],
        [[-0.1, 0.3, -1.0], [2.0, -1.0, 0.1]],
        [[0.05, -1.0, -1.0], [-1.0, -1.0, -1.0]],
    ]
    env = ScriptedEnv(rewards, dones, time_outs, constraints, groups)
    cfg = make_cfg(num_steps=3, gamma=gamma, lam=lam, tau=tau, normalize_advantage_per_mini_batch=True,
                   returns_per_step=returns_per_step)
    cfg["critic"]["obs_normalization"] = False
    alg = build(env, cfg)
    alg.set_p_max(torch.tensor(p_max))
    last_obs = rollout(alg, env, env.get_observations(), 3)

    # Independent reference with plain Python floats
    values = [[v[0] for v in row] for row in alg.storage.values.tolist()]
    last_value = alg.critic(last_obs).squeeze(1).tolist()
    c_max, deltas = None, []
    for batch in constraints:
        batch_max = [max(max(env_row[i] for env_row in batch), 1e-6) for i in range(3)]
        c_max = batch_max if c_max is None else [tau * m + (1 - tau) * b for m, b in zip(c_max, batch_max)]
        deltas.append(
            [max(p_max[i] * min(row[i] / c_max[i], 1.0) if row[i] > 0 else 0.0 for i in range(3)) for row in batch]
        )
    assert deltas[0] == pytest.approx([0.8, 0.5])
    assert deltas[1] == pytest.approx([0.2, 0.5])

    for e in range(2):
        advantage, returns, advantages = 0.0, [0.0] * 3, [0.0] * 3
        for t in reversed(range(3)):
            next_value = last_value[e] if t == 2 else values[t + 1][e]
            reward = (reward_scale * rewards[t][e] + gamma * values[t][e] * time_outs[t][e]) * (1 - deltas[t][e])
            not_terminal = (1 - dones[t][e]) * (1 - deltas[t][e])
            td = reward + not_terminal * gamma * next_value - values[t][e]
            advantage = td + not_terminal * gamma * lam * advantage
            returns[t], advantages[t] = advantage + values[t][e], advantage
        assert alg.storage.returns[:, e, 0].tolist() == pytest.approx(returns, abs=1e-5)
        assert alg.storage.advantages[:, e, 0].tolist() == pytest.approx(advantages, abs=1e-5)
        assert alg.deltas[:, e, 0].tolist() == pytest.approx([d[e] for d in deltas])
    assert alg.c_max.tolist() == pytest.approx(c_max)


def test_value_explained_variance_of_the_rollout_against_numpy():
    env = FakePushEnv(seed=4)
    alg = build(env, make_cfg())
    alg.set_p_max(p_max_at(0, 20000))
    rollout(alg, env, env.get_observations(), 4)
    values, returns = alg.storage.values.numpy().ravel(), alg.storage.returns.numpy().ravel()
    reference = 1.0 - np.var(returns - values, ddof=1) / np.var(returns, ddof=1)
    assert alg.value_explained_variance == pytest.approx(reference, rel=1e-4)
    assert alg.update()["value_explained_variance"] == alg.value_explained_variance
    returns = torch.tensor(returns)
    assert explained_variance(returns, returns) == 1.0
    assert explained_variance(torch.full_like(returns, float(returns.mean())), returns) == pytest.approx(0.0, abs=1e-6)
    assert explained_variance(-returns, returns) == pytest.approx(-3.0, rel=1e-5)  # Var(2 R) / Var(R) = 4
    assert np.isnan(explained_variance(returns, torch.ones_like(returns)))


def test_zero_delta_matches_rsl_rl_ppo_exactly():
    results = []
    for class_name in ("PPO", "dynpush.policies.cat_ppo:CaTPPO"):
        env = FakePushEnv(violation_shift=-2.0, seed=3)  # constraints all <= 0 (mean -2, std 0.3)
        cfg = make_cfg(class_name)
        if class_name.endswith("CaTPPO"):
            cfg["algorithm"]["returns_per_step"] = False
        alg = build(env, cfg)
        if isinstance(alg, CaTPPO):
            alg.set_p_max(p_max_at(0, 20000))
        rollout(alg, env, env.get_observations(), 4)
        returns, advantages = alg.storage.returns.clone(), alg.storage.advantages.clone()
        torch.manual_seed(7)
        alg.update()
        parameters = [p.detach().clone() for p in [*alg.actor.parameters(), *alg.critic.parameters()]]
        results.append((returns, advantages, parameters))
    (ret_a, adv_a, par_a), (ret_b, adv_b, par_b) = results
    assert torch.equal(ret_a, ret_b)
    assert torch.equal(adv_a, adv_b)
    assert all(torch.equal(a, b) for a, b in zip(par_a, par_b))


class SteadyRewardEnv(FakePushEnv):
    """A task whose reward is a few per step and never ends within the test, like the push task's."""

    def step(self, actions):
        obs, rewards, dones, extras = super().step(actions)
        return obs, 3.5 + 0.1 * rewards, torch.zeros_like(dones), {**extras, "time_outs": torch.zeros_like(dones)}


@pytest.mark.parametrize("returns_per_step", [True, False])
def test_critic_reaches_the_scale_of_the_returns(returns_per_step):
    """Regression: at gamma 0.998 the discounted returns of 3.5 per step head for ~1750 and rsl_rl's clipped value
    loss moves a value by about clip_param per update, so a fresh critic lags far behind its own GAE targets (and
    discounts CaT terminations as if the future were worth little) unless values are learnt in reward-per-step units,
    where it fits them every iteration (measured: 0.98 of the targets' mean, 0.60 in raw units)."""
    env = SteadyRewardEnv(violation_shift=-2.0, seed=6)
    alg = build(env, make_cfg(num_steps=8, gamma=0.998, learning_rate=1e-3, returns_per_step=returns_per_step))
    alg.set_p_max(p_max_at(0, 20000))
    obs = env.get_observations()
    for _ in range(30):
        obs = rollout(alg, env, obs, 8)
        alg.update()
    rollout(alg, env, obs, 8)
    ratio = float(alg.storage.values.mean() / alg.storage.returns.mean())
    if returns_per_step:
        assert ratio > 0.95
    else:
        assert ratio < 0.8


def test_c_max_and_delta_against_numpy():
    env = FakePushEnv(num_envs=16)
    alg = build(env, make_cfg())
    rng = np.random.default_rng(0)
    p_max = rng.uniform(0.0, 1.0, 62)
    alg.set_p_max(torch.tensor(p_max, dtype=torch.float))
    c_max = None
    for step in range(25):
        c = rng.normal(-0.3, 1.0, (16, 62)) * rng.uniform(0.1, 10.0, 62)
        c[:, 5] = -1.0  # a column never violated: c_max stays at the floor
        batch_max = np.maximum(c.max(axis=0), 1e-6)
        c_max = batch_max if c_max is None else 0.95 * c_max + 0.05 * batch_max
        delta = np.where(c > 0, p_max * np.clip(c / c_max, 0.0, 1.0), 0.0).max(axis=1)
        got = alg.termination_probability(torch.tensor(c, dtype=torch.float))
        np.testing.assert_allclose(alg.c_max.numpy(), c_max, rtol=1e-5)
        np.testing.assert_allclose(got.numpy(), delta, rtol=1e-5, atol=1e-7)
    assert alg.c_max[5].item() == pytest.approx(1e-6)
    assert (got >= 0).all() and (got <= 1).all()


def test_step_log_reports_delta_and_group_violation_rates():
    env = FakePushEnv(num_envs=16)
    alg = build(env, make_cfg())
    alg.set_p_max(p_max_at(0, 20000))
    obs = env.get_observations()
    with torch.inference_mode():
        alg.act(obs)
        obs, rewards, dones, extras = env.step(None)
        extras["log"] = {"/env/keep": torch.tensor(1.0)}
        alg.process_env_step(obs, rewards, dones, extras)
    log = extras["log"]
    assert log["/env/keep"] == 1.0
    assert log["CaT/mean_delta"].item() == pytest.approx(alg.deltas[0].mean().item())
    start, group_deltas = 0, []
    p_max = p_max_at(0, 20000)
    for name, dim in CONSTRAINT_GROUPS:
        columns = extras["constraints"][:, start : start + dim]
        rate = (columns > 0).any(dim=1).float().mean().item()
        assert log[f"CaT/violation_rate/{name}"].item() == pytest.approx(rate)
        ratio = (columns / alg.c_max[start : start + dim]).clamp(0.0, 1.0)
        group = torch.where(columns > 0, p_max[start : start + dim] * ratio, 0.0).amax(dim=1)
        assert log[f"CaT/delta/{name}"].item() == pytest.approx(group.mean().item(), abs=1e-7)
        group_deltas.append(group)
        start += dim
    torch.testing.assert_close(torch.stack(group_deltas, dim=1).amax(dim=1), alg.deltas[0, :, 0])
    assert any(log[f"CaT/delta/{name}"] > 0 for name, _ in CONSTRAINT_GROUPS)


def test_checkpoint_round_trip_keeps_c_max(tmp_path):
    env = FakePushEnv()
    alg = build(env, make_cfg())
    alg.set_p_max(p_max_at(0, 20000))
    rollout(alg, env, env.get_observations(), 4)
    assert (alg.c_max > 0).all()
    path = os.path.join(tmp_path, "ckpt.pt")
    torch.save(alg.save(), path)

    fresh = build(env, make_cfg(), seed=5)
    fresh.load(torch.load(path, weights_only=False), None, True)
    assert torch.equal(fresh.c_max, alg.c_max)
    partial = build(env, make_cfg(), seed=5)
    partial.load(torch.load(path, weights_only=False), {"actor": True}, True)
    assert (partial.c_max == 0).all()


def test_runner_learns_two_iterations(tmp_path, capsys):
    env = FakePushEnv(seed=11)
    cfg = make_cfg()
    del cfg["algorithm"]["class_name"]  # the runner defaults to CaT-PPO
    runner = CaTOnPolicyRunner(env, copy.deepcopy(cfg), log_dir=str(tmp_path), device="cpu")
    runner.learn(2)

    assert env.reward_weights == [("reach", 1.25), ("reach", 1.25 / 4)]  # 2-iteration run: switch at 0.15
    torch.testing.assert_close(runner.alg.p_max, p_max_at(1, 2))
    out = capsys.readouterr().out
    assert "| delta " in out and " coll " in out  # the runner's one-line summary of the CaT statistics
    assert os.path.isfile(tmp_path / "model_1.pt")
    record = read_progress(tmp_path)[-1]
    assert record["action_std"] == pytest.approx(float(runner.alg.actor.output_std.detach().mean()))
    assert record["learning_rate"] == runner.alg.learning_rate
    assert {"loss/surrogate", "loss/value", "loss/entropy", "loss/value_explained_variance"} <= set(record)
    assert record["loss/value_explained_variance"] == runner.alg.value_explained_variance

    resumed = CaTOnPolicyRunner(FakePushEnv(), copy.deepcopy(cfg), device="cpu")
    resumed.load(str(tmp_path / "model_1.pt"))
    assert torch.equal(resumed.alg.c_max, runner.alg.c_max)
    assert resumed.current_learning_iteration == 2  # checkpoints store the next iteration to run


def test_runner_rejects_plain_ppo():
    with pytest.raises(TypeError):
        CaTOnPolicyRunner(FakePushEnv(), make_cfg("PPO"), device="cpu")
