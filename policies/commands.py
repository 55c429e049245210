"""``dynpush`` subcommands of dynpush.policies (registered by ``dynpush.cli``): train, imitate, export, eval,
eval-locomotion, scenario, footprints, play, curve, ship.

The four evaluation studies are a command each: ``eval`` (paper Tables I/II of a push policy), ``eval-locomotion``
(command tracking of a locomotion policy), ``scenario`` (goal sequences of a scenario file) and ``footprints`` (EE
height vs object footprint). Each checks that its ONNX is of its task (push or locomotion) before anything is run
or written, and a policy of the other task is refused in one line that names the command for it.

train and imitate read ``args.argv``, the arguments ``dynpush.cli.main`` parsed, to record the user's command.
"""

from __future__ import annotations

import argparse
import json
import shlex
import time
from pathlib import Path

EVAL_EPILOG = """\
Tables I and II: the first episode of every world, --episodes of them -> eval.json, eval.png

The other studies are commands of their own:
  dynpush eval-locomotion LOCOMOTION_ONNX  command tracking per component -> locomotion_eval.json, .png
  dynpush scenario POLICY FILE             objects through goal sequences (scenarios/*.yaml) -> scenario.json, .png
  dynpush footprints POLICY                EE height vs object footprint (Fig. "EE height boxplot")
                                           -> footprints.json, .png

Table I ablations are separate trainings evaluated the same way, e.g.
  dynpush train --name no_balance --set "disabled_constraint_groups=('object_balance',)"
  dynpush train --name no_surface --set env.sampling.reach_target_on_surface=False
  dynpush export runs/no_balance && dynpush eval runs/no_balance/policy.onnx
"""

# Options that dynpush eval had before each study became a command of its own: the command that took each over.
MOVED_EVAL_OPTIONS = {
    "--scenario": ("?", "dynpush scenario POLICY FILE"),
    "--footprints": (0, "dynpush footprints POLICY"),
    "--footprint-episodes": ("?", "dynpush footprints POLICY --episodes-per-footprint N"),
    "--seconds": ("?", "dynpush eval-locomotion LOCOMOTION_ONNX --seconds S"),
}


def _train(args: argparse.Namespace) -> int:
    from dynpush.sim.config import ConfigError

    from .tasks import TASKS
    from .overrides import apply_recipe
    from .processes import launch_processes
    from .training import run_config, train

    started = args.launched_at or time.time()  # --hours counts from the user's launch
    argv = args.argv[args.argv.index("train") + 1 :]
    command = args.launched_as or shlex.join(["dynpush", "train", *argv])  # recorded in the run's launches.jsonl
    task = TASKS[args.task]
    if args.recipe and args.resume:
        raise ConfigError("--recipe configures a new run; --resume continues a run with its own config.json")
    cfg = apply_recipe(task.config_class().preset_config(args.preset), Path(args.recipe) if args.recipe else None,
                       args.set or [])
    name = args.name or task.run_prefix + args.preset
    resume_overrides = list(args.set or []) if args.resume else []  # checked against the run's config.json
    if args.init_from and args.resume:
        raise ConfigError("--init-from starts a new run; --resume continues one: give one of them")
    if args.hours is not None and not args.hours > 0:
        raise ConfigError(f"--hours must be > 0, got {args.hours!r}")
    run_dir = Path(args.runs) / name
    if args.procs > 1:  # re-run this command under torchrun, one process per shard
        run_config(cfg, run_dir, args.resume, resume_overrides)  # what every rank would refuse, refused here in one line
        drop = [i for i, a in enumerate(argv) if a == "--procs" or a.startswith("--procs=")]
        for i in reversed(drop):
            del argv[i : i + (1 if "=" in argv[i] else 2)]
        return launch_processes(args.procs, [*argv, "--launched-as", command, "--launched-at", repr(started)])
    train(cfg, run_dir, resume=args.resume, command=command, resume_overrides=resume_overrides,
          init_from=Path(args.init_from) if args.init_from else None, hours=args.hours, started=started)
    return 0


def _imitate(args: argparse.Namespace) -> int:
    from dynpush.sim.config import ConfigError

    from .imitation import ImitationConfig, imitate
    from .train import TrainConfig
    from .overrides import apply_recipe

    if args.recipe and args.resume:
        raise ConfigError("--recipe configures a new run; --resume continues a run with its own config")
    argv = args.argv[args.argv.index("imitate") + 1 :]
    cfg = apply_recipe(TrainConfig.preset_config(args.preset), Path(args.recipe) if args.recipe else None, args.set or [])
    given = {"rounds": args.rounds, "steps_per_round": args.steps_per_round, "expert_object_size": args.expert_object_size,
             "expert_overrides": tuple(args.expert_set) if args.expert_set else None}
    imitation = ImitationConfig(**{name: value for name, value in given.items() if value is not None})
    imitate(cfg, imitation, Path(args.runs) / args.name, resume=args.resume, command=shlex.join(["dynpush", "imitate", *argv]))
    return 0


def _export(args: argparse.Namespace) -> int:
    from .tasks import task_of_run

    task = task_of_run(Path(args.run))
    print(task.exported(task.export(Path(args.run), args.checkpoint, Path(args.out) if args.out else None)))
    return 0


class _MovedOption(argparse.Action):
    """An option that moved to another command (``MOVED_EVAL_OPTIONS``): parsing it records the one-line error that
    names that command; the command then stops with it (exit status 2) before it reads or writes anything."""

    def __init__(self, option_strings, dest, moved_to: str, **kwargs):
        self.moved_to = moved_to
        super().__init__(option_strings, dest, help=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, f"{option_string} is no longer an option of dynpush eval: run {self.moved_to}")


def _checked_policy(args: argparse.Namespace, task: str) -> Path:
    """``args.policy`` once it is known to be a readable ONNX of ``task`` (push or locomotion). A missing or unreadable
    file stops with one line naming it, a policy of the other task with one line naming the command that evaluates it
    (:class:`~dynpush.errors.UserError`)."""
    from dynpush.errors import UserError

    from .tasks import TASKS, task_of_onnx

    policy = Path(args.policy)
    if task_of_onnx(policy) is not TASKS[task]:
        raise UserError(TASKS[task].refusal(policy, args.command))
    return policy


def _eval(args: argparse.Namespace) -> int:
    from dynpush.errors import UserError

    from .evaluate import EvalConfig, evaluate

    if args.moved:  # an option of another study's command (MOVED_EVAL_OPTIONS)
        raise UserError(args.moved)
    policy = _checked_policy(args, "push")
    cfg = EvalConfig(episodes=args.episodes, num_envs=args.num_envs, noise=args.noise, device=args.device,
                     seed=args.seed, overrides=tuple(args.set or ()))
    out = Path(args.out) if args.out else policy.parent / "eval"
    result = evaluate(policy, cfg, out)
    print(f"success {result['success_rate']:.2f} % (paper {result['paper']['success_rate']}),"
          f" toppled {result['toppled_rate']:.2f} % (paper {result['paper']['toppled_rate']})")
    print("violated [% of time]: " + ", ".join(f"{k} {v:.3f}" for k, v in result["constraint_violation_percent"].items()))
    print(f"wrote {out / 'eval.json'} and {out / 'eval.png'}")
    return 0


def _eval_locomotion(args: argparse.Namespace) -> int:
    from .locomotion_eval import LocomotionEvalConfig, evaluate_locomotion

    policy = _checked_policy(args, "locomotion")
    cfg = LocomotionEvalConfig(num_envs=args.num_envs, seconds=args.seconds, seed=args.seed, noise=args.noise,
                               overrides=tuple(args.set or ()))
    out = Path(args.out) if args.out else policy.parent / "locomotion_eval"
    result = evaluate_locomotion(policy, cfg, out)
    print("tracking RMS error: " + ", ".join(f"{name} {value:.3f} {result['units'][name]}"
                                            for name, value in result["tracking_rms"].items()) + f"; fell {result['fell_percent']:.1f} %")
    print(f"wrote {out / 'locomotion_eval.json'} and {out / 'locomotion_eval.png'}")
    return 0


def _scenario(args: argparse.Namespace) -> int:
    from .scenario_schema import load_scenario
    from .scenarios import run_scenario

    policy = _checked_policy(args, "push")
    scenario = load_scenario(Path(args.file))
    out = Path(args.out) if args.out else policy.parent / f"scenario_{scenario.name}"
    result = run_scenario(policy, scenario, out, args.noise, args.device, args.seed, tuple(args.set or ()))
    summary = {name: {k: row[k] for k in ("success_rate", "face_switches_per_goal")}
               for name, row in result["objects"].items()}
    print(json.dumps(summary, indent=1))
    print(f"wrote {out / 'scenario.json'} and {out / 'scenario.png'}")
    return 0


def _footprints(args: argparse.Namespace) -> int:
    from .footprints import FootprintConfig, footprint_study

    policy = _checked_policy(args, "push")
    cfg = FootprintConfig(successful_episodes=args.episodes_per_footprint, num_envs=args.num_envs,
                          device=args.device, seed=args.seed, overrides=tuple(args.set or ()))
    out = Path(args.out) if args.out else policy.parent / "footprints"
    result = footprint_study(policy, cfg, out)
    for row in result["footprints"]:
        stats = row["ee_height_in_contact_m"]
        print(f"footprint {row['side_m']:.2f} m: {row['successful_episodes']} successful episodes,"
              f" median EE height in contact {stats.get('median', float('nan')):.3f} m")
    print(f"wrote {out / 'footprints.json'} and {out / 'footprints.png'}")
    return 0


def _play(args: argparse.Namespace) -> int:
    from .play import play

    policy = Path(args.policy)
    out = Path(args.out) if args.out else policy.parent / "play.png"
    out = out if out.suffix == ".png" else out.with_suffix(".png")  # the file matplotlib writes
    result = play(policy, args.episodes, out, Path(args.usd) if args.usd else None, args.noise, args.seed,
                  tuple(args.set or ()))
    outcomes = ["success" if e["success"] else "toppled" if e["toppled"] else "failed" for e in result["episodes"]]
    print(f"{', '.join(outcomes)}; wrote {out}" + (f" and {args.usd}" if args.usd else ""))
    return 0


def _curve(args: argparse.Namespace) -> int:
    from .progress import SMOOTHING, plot_learning_curve
    from .run_folder import read_json
    from .tasks import task_of_config

    run = Path(args.run)
    out = Path(args.out) if args.out else run / "learning_curve.png"
    config = run / "config.json"
    data = read_json(config) if config.exists() else {}
    paper = task_of_config(data).paper_success(data) if data else None  # a curve without config.json: no paper line
    summary = plot_learning_curve(run, out, paper)
    rates = ", ".join(f"{key[:-len('_percent')]} {value:.1f} %" for key, value in summary.items() if key.endswith("_percent"))
    print(f"{summary['iterations']} iterations in {summary['hours']:.2f} h: {rates} (mean of the last {SMOOTHING}"
          f" iterations); wrote {out}")
    return 0


def _ship(args: argparse.Namespace) -> int:
    from .ship import ship
    from .tasks import task_of_run

    task = task_of_run(Path(args.run))
    out = Path(args.to) if args.to else task.shipped_dir
    record = ship(Path(args.run), out, args.checkpoint, args.episodes, args.seed, args.worlds)
    trained = f"shipped {record['run']}/{record['checkpoint']} ({record['iterations']} iterations, {record['training_wall_clock_h']:.2f} h)"
    print(f"{trained}: {task.shipped_summary(record['evaluation'])}; wrote {out}")
    return 0


def _common(p: argparse.ArgumentParser, out: str, policy: str = "push policy.onnx written by dynpush export",
            device: bool = True, noise: bool = True) -> None:
    """The arguments of the commands that run an exported policy in the simulator: the policy (``policy``: its help),
    --out (``out``: its help, with the default), --noise (unless ``noise`` is False), --seed, --device (unless
    ``device`` is False) and --set."""
    p.add_argument("policy", help=policy)
    p.add_argument("--out", default=None, metavar="PATH", help=out)
    if noise:
        p.add_argument("--noise", action=argparse.BooleanOptionalAction, default=None,
                       help="actor observation noise on/off (default: as in training)")
    p.add_argument("--seed", type=int, default=0, metavar="N", help="seed of the simulated worlds (default 0)")
    if device:
        p.add_argument("--device", default="cpu", metavar="DEVICE",
                       help="simulation device, e.g. cpu or cuda:0 (default cpu)")
    p.add_argument("--set", nargs="*", metavar="env.FIELD=VALUE", help="environment overrides, e.g. env.episode_length_s=10.0")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds this package's subcommands to the ``dynpush`` parser."""
    from .tasks import TASKS

    p = subparsers.add_parser("train", help="train a push (or locomotion) policy with CaT-PPO"
                                            " (checkpoints and tensorboard in runs/NAME)")
    p.add_argument("--task", choices=tuple(TASKS), default="push",
                   help="push: the goal-pushing policy (tracked base); locomotion: the legged 6D-command policy (MuJoCo-Warp)")
    p.add_argument("--preset", default="cpu", help="cpu (2-core machine) or paper (4096 envs, 20000 iterations, GPU)")
    p.add_argument("--name", default=None,
                   help="run name (default: the preset, e.g. cpu; locomotion_cpu for --task locomotion)")
    p.add_argument("--runs", default="runs", help="folder of the runs")
    p.add_argument("--resume", action="store_true", help="continue the run from its latest checkpoint")
    p.add_argument("--init-from", default=None, metavar="CHECKPOINT",
                   help="start a new run from the actor and critic (with their normalisers) of another run's checkpoint,"
                        " e.g. runs/bc/imitation.pt, or from the actor of an exported policy.onnx (e.g. the shipped one;"
                        " needs fine_tune.critic_warmup_iterations > 0); optimizer, CaT state and iteration count start fresh")
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

    p = subparsers.add_parser("imitate", help="DAgger from the scripted pusher into a run's actor (runs/NAME/imitation.pt);"
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
                        " --set \"fine_tune.expert_overrides=('push_speed=1.0',)\"")
    p.add_argument("--recipe", default=None, metavar="FILE", help="a file of field=value overrides, as for train")
    p.add_argument("--set", nargs="*", metavar="FIELD=VALUE", help="override training config fields, as for train")
    p.set_defaults(func=_imitate)

    p = subparsers.add_parser("export", help="export a run's checkpoint to ONNX with its contract (runs/NAME/policy.onnx;"
                                             " a locomotion run: runs/NAME/locomotion.onnx)")
    p.add_argument("run", help="run folder (runs/NAME with config.json and model_*.pt)")
    p.add_argument("--checkpoint", default=None, help="checkpoint file in the run folder (default: the latest model_K.pt)")
    p.add_argument("--out", default=None, help="output file (default: RUN/policy.onnx)")
    p.set_defaults(func=_export)

    p = subparsers.add_parser("eval", help="evaluate a push policy.onnx on the paper's Tables I/II (eval.json, eval.png)",
                              epilog=EVAL_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(p, out="output folder (default: eval/ beside the policy)")
    p.add_argument("--episodes", type=int, default=4096, metavar="N",
                   help="first episodes to run, one per world (default 4096, as in the paper)")
    p.add_argument("--num-envs", type=int, default=None, metavar="N",
                   help="worlds simulated together; rounds run until --episodes are done (default: min(episodes, 1024))")
    for option, (nargs, moved_to) in MOVED_EVAL_OPTIONS.items():
        p.add_argument(option, action=_MovedOption, dest="moved", nargs=nargs, moved_to=moved_to)
    p.set_defaults(func=_eval)

    p = subparsers.add_parser("eval-locomotion", help="evaluate a locomotion.onnx: command tracking per component, falls,"
                                                      " constraint violations (locomotion_eval.json, .png)")
    _common(p, out="output folder (default: locomotion_eval/ beside the policy)", device=False,
            policy="locomotion.onnx written by dynpush export of a locomotion run")
    p.add_argument("--num-envs", type=int, default=256, metavar="N", help="worlds, one held command each (default 256)")
    p.add_argument("--seconds", type=float, default=10.0, metavar="S",
                   help="seconds each world holds its command; the first 2 s are not counted (default 10)")
    p.set_defaults(func=_eval_locomotion)

    p = subparsers.add_parser("scenario", help="push objects through the goal sequences of a scenario file (paper IV-C):"
                                               " success and contact face switches per goal (scenario.json, .png)")
    _common(p, out="output folder (default: scenario_NAME/ beside the policy, NAME: the file's name field)")
    p.add_argument("file", help="scenario YAML: objects and goal sequences (see scenarios/*.yaml)")
    p.set_defaults(func=_scenario)

    p = subparsers.add_parser("footprints", help="EE height while in contact for six object footprints, observation"
                                                 " noise off (paper Fig. \"EE height boxplot\"; footprints.json, .png)")
    _common(p, out="output folder (default: footprints/ beside the policy)", noise=False)
    p.add_argument("--episodes-per-footprint", type=int, default=1000, metavar="N",
                   help="successful episodes to collect per footprint (default 1000, as in the paper)")
    p.add_argument("--num-envs", type=int, default=512, metavar="N", help="worlds simulated together per footprint (default 512)")
    p.set_defaults(func=_footprints)

    p = subparsers.add_parser("play", help="roll out a few episodes: top-down PNG, optionally a USD animation")
    _common(p, out="PNG file (default: play.png beside the policy)", device=False)
    p.add_argument("--episodes", type=int, default=4, metavar="N", help="episodes, one per world (default 4)")
    p.add_argument("--usd", default=None, metavar="FILE", help="also record the rollout as a USD animation (out.usda text, out.usdc binary)")
    p.set_defaults(func=_play)

    p = subparsers.add_parser("curve", help="learning curve of a run: success and rewards vs wall-clock hours (PNG)")
    p.add_argument("run", help="run folder (runs/NAME with progress.jsonl)")
    p.add_argument("--out", default=None, help="PNG file (default: RUN/learning_curve.png)")
    p.set_defaults(func=_curve)

    p = subparsers.add_parser("ship", help="export a run's policy into the package with its eval, curve and provenance")
    p.add_argument("run", help="run folder (runs/NAME)")
    p.add_argument("--checkpoint", default=None, help="checkpoint file in the run folder (default: the latest model_K.pt)")
    p.add_argument("--episodes", type=int, default=4096, help="evaluation episodes (paper: 4096)")
    p.add_argument("--worlds", type=int, default=256, help="a locomotion run: worlds of its tracking evaluation")
    p.add_argument("--seed", type=int, default=0, help="evaluation seed")
    p.add_argument("--to", default=None, help="output folder (default: the installed package's dynpush/shipped)")
    p.set_defaults(func=_ship)
