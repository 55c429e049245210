"""The ``dynpush`` command line."""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path


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


def _train(args: argparse.Namespace) -> int:
    from dynpush.policies.locomotion_train import LocomotionTrainConfig
    from dynpush.policies.train import TrainConfig
    from dynpush.policies.training import apply_recipe, launch_processes, run_config, train
    from dynpush.sim.config import ConfigError

    started = args.launched_at or time.time()  # --hours counts from the user's launch
    argv = args.argv[args.argv.index("train") + 1 :]
    command = args.launched_as or shlex.join(["dynpush", "train", *argv])  # recorded in the run's launches.jsonl
    config_class = {"push": TrainConfig, "locomotion": LocomotionTrainConfig}[args.task]
    if args.recipe and args.resume:
        raise ConfigError("--recipe configures a new run; --resume continues a run with its own config.json")
    cfg = apply_recipe(config_class.preset_config(args.preset), Path(args.recipe) if args.recipe else None,
                       args.set or [])
    name = args.name or (args.preset if args.task == "push" else f"{args.task}_{args.preset}")
    extend_to = None
    if args.resume and args.set:  # a resumed run keeps its config.json; only its length may change
        fields = sorted({item.split("=", 1)[0] for item in args.set})
        if fields != ["iterations"]:
            raise ConfigError(f"--resume continues the run's own config; only iterations=N may be set, got {fields}")
        extend_to = cfg.iterations
    if args.init_from and args.resume:
        raise ConfigError("--init-from starts a new run; --resume continues one: give one of them")
    if args.hours is not None and not args.hours > 0:
        raise ConfigError(f"--hours must be > 0, got {args.hours!r}")
    run_dir = Path(args.runs) / name
    if args.procs > 1:  # re-run this command under torchrun, one process per shard
        run_config(cfg, run_dir, args.resume, extend_to)  # what every rank would refuse, refused here in one line
        drop = [i for i, a in enumerate(argv) if a == "--procs" or a.startswith("--procs=")]
        for i in reversed(drop):
            del argv[i : i + (1 if "=" in argv[i] else 2)]
        return launch_processes(args.procs, [*argv, "--launched-as", command, "--launched-at", repr(started)])
    train(cfg, run_dir, resume=args.resume, command=command, extend_to=extend_to,
          init_from=Path(args.init_from) if args.init_from else None, hours=args.hours, started=started)
    return 0


def _imitate(args: argparse.Namespace) -> int:
    from dynpush.policies.imitation import ImitationConfig, imitate
    from dynpush.policies.train import TrainConfig
    from dynpush.policies.training import apply_recipe
    from dynpush.sim.config import ConfigError

    if args.recipe and args.resume:
        raise ConfigError("--recipe configures a new run; --resume continues a run with its own config")
    argv = args.argv[args.argv.index("imitate") + 1 :]
    cfg = apply_recipe(TrainConfig.preset_config(args.preset), Path(args.recipe) if args.recipe else None, args.set or [])
    given = {"rounds": args.rounds, "steps_per_round": args.steps_per_round, "expert_object_size": args.expert_object_size,
             "expert_overrides": tuple(args.expert_set) if args.expert_set else None}
    imitation = ImitationConfig(**{name: value for name, value in given.items() if value is not None})
    imitate(cfg, imitation, Path(args.runs) / args.name, resume=args.resume, command=shlex.join(["dynpush", "imitate", *argv]))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dynpush", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("env-info", help="print the scene, observation/action/constraint sizes, solver and device")
    p.add_argument("--num-envs", type=int, default=4)
    p.add_argument("--device", default="cpu")
    p.add_argument("--solver", default="xpbd")
    p.set_defaults(func=_env_info)

    p = sub.add_parser("train", help="train a push (or locomotion) policy with CaT-PPO (checkpoints and tensorboard in runs/NAME)")
    p.add_argument("--task", choices=("push", "locomotion"), default="push",
                   help="push: the goal-pushing policy (tracked base); locomotion: the legged 6D-command policy (MuJoCo-Warp)")
    p.add_argument("--preset", default="cpu", help="cpu (2-core machine) or paper (4096 envs, 20000 iterations, GPU)")
    p.add_argument("--name", default=None, help="run name (default: the preset)")
    p.add_argument("--runs", default="runs", help="folder of the runs")
    p.add_argument("--resume", action="store_true", help="continue the run from its latest checkpoint")
    p.add_argument("--init-from", default=None, metavar="CHECKPOINT",
                   help="start a new run from the actor and critic (with their normalisers) of another run's checkpoint,"
                        " e.g. runs/bc/imitation.pt, or from the actor of an exported policy.onnx (e.g. the shipped one;"
                        " needs critic_warmup_iterations > 0); optimizer, CaT state and iteration count start fresh")
    p.add_argument("--procs", type=int, default=1,
                   help="processes on this machine (torchrun, gloo on CPU / NCCL on GPUs); env.num_envs is split")
    p.add_argument("--recipe", default=None, metavar="FILE",
                   help="a file of field=value overrides, one per line (configs/recipes/); --set applies after it")
    p.add_argument("--set", nargs="*", metavar="FIELD=VALUE", help="override config fields, e.g. env.num_envs=256 iterations=100")
    p.add_argument("--hours", type=float, default=None, metavar="H",
                   help="stop at the last iteration boundary before H hours of this launch, with a checkpoint that"
                        " --resume continues")
    p.add_argument("--launched-as", default=None, help=argparse.SUPPRESS)  # the user's command, from a --procs relaunch
    p.add_argument("--launched-at", type=float, default=None, help=argparse.SUPPRESS)  # time.time() of that command
    p.set_defaults(func=_train)

    p = sub.add_parser("imitate", help="DAgger from the scripted pusher into a run's actor (runs/NAME/imitation.pt);"
                                      " fine-tune with dynpush train --name NAME --resume")
    p.add_argument("--preset", default="cpu", help="cpu or paper: the run's environment and networks")
    p.add_argument("--name", required=True, help="run name")
    p.add_argument("--runs", default="runs", help="folder of the runs")
    p.add_argument("--resume", action="store_true", help="continue after the last finished round")
    p.add_argument("--rounds", type=int, default=None, help="DAgger rounds (default 8)")
    p.add_argument("--steps-per-round", type=int, default=None, help="control steps of every world per round (default 250)")
    p.add_argument("--expert-object-size", type=float, default=None, metavar="METRES",
                   help="the expert assumes every object is a cuboid of this edge with a centred mass (it then acts only on"
                        " what the policy observes); default: it reads the true size, shape and centre of mass; kept on --resume")
    p.add_argument("--expert-set", nargs="*", metavar="FIELD=VALUE",
                   help="the expert's other gains (ScriptedPusherConfig fields, e.g. push_speed=1.0; after"
                        " --expert-object-size); kept on --resume; the fine-tuning's imitation term takes its own:"
                        " --set \"expert_overrides=('push_speed=1.0',)\"")
    p.add_argument("--recipe", default=None, metavar="FILE", help="a file of field=value overrides, as for train")
    p.add_argument("--set", nargs="*", metavar="FIELD=VALUE", help="override training config fields, as for train")
    p.set_defaults(func=_imitate)

    # Commands of the evaluation/export side and of the deployment runtime register themselves.
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
