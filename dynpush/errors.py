"""Errors in what the user gave dynpush: a file, a config field, an argument.

``dynpush``'s ``main()`` prints a :class:`UserError` as one line (``dynpush: <message>``) and exits with
status 2; any other exception is a bug in dynpush and keeps its traceback. Every user error subclasses
:class:`UserError` and also the built-in type its callers catch (``ValueError``, ``FileNotFoundError``...).
Only the standard library here: the deployment runtime imports this module.
"""


class UserError(Exception):
    """Something the user gave is wrong; the message names the file or field and what was expected."""


class MissingFileError(UserError, FileNotFoundError):
    """A file or folder the user named (or one a run folder must hold) does not exist."""


class CorruptFileError(UserError, ValueError):
    """A file the user named exists but cannot be read as what it should be (truncated, foreign, malformed)."""
