"""Errors a user can act on.  The CLI prints them as one line and exits with code 2."""


class LidarfxError(Exception):
    """Bad input or an impossible request: shown to the user as a one-line message."""


EXIT_USAGE = 2


class LidarfxWarning(UserWarning):
    """Something the user should know about a result (the CLI prints it as one line)."""


def check_seed(seed) -> int:
    """A random seed as numpy, numba and scikit-learn take it: an integer in 0 .. 2**32 - 1
    (the one rule of every seeded option: ``classify --seed``, ``features --seed``)."""
    try:
        v = int(seed)
        ok = v == seed and 0 <= v < 2**32
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise LidarfxError(f"seed must be an integer from 0 to {2**32 - 1}, got {seed!r}")
    return v
