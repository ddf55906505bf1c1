"""Argument types shared by the commands."""
from __future__ import annotations

import argparse


def numbers(text: str, n: int, what: str = "value") -> list[float]:
    """``n`` comma-separated numbers (spaces allowed); ValueError with a one-line message otherwise."""
    try:
        vals = [float(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        raise ValueError(f"{what} must be {n} comma-separated numbers, got {text!r}") from None
    if len(vals) != n:
        raise ValueError(f"{what} must be {n} comma-separated numbers, got {text!r}")
    return vals


def xyz(text: str) -> list[float]:
    """argparse type for a position ``x,y,z`` (e.g. ``--scanner 12.5,-3.0,1.7``)."""
    try:
        return numbers(text, 3, "a position x,y,z")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
