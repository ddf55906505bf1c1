"""Progress display (rich) for long work, on a terminal, chosen by the expected time.

A step that reports progress (``bar``) or a step that cannot (``stage``: one numba kernel, a
scikit-learn fit) is shown when it is going to take a while, whatever the point count: a bar
appears once the work has run for :data:`AUTO_AFTER` seconds and its rate says the whole will
take more than :data:`AUTO_LONGER_THAN` seconds; a stage shows a spinner with the elapsed time
after :data:`AUTO_AFTER` seconds.  ``progress=True`` shows them at once, ``False`` (``-q``)
never; by default only on an interactive stderr.
"""
from __future__ import annotations

import contextlib
import sys
import threading
import time
from typing import Callable, Iterator

AUTO_AFTER = 1.0
"""Seconds of work before an automatic bar or stage may appear."""
AUTO_LONGER_THAN = 3.0
"""Expected total seconds that earn an automatic bar."""


def wanted(progress: bool | None) -> bool | None:
    """``progress`` if given; by default ``None`` (decide by the expected time) on an interactive
    stderr and ``False`` elsewhere (a log file gets no bars)."""
    if progress is not None:
        return bool(progress)
    return None if sys.stderr.isatty() else False


def _progress(spinner: bool = False):
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    cols = ([SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn()] if spinner else
            [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn()])
    return Progress(*cols, console=Console(stderr=True), transient=True)


@contextlib.contextmanager
def bar(description: str, total: int, enabled: bool | None,
        clock: Callable[[], float] = time.monotonic) -> Iterator[Callable[[int], None]]:
    """Yield ``advance(k)`` for work of ``total`` units.  ``enabled``: True shows a bar now, False
    never, None (see :func:`wanted`) once the work has run :data:`AUTO_AFTER` s and is expected
    to take more than :data:`AUTO_LONGER_THAN` s in all."""
    if enabled is False or total <= 0:
        yield lambda k: None
        return
    t0 = clock()
    state = {"done": 0, "p": None, "task": None}

    def start() -> None:
        p = _progress()
        p.start()
        state["task"] = p.add_task(description, total=total, completed=state["done"])
        state["p"] = p

    def advance(k: int) -> None:
        state["done"] += k
        if state["p"] is None:
            elapsed = clock() - t0
            done = state["done"]
            if elapsed < AUTO_AFTER or done <= 0 or elapsed * total / done < AUTO_LONGER_THAN:
                return
            start()
        else:
            state["p"].advance(state["task"], k)

    if enabled:
        start()
    try:
        yield advance
    finally:
        if state["p"] is not None:
            state["p"].stop()


@contextlib.contextmanager
def stage(description: str, enabled: bool | None, delay: float | None = None) -> Iterator[None]:
    """A spinner with the elapsed time around one long step that reports no progress of its own
    (``enabled`` as for :func:`bar`; automatic: shown after ``delay`` = :data:`AUTO_AFTER` s)."""
    if enabled is False:
        yield
        return
    lock = threading.Lock()
    state = {"p": None, "done": False}

    def show() -> None:
        with lock:
            if state["done"]:
                return
            p = _progress(spinner=True)
            p.start()
            p.add_task(description, total=None)
            state["p"] = p

    timer = threading.Timer(0.0 if enabled else (AUTO_AFTER if delay is None else delay), show)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        with lock:
            state["done"] = True
            if state["p"] is not None:
                state["p"].stop()
