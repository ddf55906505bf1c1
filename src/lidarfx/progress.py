"""Progress bars (rich) for long work, shown on a terminal only unless forced."""
from __future__ import annotations

import contextlib
import sys
from typing import Callable, Iterator


def wanted(progress: bool | None, size: int, threshold: int = 2_000_000) -> bool:
    """``progress`` if given; by default only for large work on an interactive stderr."""
    if progress is not None:
        return bool(progress)
    return size >= threshold and sys.stderr.isatty()


@contextlib.contextmanager
def bar(description: str, total: int, enabled: bool) -> Iterator[Callable[[int], None]]:
    """Yield ``advance(k)``; draws a rich progress bar on stderr when ``enabled``."""
    if not enabled:
        yield lambda k: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as p:
        tid = p.add_task(description, total=total)
        yield lambda k: p.advance(tid, k)
