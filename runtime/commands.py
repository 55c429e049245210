"""``dynpush`` subcommands of dynpush.runtime (registered by ``dynpush.cli``): run, replay, sim2sim, demo.

Each prints one JSON document on stdout. Invalid configs, failed start-up checks and unreadable logs raise
user errors (``dynpush.errors``), which ``dynpush``'s ``main()`` prints as one line with exit status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
from pathlib import Path


def _run(args: argparse.Namespace) -> int:
    from .app import Runtime
    from .config import load_config

    stop = threading.Event()
    runtime = Runtime(load_config(args.config), stop)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    if args.max_seconds is not None:
        timer = threading.Timer(args.max_seconds, stop.set)
        timer.daemon = True
        timer.start()
    print(f"dynpush run: logging to {runtime.log.path}; Ctrl-C stops", file=sys.stderr)
    summary = runtime.run()
    print(json.dumps(summary, indent=1))
    return 0 if runtime.error is None else 1


def _replay(args: argparse.Namespace) -> int:
    from .replay import replay

    print(json.dumps(replay(Path(args.log), args.policy), indent=1))
    return 0


def _locomotion_policy(args: argparse.Namespace) -> str | None:
    """The locomotion ONNX the runtime runs: None with ``--locomotion onboard``; ``--locomotion-policy``, else the
    shipped one (``dynpush/shipped/locomotion``)."""
    from dynpush.shipped import shipped_file

    from .config import RuntimeConfigError

    if args.locomotion == "onboard":
        if args.locomotion_policy:
            raise RuntimeConfigError(f"--locomotion-policy {args.locomotion_policy} needs --locomotion onnx (the default,"
                                     " onboard, leaves the 6D command to the simulator's tracked base)")
        return None
    return args.locomotion_policy or str(shipped_file("locomotion/locomotion.onnx"))


def _stop_if_too_slow(report: dict) -> None:
    """``--on-slow stop``: after the report is written, the run ends with its one line (exit status 2)."""
    from .sim2sim import SimulatorTooSlowError

    if report["timing"] == "stopped_slow":
        raise SimulatorTooSlowError(report["realtime_check"]["message"])


def _sim2sim(args: argparse.Namespace) -> int:
    from .sim2sim import SimToSimOptions, describe_timing, run_sim2sim

    options = SimToSimOptions(policy=args.policy, episodes=args.episodes, mocap_noise_m=args.mocap_noise,
                              mocap_noise_rad=args.mocap_noise_rad, latency_s=args.latency, drop=args.drop,
                              lockstep=args.lockstep, seed=args.seed, config=args.config, overrides=args.set or [],
                              log_dir=args.log_dir, trajectory_png=args.png, record=args.record,
                              locomotion_policy=_locomotion_policy(args), on_slow=args.on_slow, min_rate=args.min_rate)
    report = run_sim2sim(options)
    text = json.dumps(report, indent=1)
    if args.out:
        Path(args.out).write_text(text)
    print(text)
    _stop_if_too_slow(report)
    print(describe_timing(report), file=sys.stderr)  # stdout holds the JSON document only
    return 0 if report["completed"] else 1


def _demo(args: argparse.Namespace) -> int:
    from dynpush.shipped import shipped_file, training_record

    from .sim2sim import SimToSimOptions, describe_timing, run_sim2sim

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    record = training_record()
    options = SimToSimOptions(policy=str(shipped_file("policy.onnx")), episodes=args.episodes, lockstep=args.lockstep,
                              seed=args.seed, overrides=args.set or [], log_dir=str(out),
                              trajectory_png=str(out / "demo.png"), locomotion_policy=_locomotion_policy(args),
                              on_slow=args.on_slow, min_rate=args.min_rate)
    legs = (f"legged robot, locomotion {options.locomotion_policy} in the runtime" if options.locomotion_policy
            else "tracked base")
    print(f"dynpush demo: the shipped policy ({record['run']}, {record['iterations']} iterations) through the"
          f" deployment runtime against the simulator ({legs}), {args.episodes} episodes"
          f" ({'lock-step' if args.lockstep else 'real time, 50 Hz'})", file=sys.stderr)
    report = run_sim2sim(options)
    (out / "demo.json").write_text(json.dumps(report, indent=1))
    _stop_if_too_slow(report)  # its episodes are not a real-time result: none is printed as one
    for episode in report["episode_results"]:
        outcome = (f"success at {episode['time_to_success_s']:.1f} s" if episode["success"]
                   else "toppled" if episode["toppled"] else "failed")
        print(f"episode {episode['index']}: {episode['shape']} {episode['mass_kg']:.1f} kg,"
              f" goal {math.hypot(*episode['goal'][:2]):.2f} m from its start -> {outcome}")
    evaluation = record["evaluation"]
    rate = report["success_rate"]
    print(f"success {100.0 * rate:.0f} % of {report['episodes']} episodes" if rate is not None else "no episode completed")
    print(describe_timing(report))
    print(f"(shipped evaluation, tracked base: {evaluation['success_percent']:.2f} % of {evaluation['episodes']} episodes;"
          f" paper {evaluation['paper']['success_rate']} %)")
    print(f"wrote {out / 'demo.png'} and {out / 'demo.json'}")
    return 0 if report["completed"] else 1


def _locomotion_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--locomotion", choices=("onboard", "onnx"), default="onboard",
                   help="onboard: the simulator's tracked base takes the 6D command; onnx: the runtime runs"
                        " --locomotion-policy and sends 17 joint targets to a legged simulated robot")
    p.add_argument("--locomotion-policy", default=None, metavar="ONNX",
                   help="locomotion.onnx (dynpush export of a locomotion run; default: the shipped one)")


REALTIME_CHECK_HELP = """\
real time (the default clock): the simulator must step once per 20 ms control period. It reports its
pace; when it steps fewer than --min-rate (default 0.9) of the control periods in a 1 s window (this
machine cannot run it in real time, so the robot would be controlled at a fraction of 50 Hz), one line
on stderr says so, e.g. "sim2sim: the simulator keeps 34 % of the 50 Hz control rate on this machine
(real time needs 90 %); switching to lock-step (simulated time)", and --on-slow decides: lockstep
(default) reruns the episodes in lock-step, stop writes the report and exits with status 2. The
report's "timing" says how its result was clocked: realtime, lockstep (--lockstep),
lockstep_fallback, stopped_slow (or realtime_unmeasured: the simulator ended before one control
period); "realtime_check" holds the measured rate."""


def _realtime_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--on-slow", choices=("lockstep", "stop"), default="lockstep",  # sim2sim.ON_SLOW (not imported: parsing stays light)
                   help="real time, the simulator falls behind the control rate: rerun in lock-step (default) or stop"
                        " with exit status 2 (see below)")
    p.add_argument("--min-rate", type=float, default=0.9, metavar="FRACTION",
                   help="real time needs the simulator to step at least this fraction of the control periods in"
                        " every 1 s window (default 0.9)")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds this package's subcommands to the ``dynpush`` parser."""
    p = subparsers.add_parser("run", help="run the deployment runtime (50 Hz loop) from a YAML config")
    p.add_argument("config", help="runtime YAML (see configs/runtime_*.yaml)")
    p.add_argument("--max-seconds", type=float, default=None, help="stop after this long (default: until Ctrl-C)")
    p.set_defaults(func=_run)

    p = subparsers.add_parser("replay", help="re-run the policies on a tick log's observations; largest deviation")
    p.add_argument("log", help="tick log (.dplog) written by dynpush run or sim2sim")
    p.add_argument("--policy", default=None, help="push policy ONNX to compare (default: the one in the log's config)")
    p.set_defaults(func=_replay)

    p = subparsers.add_parser("sim2sim", help="the runtime against the simulator over loopback UDP; success rate",
                              epilog=REALTIME_CHECK_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("policy", help="push policy ONNX")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--mocap-noise", type=float, default=0.0, metavar="M", help="mocap position noise std per axis [m]")
    p.add_argument("--mocap-noise-rad", type=float, default=0.0, metavar="RAD", help="mocap rotation noise std [rad]")
    p.add_argument("--latency", type=float, default=0.0, metavar="S", help="mocap latency [s] (whole control periods)")
    p.add_argument("--drop", type=float, default=0.0, metavar="P", help="probability a mocap frame is lost")
    p.add_argument("--lockstep", action="store_true", help="simulated time, one tick per simulator step (default: real time)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--config", default=None, help="runtime YAML to start from (safety limits, timeouts, ramp)")
    p.add_argument("--set", nargs="*", metavar="env.FIELD=VALUE", help="simulator overrides, e.g. env.episode_length_s=10.0")
    p.add_argument("--log-dir", default="runs/sim2sim", help="folder of the runtime's tick log")
    p.add_argument("--out", default=None, help="also write the report to this JSON file")
    p.add_argument("--png", default=None, help="top-down picture of the episodes' paths (as dynpush play draws them)")
    p.add_argument("--record", default=None, metavar="NPZ",
                   help="the simulator writes what it saw per step (its own observations, poses, each episode's start"
                        " state) to this file, for benchmarks/chain_side_by_side.py")
    _realtime_arguments(p)
    _locomotion_arguments(p)
    p.set_defaults(func=_sim2sim)

    p = subparsers.add_parser("demo", help="the shipped policy through the runtime against the simulator (offline)",
                              epilog=REALTIME_CHECK_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episodes", type=int, default=4)
    p.add_argument("--lockstep", action="store_true", help="simulated time, as fast as it runs (default: real time)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", nargs="*", metavar="env.FIELD=VALUE", help="simulator overrides, e.g. env.episode_length_s=10.0")
    p.add_argument("--out", default="runs/demo", help="folder of demo.png, demo.json and the runtime's tick log")
    _realtime_arguments(p)
    _locomotion_arguments(p)
    p.set_defaults(func=_demo)
