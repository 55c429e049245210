"""Training throughput on the CPU: world-steps/s of real ``dynpush train`` runs, a candidate configuration against a
baseline measured side by side in the same invocation.

Both sides are TrainConfig overrides on the ``cpu`` preset: the recipe (default ``configs/recipes/long_run.txt``, the
long run's 1024 worlds, networks and PPO settings), then ``--set`` for the candidate or ``--baseline-set`` for the
baseline; with neither, both sides are the long run and the speed-up (~1.0) shows the measurement noise. For every
process count in ``--procs`` and every repeat, the baseline trains, then the candidate (A B A B ...: drift of the
machine falls on both), each a fresh ``dynpush train --procs P`` of ``--warmup`` + ``--iterations`` iterations in a
temporary folder. The warm-up iterations (Warp and torch compile, first checkpoint) are left out; of the others the
run's ``progress.jsonl`` gives the rollout (collect) and PPO update (learn) seconds. Under ``--procs 2`` that file is
rank 0's: its collect time is its own shard's rollout, and its learn time includes the wait for the slower rank at
the first gradient all-reduce, so collect + learn is the iteration of both processes.

The runs start from fresh networks and follow the first iterations of the long run's schedules (the benchmark does
not compress them into its few iterations), so they measure the throughput at a run's start.

Prints one JSON object: per process count, each side's mean collect_s, learn_s, iteration_s (collect + learn) and
wall_iteration_s (between progress records: also logging) [s], world-steps per iteration (all processes) and
world-steps/s (per iteration_s), every run's figures, and the speed-up (candidate / baseline world-steps/s) of the
means and of each repeat's pair (their range is the spread). Progress goes to stderr.

    python benchmarks/train_throughput.py [--recipe configs/recipes/long_run.txt] [--set FIELD=VALUE ...]
        [--baseline-set FIELD=VALUE ...] [--procs 1 2] [--iterations 20] [--warmup 5] [--repeats 1] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

RECIPE = Path(__file__).resolve().parents[1] / "configs" / "recipes" / "long_run.txt"
SUMMARY_FIELDS = ("collect_s", "learn_s", "iteration_s", "wall_iteration_s", "world_steps_per_s")
"""The per-run figures that a side's summary averages over its repeats."""


def benchmark_overrides(iterations: int, warmup: int) -> list[str]:
    """TrainConfig overrides applied after each side's own: the run's length and what would distort its timing."""
    total = warmup + iterations
    return [
        f"iterations={total}",
        f"save_interval={total}",  # rsl_rl saves after iteration 0 (a warm-up one) and at the end, nothing between
        "eval_interval=0",  # an evaluation is due at iteration 0; it is not training
        # Schedules at the long run's absolute iterations: compressed into a few iterations, p_max would ramp to its
        # final values and change how often worlds terminate and reset.
        "scale_schedules_with_run_length=False",
    ]


def world_steps_per_iteration(config: dict) -> int:
    """World-steps of one iteration over all processes, from a run's ``config.json`` (``env.num_envs`` is the total)."""
    return config["env"]["num_envs"] * config["num_steps_per_env"]


def summarize_run(records: list[dict], warmup: int, steps_per_iteration: int) -> dict[str, float]:
    """The throughput of a run from its ``progress.jsonl`` records (in iteration order), the first ``warmup`` left out.

    Means over the measured iterations of ``collect_s``, ``learn_s`` and ``iteration_s`` = collect + learn [s], the
    standard deviation of ``iteration_s`` [s] (the run's own noise), ``wall_iteration_s`` [s] (the time between the
    last warm-up record and the last record, per measured iteration: also logging and checkpoints),
    ``world_steps_per_iteration`` and ``world_steps_per_s`` (per ``iteration_s``).
    """
    if warmup < 1:
        raise ValueError(f"warmup must be >= 1 (the wall time starts at the last warm-up record), got {warmup}")
    measured = records[warmup:]
    if not measured:
        raise ValueError(f"{len(records)} progress records, none after the {warmup} warm-up iterations")
    iteration_s = [r["collect_s"] + r["learn_s"] for r in measured]
    mean_iteration_s = statistics.fmean(iteration_s)
    return {
        "iterations": len(measured),
        "collect_s": statistics.fmean(r["collect_s"] for r in measured),
        "learn_s": statistics.fmean(r["learn_s"] for r in measured),
        "iteration_s": mean_iteration_s,
        "iteration_s_std": statistics.stdev(iteration_s) if len(iteration_s) > 1 else 0.0,
        "wall_iteration_s": (measured[-1]["time"] - records[warmup - 1]["time"]) / len(measured),
        "world_steps_per_iteration": steps_per_iteration,
        "world_steps_per_s": steps_per_iteration / mean_iteration_s,
    }


def summarize_side(runs: list[dict]) -> dict:
    """One side's runs (one per repeat, ``summarize_run``'s figures): the mean of each of ``SUMMARY_FIELDS``, the
    world-steps/s of each run, and the runs themselves."""
    return {
        **{name: statistics.fmean(run[name] for run in runs) for name in SUMMARY_FIELDS},
        "world_steps_per_s_per_repeat": [run["world_steps_per_s"] for run in runs],
        "runs": runs,
    }


def speedup(baseline: list[dict], candidate: list[dict]) -> dict:
    """Candidate over baseline world-steps/s (> 1: the candidate trains faster): of the means over the repeats, and of
    each repeat's pair of runs, with the range of those (the spread)."""
    if len(baseline) != len(candidate) or not baseline:
        raise ValueError(f"need one candidate run per baseline run, got {len(baseline)} and {len(candidate)}")
    pairs = [c["world_steps_per_s"] / b["world_steps_per_s"] for b, c in zip(baseline, candidate)]
    means = [statistics.fmean(run["world_steps_per_s"] for run in side) for side in (baseline, candidate)]
    return {"speedup": means[1] / means[0], "speedup_per_repeat": pairs, "speedup_range": [min(pairs), max(pairs)]}


def config_summary(overrides: list[str]) -> dict:
    """The TrainConfig of ``overrides`` on the cpu preset, validated (a typo stops here, before any run), and the
    fields that set the cost of an iteration."""
    from dynpush.policies.train import TrainConfig
    from dynpush.policies.overrides import apply_overrides

    cfg = apply_overrides(TrainConfig.preset_config("cpu"), overrides).validate()
    return {"num_envs": cfg.env.num_envs, "num_steps_per_env": cfg.num_steps_per_env,
            "actor_hidden": list(cfg.network.actor_hidden), "critic_hidden": list(cfg.network.critic_hidden),
            "num_learning_epochs": cfg.ppo.num_learning_epochs, "num_mini_batches": cfg.ppo.num_mini_batches}


def train_and_summarize(overrides: list[str], procs: int, run_dir: Path, warmup: int) -> dict[str, float]:
    """Trains a fresh run of ``overrides`` (cpu preset) with ``procs`` processes into ``run_dir`` and summarizes it."""
    from dynpush.policies.progress import read_progress
    from dynpush.policies.run_folder import CONFIG, read_json

    command = [sys.executable, "-m", "dynpush", "train", "--preset", "cpu", "--runs", str(run_dir.parent),
               "--name", run_dir.name, "--procs", str(procs), "--set", *overrides]
    # The training's own output goes to stderr with the progress: stdout carries the JSON object only.
    result = subprocess.run(command, check=False, stdout=sys.stderr, stderr=sys.stderr)
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(command)} exited with status {result.returncode}")
    steps = world_steps_per_iteration(read_json(run_dir / CONFIG))
    return summarize_run(read_progress(run_dir), warmup, steps)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--recipe", type=Path, default=RECIPE, help="overrides of both sides, before their own")
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE", help="the candidate's overrides")
    parser.add_argument("--baseline-set", nargs="*", default=[], metavar="FIELD=VALUE", help="the baseline's overrides")
    parser.add_argument("--procs", type=int, nargs="+", default=[1, 2], help="process counts (dynpush train --procs)")
    parser.add_argument("--iterations", type=int, default=20, help="measured iterations per run")
    parser.add_argument("--warmup", type=int, default=5, help="iterations left out at the start of each run (>= 1)")
    parser.add_argument("--repeats", type=int, default=1, help="baseline-candidate pairs per process count")
    parser.add_argument("--out", type=Path, default=None, help="also write the JSON object to this file")
    args = parser.parse_args()
    if args.warmup < 1 or args.iterations < 1 or args.repeats < 1:
        parser.error("--warmup, --iterations and --repeats must be >= 1")

    from dynpush.policies.overrides import read_recipe

    recipe = read_recipe(args.recipe)
    harness = benchmark_overrides(args.iterations, args.warmup)
    sides = {"baseline": [*recipe, *args.baseline_set, *harness], "candidate": [*recipe, *args.set, *harness]}
    configs = {side: config_summary(overrides) for side, overrides in sides.items()}
    for side, config in configs.items():
        for procs in args.procs:
            if config["num_envs"] % procs:
                parser.error(f"{side}: env.num_envs={config['num_envs']} is not divisible by --procs {procs}")

    runs: dict[int, dict[str, list[dict]]] = {procs: {side: [] for side in sides} for procs in args.procs}
    total, done = len(args.procs) * args.repeats * len(sides), 0
    with tempfile.TemporaryDirectory(prefix="train_throughput_") as folder:
        for repeat in range(args.repeats):
            for procs in args.procs:
                for side, overrides in sides.items():
                    done += 1
                    print(f"[{done}/{total}] {side}, --procs {procs}, repeat {repeat + 1}/{args.repeats}",
                          file=sys.stderr, flush=True)
                    run_dir = Path(folder) / f"{side}_p{procs}_r{repeat}"
                    runs[procs][side].append(train_and_summarize(overrides, procs, run_dir, args.warmup))

    report = {
        "machine": {"cpu_count": os.cpu_count(), "processor": platform.processor() or platform.machine()},
        "recipe": str(args.recipe),
        "baseline_set": args.baseline_set,
        "candidate_set": args.set,
        "benchmark_set": harness,
        "baseline_config": configs["baseline"],
        "candidate_config": configs["candidate"],
        "warmup": args.warmup,
        "iterations": args.iterations,
        "repeats": args.repeats,
        "procs": [{"procs": procs, **speedup(by_side["baseline"], by_side["candidate"]),
                   **{side: summarize_side(side_runs) for side, side_runs in by_side.items()}}
                  for procs, by_side in runs.items()],
    }
    text = json.dumps(report, indent=2)
    if args.out is not None:
        args.out.write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
