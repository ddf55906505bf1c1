"""Errors a user can act on.  The CLI prints them as one line and exits with code 2 (bad input
or usage) or 1 (the environment failed: disk full, out of memory, a read-only file system)."""
from __future__ import annotations

import errno as _errno


class LidarfxError(Exception):
    """Bad input or an impossible request: shown to the user as a one-line message."""


EXIT_USAGE = 2
"""Exit code of bad input or usage (a one-line error naming what to change)."""
EXIT_FAILURE = 1
"""Exit code of a run the environment stopped: disk full, file too large, read-only file system,
quota exceeded, an I/O error, out of memory (:func:`environment_failure`)."""

ENVIRONMENT_ERRNOS = frozenset(getattr(_errno, name) for name in ("ENOSPC", "EDQUOT", "EFBIG", "EROFS", "EIO", "ENOMEM")
                               if hasattr(_errno, name))
"""OSError numbers that mean the machine, not the input, stopped the run."""


def environment_failure(exc: BaseException | None) -> BaseException | None:
    """The :class:`MemoryError` or the OSError of :data:`ENVIRONMENT_ERRNOS` that ``exc`` is or
    was raised from (its ``__cause__`` / ``__context__`` chain), else None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, MemoryError) or (isinstance(exc, OSError) and exc.errno in ENVIRONMENT_ERRNOS):
            return exc
        exc = exc.__cause__ if exc.__cause__ is not None else (None if exc.__suppress_context__ else exc.__context__)
    return None


class LidarfxWarning(UserWarning):
    """Something the user should know about a result (the CLI prints it as one line)."""


def check_int(name: str, value, lo: int, hi: int, *, hi_text: str | None = None, note: str = "") -> int:
    """``value`` as an int in ``lo .. hi`` (an integral float passes; bools, strings and 23-digit
    numbers that no kernel can take do not), else the one-line error
    "NAME must be an integer from LO to HI[NOTE], got VALUE"."""
    try:
        v = int(value)
        is_bool = isinstance(value, bool) or getattr(getattr(value, "dtype", None), "kind", "") == "b"
        ok = not is_bool and v == value and lo <= v <= hi
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise LidarfxError(f"{name} must be an integer from {lo} to {hi_text or hi}{note}, got {value!r}")
    return v


def check_number(name: str, value, lo: float, hi: float, *, open_lo: bool = False) -> float:
    """``value`` as a finite float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``; bools and
    strings do not pass), else the one-line error "NAME must be a number in [LO, HI], got VALUE"."""
    import math

    try:
        is_bool = isinstance(value, bool) or getattr(getattr(value, "dtype", None), "kind", "") == "b"
        v = float(value) if not is_bool and not isinstance(value, (str, bytes)) else math.nan
    except (TypeError, ValueError, OverflowError):
        v = math.nan
    if not (math.isfinite(v) and lo <= v <= hi) or (open_lo and v == lo):
        raise LidarfxError(f"{name} must be a number in {'(' if open_lo else '['}{lo:g}, {hi:g}], got {value!r}")
    return v


def check_seed(seed) -> int:
    """A random seed as numpy, numba and scikit-learn take it: an integer in 0 .. 2**32 - 1
    (the one rule of every seeded option: ``classify --seed``, ``features --seed``)."""
    return check_int("seed", seed, 0, 2**32 - 1)
