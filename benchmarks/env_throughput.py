"""Push-environment throughput on the CPU: world-steps per second with every kernel included.

Prints one JSON object: for each N in --num-envs, world-steps/s of captured steps (``PushEnv.step``,
torch glue included), the per-stage split of an uncaptured step (physics = solver, collision =
collision pipeline + contact classification, kernels = task kernels and kinematics, torch glue =
``step()`` minus the graph launch), and with --procs 2 the summed throughput of two processes of
N/2 worlds each (the Warp CPU backend runs a launch on one core; a second process uses the second).

``--set FIELD=VALUE`` changes the environment's config (``PushEnvConfig`` fields, e.g. ``sim.xpbd_iterations=2``);
with ``--baseline-set`` (or ``--baseline-set`` alone: today's defaults) every size is also measured with the
baseline's config in the same invocation, alternating (baseline, candidate) so that drift of the machine falls on
both, and reported with the speed-up (candidate / baseline world-steps/s). ``--kernels`` adds where an uncaptured
step spends its time, per Warp kernel (ms per step, launches per step, share), the profile that says which lever
can pay.

    python benchmarks/env_throughput.py [--num-envs 64 256 1024] [--steps 200] [--procs 2]
        [--set sim.contacts_per_world=16 ...] [--baseline-set ...] [--kernels]
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


def measure(num_envs: int, steps: int, split: bool, overrides: tuple[str, ...] = (), kernels: bool = False,
            queue=None) -> dict:
    import warp as wp

    from dynpush.policies.overrides import apply_overrides
    from dynpush.sim.config import PushEnvConfig
    from dynpush.sim.push_env import PushEnv

    torch.set_num_threads(1)
    cfg = apply_overrides(PushEnvConfig(num_envs=num_envs, seed=0), list(overrides))
    env = PushEnv(cfg.validate())
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
    if kernels:
        result["kernels_of_uncaptured_step"] = kernel_profile(env, actions, steps)
    result["overrides"] = list(overrides)
    if queue is not None:
        queue.put(result)
    return result


def kernel_profile(env, actions: list[torch.Tensor], steps: int, top: int = 12) -> list[dict]:
    """Per-kernel time of uncaptured steps, the ``top`` costliest first: every ``wp.launch`` timed to its end (a CPU
    launch runs to completion before it returns), so the ms per step of a kernel include its launch overhead."""
    import warp as wp

    totals: dict[str, float] = collections.defaultdict(float)
    launches: collections.Counter = collections.Counter()
    launch = wp.launch

    def timed_launch(kernel, *args, **kwargs):
        start = time.perf_counter()
        result = launch(kernel, *args, **kwargs)
        name = getattr(kernel, "key", str(kernel))
        totals[name] += time.perf_counter() - start
        launches[name] += 1
        return result

    wp.launch = timed_launch
    try:
        for i in range(steps):
            env.step_uncaptured(actions[i % 16])
    finally:
        wp.launch = launch
    step_total = sum(totals.values())
    ranked = sorted(totals.items(), key=lambda item: -item[1])[:top]
    return [{"kernel": name, "ms_per_step": round(1e3 * t / steps, 3), "launches_per_step": launches[name] / steps,
             "share": round(t / step_total, 4)} for name, t in ranked]


def two_processes(num_envs: int, steps: int, procs: int, overrides: tuple[str, ...] = ()) -> dict:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    workers = [ctx.Process(target=measure, args=(num_envs // procs, steps, False, overrides, False, queue))
               for _ in range(procs)]
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
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE",
                        help="PushEnvConfig overrides of the measured (candidate) configuration")
    parser.add_argument("--baseline-set", nargs="*", default=None, metavar="FIELD=VALUE",
                        help="measure a baseline too, with these overrides (none: the defaults), side by side")
    parser.add_argument("--kernels", action="store_true", help="add the per-kernel time split of an uncaptured step")
    args = parser.parse_args()
    candidate = tuple(args.set)
    baseline = None if args.baseline_set is None else tuple(args.baseline_set)
    report = {
        "machine": {"cpu_count": os.cpu_count(), "processor": platform.processor() or platform.machine()},
        "single_process": [],
    }
    for n in args.num_envs:
        result = {}
        if baseline is not None:
            result["baseline"] = measure(n, args.steps, split=True, overrides=baseline, kernels=args.kernels)
        result.update(measure(n, args.steps, split=True, overrides=candidate, kernels=args.kernels))
        if baseline is not None:
            result["speedup_vs_baseline"] = result["world_steps_per_s"] / result["baseline"]["world_steps_per_s"]
        report["single_process"].append(result)
    if args.procs > 1:
        n = max(args.num_envs)
        if baseline is not None:
            report["multi_process_baseline"] = two_processes(n, args.steps, args.procs, baseline)
        multi = two_processes(n, args.steps, args.procs, candidate)
        single = next(r for r in report["single_process"] if r["num_envs"] == n)
        multi["speedup_vs_one_process"] = multi["world_steps_per_s"] / single["world_steps_per_s"]
        if baseline is not None:
            multi["speedup_vs_baseline"] = (multi["world_steps_per_s"]
                                            / report["multi_process_baseline"]["world_steps_per_s"])
        report["multi_process"] = multi
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
