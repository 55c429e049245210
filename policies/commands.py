"""``dynpush`` subcommands of dynpush.policies (registered by ``dynpush.cli``)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds this package's subcommands to the ``dynpush`` parser."""
