"""``dynpush`` subcommands of dynpush.runtime (registered by ``dynpush.cli``)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds this package's subcommands to the ``dynpush`` parser."""
