"""``dynpush`` subcommands of dynpush.sim (registered by ``dynpush.cli``): env-info."""

from __future__ import annotations

import argparse


def _env_info(args: argparse.Namespace) -> int:
    from dynpush.kernels.push.observations import POLICY_TERMS, PRIVILEGED_TERMS
    from dynpush.kernels.push.views import NUM_CRITIC_OBS

    from .config import PushEnvConfig, SimConfig
    from .push_env import PushEnv

    env = PushEnv(PushEnvConfig(num_envs=args.num_envs, device=args.device, sim=SimConfig(solver=args.solver)))
    scene, model = env.scene, env.scene.model
    lines = [
        f"device            {env.wp_device} (solver {env.cfg.sim.solver}, {env.cfg.sim.substeps} substeps,"
        f" {env.cfg.sim.xpbd_iterations} XPBD iterations, control {1.0 / env.cfg.control_dt:.0f} Hz)",
        f"worlds            {env.num_envs} ({scene.bodies_per_world} bodies, {model.shape_count // env.num_envs} shapes,"
        f" {model.joint_count // env.num_envs} joints per world)",
        f"robot             base {scene.robot.base_mass:.1f} kg + arm, 5 controlled arm joints + frozen WRIST_2",
        f"episode           {env.cfg.episode_length_s:.0f} s = {env.max_episode_length} steps",
        f"actions           {env.num_actions} = (vx, vy, yaw rate, roll, pitch, height) + 5 arm joints",
        "observations      policy 54 = " + ", ".join(f"{n} {s}" for n, s in POLICY_TERMS),
        f"                  critic {NUM_CRITIC_OBS} = policy (noiseless) + "
        + ", ".join(f"{n} {s}" for n, s in PRIVILEGED_TERMS)
        + f"; the critic reads {len(env.critic_input_columns)} of them (not last_actions)",
        "constraints       " + ", ".join(f"{n} {s}" for n, s in env.constraint_groups)
        + f" (= {env.constraints_t.shape[1]})",
    ]
    print("\n".join(lines))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds this package's subcommands to the ``dynpush`` parser."""
    p = subparsers.add_parser("env-info", help="print the scene, observation/action/constraint sizes, solver and device")
    p.add_argument("--num-envs", type=int, default=4)
    p.add_argument("--device", default="cpu")
    p.add_argument("--solver", default="xpbd")
    p.set_defaults(func=_env_info)
