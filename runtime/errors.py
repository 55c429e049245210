"""Errors that stop the runtime before the robot moves."""


class StartupError(RuntimeError):
    """A check or connection at start-up failed; the message says what, where and what was expected."""
