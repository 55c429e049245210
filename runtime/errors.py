"""Errors that stop the runtime before the robot moves."""

from dynpush.errors import UserError


class StartupError(UserError, RuntimeError):
    """A check or connection at start-up failed; the message says what, where and what was expected."""
