"""Push-environment throughput on the CPU: world-steps per second with every kernel included.

Prints one JSON object: for each N in --num-envs, world-steps/s of captured steps (``PushEnv.step``,
torch glue included), the per-stage split of an uncaptured step (physics = solver, collision =
collision pipeline + contact classification, kernels = task kernels and kinematics, torch glue =
``step()`` minus the graph launch), and with --procs 2 the summed throughput of two processes of
N/2 worlds each (the Warp CPU backend runs a launch on one core; a second process uses the second).

    python benchmarks/env_throughput.py [--num-envs 64 256 1024] [--steps 200] [--procs 2]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import multiprocessing as mp
import os
import platform
import time

import torch


def measure(num_envs: int, steps: int, split: bool, queue=None) -> dict:
    import warp as wp

    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    torch.set_num_threads(1)
    env = PushEnv(PushEnvConfig(num_envs=num_envs, seed=0))
    generator = torch.Generator().manual_seed(0)
    actions = [0.5 * torch.randn(num_envs, 11, generator=generator) for _ in range(16)]
    for i in range(20):  # warm-up
        env.step(actions[i % 16])
    start = time.perf_counter()
    for i in range(steps):
        env.step(actions[i % 16])
    step_s = (time.perf_counter() - start) / steps
    result = {"num_envs": num_envs, "world_steps_per_s": num_envs / step_s, "step_ms": 1e3 * step_s}
    if split:
        start = time.perf_counter()
        for _ in range(steps):
            wp.capture_launch(env._graph)
        launch_s = (time.perf_counter() - start) / steps
        totals: dict[str, float] = collections.defaultdict(float)

        @contextlib.contextmanager
        def timer(name: str):
            t0 = time.perf_counter()
            yield
            totals[name] += time.perf_counter() - t0

        env.stage_timer = timer
        for i in range(steps):
            env.step_uncaptured(actions[i % 16])
        env.stage_timer = None
        uncaptured = sum(totals.values()) / steps
        result["uncaptured_step_ms"] = 1e3 * uncaptured
        result["split_of_uncaptured_step"] = {k: round(v / steps / uncaptured, 4) for k, v in totals.items()}
        result["torch_glue_ms"] = 1e3 * max(step_s - launch_s, 0.0)
        result["graph_launch_ms"] = 1e3 * launch_s
    if queue is not None:
        queue.put(result)
    return result


def two_processes(num_envs: int, steps: int, procs: int) -> dict:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    workers = [ctx.Process(target=measure, args=(num_envs // procs, steps, False, queue)) for _ in range(procs)]
    for w in workers:
        w.start()
    results = [queue.get() for _ in workers]
    for w in workers:
        w.join()
    return {"num_envs": num_envs, "procs": procs, "world_steps_per_s": sum(r["world_steps_per_s"] for r in results)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--num-envs", type=int, nargs="+", default=[64, 256, 1024])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--procs", type=int, default=2, help="processes for the multi-process figure (0: skip)")
    args = parser.parse_args()
    report = {
        "machine": {"cpu_count": os.cpu_count(), "processor": platform.processor() or platform.machine()},
        "single_process": [measure(n, args.steps, split=True) for n in args.num_envs],
    }
    if args.procs > 1:
        n = max(args.num_envs)
        multi = two_processes(n, args.steps, args.procs)
        single = next(r for r in report["single_process"] if r["num_envs"] == n)
        multi["speedup_vs_one_process"] = multi["world_steps_per_s"] / single["world_steps_per_s"]
        report["multi_process"] = multi
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
