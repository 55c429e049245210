"""The ``dynpush`` command line."""

from __future__ import annotations

import argparse
import sys


def _env_info(args: argparse.Namespace) -> int:
    from dynpush.kernels.observations import POLICY_TERMS, PRIVILEGED_TERMS
    from dynpush.sim.config import PushEnvConfig, SimConfig
    from dynpush.sim.push_env import PushEnv

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
        "                  critic 73 = policy (noiseless) + " + ", ".join(f"{n} {s}" for n, s in PRIVILEGED_TERMS),
        "constraints       " + ", ".join(f"{n} {s}" for n, s in env.constraint_groups)
        + f" (= {env.constraints_t.shape[1]})",
    ]
    print("\n".join(lines))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dynpush", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("env-info", help="print the scene, observation/action/constraint sizes, solver and device")
    p.add_argument("--num-envs", type=int, default=4)
    p.add_argument("--device", default="cpu")
    p.add_argument("--solver", default="xpbd")
    p.set_defaults(func=_env_info)

    # Commands of the training/evaluation/export side and of the deployment runtime register themselves.
    from dynpush.policies.commands import register as register_policy_commands
    from dynpush.runtime.commands import register as register_runtime_commands

    register_policy_commands(sub)
    register_runtime_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Runs one subcommand; a user error (:class:`dynpush.errors.UserError`) ends with one line on stderr and exit
    status 2, like argparse's own usage errors. Other exceptions are bugs and keep their traceback."""
    from dynpush.errors import UserError

    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    try:
        return args.func(args)
    except UserError as error:
        print(f"dynpush: {' '.join(str(error).split())}", file=sys.stderr)  # one line, even for a listing message
        return 2


if __name__ == "__main__":
    sys.exit(main())
