"""Legged simulation throughput on the CPU: world-steps per second of captured control steps.

Prints one JSON object with, in one run (compare the ratios, not the absolute figures, across machines):
- ``locomotion``: ``LocomotionEnv`` (MuJoCo-Warp, MuJoCo's contacts) at --num-envs worlds with random leg
  actions, for the configured solver settings (``MuJoCoConfig``: CG, 5 iterations) and for MuJoCo's
  defaults (Newton solver, Newton's default iteration counts and contact buffers);
- ``legged_push``: the legged push environment (Newton's contacts, a locomotion ONNX in the loop when
  --locomotion-policy is given, else external leg targets) next to the tracked-base push environment.

    python benchmarks/locomotion_throughput.py [--num-envs 512] [--steps 60] [--locomotion-policy runs/X/locomotion.onnx]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import torch


def _rate(env, num_actions: int, steps: int) -> float:
    generator = torch.Generator().manual_seed(0)
    actions = [0.5 * torch.randn(env.num_envs, num_actions, generator=generator) for _ in range(8)]
    for i in range(5):  # warm-up
        env.step(actions[i % 8])
    start = time.perf_counter()
    for i in range(steps):
        env.step(actions[i % 8])
    return env.num_envs * steps / (time.perf_counter() - start)


def locomotion(num_envs: int, steps: int) -> dict:
    import newton

    from dynpush.sim import locomotion_env
    from dynpush.sim.locomotion_config import LocomotionEnvConfig

    configured = _rate(locomotion_env.LocomotionEnv(LocomotionEnvConfig(num_envs=num_envs)), 12, steps)
    solver = newton.solvers.SolverMuJoCo
    try:  # MuJoCo's defaults: only the arguments every solver construction needs
        locomotion_env.newton.solvers.SolverMuJoCo = lambda model, **kwargs: solver(model, use_mujoco_contacts=True)
        defaults = _rate(locomotion_env.LocomotionEnv(LocomotionEnvConfig(num_envs=num_envs)), 12, steps)
    finally:
        locomotion_env.newton.solvers.SolverMuJoCo = solver
    return {"num_envs": num_envs, "configured_world_steps_per_s": configured, "mujoco_defaults_world_steps_per_s": defaults,
            "ratio_configured_over_defaults": configured / defaults}


def legged_push(num_envs: int, steps: int, locomotion_policy: str | None) -> dict:
    from dynpush.sim.config import LeggedModeConfig, PushEnvConfig
    from dynpush.sim.envs import make_push_env

    tracked = _rate(make_push_env(PushEnvConfig(num_envs=num_envs)), 11, steps)
    legged_cfg = LeggedModeConfig(enabled=True, locomotion_policy=locomotion_policy or "")
    legged = _rate(make_push_env(PushEnvConfig(num_envs=num_envs, legged=legged_cfg)), 11, steps)
    return {"num_envs": num_envs, "locomotion_onnx_in_the_loop": bool(locomotion_policy),
            "tracked_base_world_steps_per_s": tracked, "legged_world_steps_per_s": legged,
            "ratio_legged_over_tracked": legged / tracked}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--num-envs", type=int, default=512)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--locomotion-policy", default=None, help="locomotion.onnx run inside the legged push env")
    args = parser.parse_args()
    torch.set_num_threads(1)
    result = {"machine": platform.processor() or platform.machine(), "locomotion": locomotion(args.num_envs, args.steps),
              "legged_push": legged_push(args.num_envs, args.steps, args.locomotion_policy)}
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
