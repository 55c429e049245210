"""`benchmarks/critic_at_success.py`: its discounted returns, transition groups and scored states, against hand-made
inputs (no simulation)."""

import numpy as np
import pytest
import torch


def test_discounted_returns(load_benchmark):
    """``G_t = r_t + gamma c_t G_{t+1}`` with ``G_T = 0``: a loop in numpy over two worlds, one of which terminates
    (c = 0) and one of which is softly terminated by CaT (c = 0.5)."""
    bench = load_benchmark("critic_at_success")
    rewards = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    continues = np.array([[1.0, 0.5], [0.0, 1.0], [1.0, 1.0]])
    gamma = 0.9
    expected = np.zeros_like(rewards)
    for w in range(2):
        following = 0.0
        for t in (2, 1, 0):
            following = rewards[t, w] + gamma * continues[t, w] * following
            expected[t, w] = following
    returns = bench.discounted_returns(torch.tensor(rewards), torch.tensor(continues), gamma)
    np.testing.assert_allclose(returns.numpy(), expected)
    assert returns[1, 0] == pytest.approx(3.0)  # the episode ended after step 1: nothing of step 2 flows back


def test_transition_groups_partition_the_valid_transitions(load_benchmark):
    bench = load_benchmark("critic_at_success")
    before = torch.tensor([0, 0, 1, 1, 0, 1])
    after = torch.tensor([1, 0, 0, 1, 1, 1])
    valid = torch.tensor([True, True, True, True, False, False])
    groups = bench.transition_groups(before, after, valid)
    assert groups["enter"].tolist() == [True, False, False, False, False, False]
    assert groups["stay_out"].tolist() == [False, True, False, False, False, False]
    assert groups["leave"].tolist() == [False, False, True, False, False, False]
    assert groups["stay_in"].tolist() == [False, False, False, True, False, False]
    union = sum(mask.int() for mask in groups.values())
    assert union.tolist() == valid.int().tolist()


def test_scored_states_sum_the_horizon_and_meet_no_time_out(load_benchmark):
    """A state is scored when ``horizon`` collected steps follow it and none of steps t .. t + horizon - 1 times out
    (its return would hold the critic's own bootstrap)."""
    bench = load_benchmark("critic_at_success")
    time_outs = torch.zeros(8, 2, dtype=torch.bool)
    time_outs[4, 1] = True  # world 1 times out at step 4
    scored = bench.scored_states(time_outs, horizon=3)
    assert scored[:, 0].tolist() == [True] * 5 + [False] * 3  # the last 3 steps lack a full horizon
    assert scored[:, 1].tolist() == [True, True, False, False, False, False, False, False]
    assert not bench.scored_states(time_outs, horizon=8).any()
