"""The ``dynpush`` command line."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dynpush", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    # Every package's commands register themselves (its commands.py), in this order: the simulator's, the
    # training/evaluation/export side's and the deployment runtime's.
    from dynpush.policies.commands import register as register_policy_commands
    from dynpush.runtime.commands import register as register_runtime_commands
    from dynpush.sim.commands import register as register_sim_commands

    register_sim_commands(sub)
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
