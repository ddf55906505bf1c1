"""Errors a user can act on.  The CLI prints them as one line and exits with code 2."""


class LidarfxError(Exception):
    """Bad input or an impossible request: shown to the user as a one-line message."""


EXIT_USAGE = 2


class LidarfxWarning(UserWarning):
    """Something the user should know about a result (the CLI prints it as one line)."""
