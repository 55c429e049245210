"""`benchmarks/train_throughput.py`: its summary of a run's progress.jsonl (warm-up left out, means, world-steps/s)
and the candidate / baseline speed-up, on hand-made records (no training)."""

import pytest


def records(collect_s, learn_s, start=100.0, logging_s=0.1):
    """progress.jsonl records of consecutive iterations, each logged ``logging_s`` after its collect + learn."""
    out, now = [], start
    for iteration, (collect, learn) in enumerate(zip(collect_s, learn_s)):
        now += collect + learn + logging_s
        out.append({"iteration": iteration, "time": now, "collect_s": collect, "learn_s": learn, "eval_s": 0.0})
    return out


def test_summary_leaves_out_the_warmup(load_benchmark):
    """Two slow warm-up iterations (compilation) do not enter the means; world-steps/s is per collect + learn."""
    throughput = load_benchmark("train_throughput")
    run = records(collect_s=[30.0, 9.0, 1.0, 2.0, 3.0], learn_s=[5.0, 5.0, 0.5, 0.5, 0.5])
    summary = throughput.summarize_run(run, warmup=2, steps_per_iteration=1000)
    assert summary["iterations"] == 3
    assert summary["collect_s"] == pytest.approx(2.0)
    assert summary["learn_s"] == pytest.approx(0.5)
    assert summary["iteration_s"] == pytest.approx(2.5)
    assert summary["iteration_s_std"] == pytest.approx(1.0)  # 1.5, 2.5, 3.5
    assert summary["wall_iteration_s"] == pytest.approx(2.6)  # also the 0.1 s of logging per iteration
    assert summary["world_steps_per_iteration"] == 1000
    assert summary["world_steps_per_s"] == pytest.approx(400.0)


def test_summary_needs_a_measured_iteration_and_a_warmup(load_benchmark):
    throughput = load_benchmark("train_throughput")
    run = records(collect_s=[1.0, 1.0], learn_s=[1.0, 1.0])
    with pytest.raises(ValueError, match="none after"):
        throughput.summarize_run(run, warmup=2, steps_per_iteration=10)
    with pytest.raises(ValueError, match="warmup"):
        throughput.summarize_run(run, warmup=0, steps_per_iteration=10)


def test_world_steps_per_iteration_is_over_all_processes(load_benchmark):
    """config.json holds the total env.num_envs (split over the processes): 1024 worlds x 24 steps."""
    throughput = load_benchmark("train_throughput")
    assert throughput.world_steps_per_iteration({"env": {"num_envs": 1024}, "num_steps_per_env": 24}) == 24576


def test_speedup_is_candidate_over_baseline(load_benchmark):
    """> 1 when the candidate trains faster; per repeat pair and of the means, with the range of the pairs."""
    throughput = load_benchmark("train_throughput")
    baseline = [{"world_steps_per_s": 100.0}, {"world_steps_per_s": 200.0}]
    candidate = [{"world_steps_per_s": 150.0}, {"world_steps_per_s": 240.0}]
    result = throughput.speedup(baseline, candidate)
    assert result["speedup"] == pytest.approx(390.0 / 300.0)
    assert result["speedup_per_repeat"] == pytest.approx([1.5, 1.2])
    assert result["speedup_range"] == pytest.approx([1.2, 1.5])
    with pytest.raises(ValueError, match="one candidate run per baseline run"):
        throughput.speedup(baseline, candidate[:1])


def test_benchmark_overrides_set_the_length_and_keep_evaluations_out(load_benchmark):
    """A run of warm-up + measured iterations, no evaluation, no checkpoint between its first and last iteration."""
    throughput = load_benchmark("train_throughput")
    overrides = throughput.benchmark_overrides(iterations=20, warmup=5)
    assert "iterations=25" in overrides and "save_interval=25" in overrides and "eval_interval=0" in overrides
