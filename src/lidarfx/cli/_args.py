"""Argument types shared by the commands."""
from __future__ import annotations

import argparse
import math
import re


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
    """argparse type for a position ``x,y,z`` (e.g. ``--scanner 12.5,-3.0,1.7``): finite numbers."""
    try:
        vals = numbers(text, 3, "a position x,y,z")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"a position x,y,z must be finite numbers, got {text!r}")
    return vals


NUMBER_LIST_OPTIONS = ("--scanner", "--origin", "--rotation", "--reference-plane", "--range",
                       "--from", "--to", "--normal")
"""Options whose value is a comma-separated list of numbers, which may start with a minus sign."""
_NUMBER_LIST = re.compile(r"^-[0-9.][0-9.eE+\-]*(,[0-9.eE+\- ]*)+$")


def join_number_lists(argv: list[str]) -> list[str]:
    """``--scanner -1,2,3`` as ``--scanner=-1,2,3``: argparse takes a value starting with ``-``
    for an option unless it is one plain number, so a position west or south of the origin was
    refused ("expected one argument")."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in NUMBER_LIST_OPTIONS and i + 1 < len(argv) and _NUMBER_LIST.match(argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def check_output(input_path: str, output_path: str) -> None:
    """Before any work: the output is not the input (inputs are never modified), its format is
    known from the extension and its folder exists."""
    from .._atomic import check_not_same_file
    from ..io import check_output_path

    check_not_same_file(input_path, output_path)
    check_output_path(output_path)


COLUMNS_HELP = "column spec for text input, e.g. x,y,z,intensity,classification (default: its header line)"


def add_columns(p) -> None:
    """The ``--columns`` option of a command that reads point clouds."""
    p.add_argument("--columns", default=None, help=COLUMNS_HELP)


def columns_of(args) -> list[str] | None:
    """The ``--columns`` spec as a list (None when not given)."""
    return args.columns.split(",") if getattr(args, "columns", None) else None


def read_clouds(paths, args, progress=None):
    """Paths for the library to read, or, with ``--columns``, the clouds read with that spec
    (named as the user typed them, like files read by the library).

    The spec applies to the text and ``.npy`` inputs; other formats (LAS/LAZ, PLY, ``.npz``)
    name their own fields and are read as they are, so one command can mix them.  A spec
    that applies to none of the inputs is an error (it was meant for something)."""
    cols = columns_of(args)
    if paths is None or cols is None:
        return paths
    from .. import io

    takes = [io.accepts_columns(p) for p in paths]
    if not any(takes):
        return [io.read(paths[0], columns=cols)]  # the reader's one-line refusal
    out = []
    for p, t in zip(paths, takes):
        cloud = io.read(p, columns=cols if t else None, progress=progress)
        cloud.meta["name"] = str(p)
        out.append(cloud)
    return out


def read_input(args):
    """Read ``args.input`` for a command that writes ``args.output``.

    Refuses a bad output first (:func:`check_output`), applies the
    ``--columns`` spec of text input and shows progress unless ``-q``.  Returns
    ``(cloud, progress)``; ``progress`` is what to pass on to the later steps.
    """
    from .. import io

    check_output(args.input, args.output)
    progress = False if args.quiet else None
    return io.read(args.input, columns=columns_of(args), progress=progress), progress


def check_output_dir(path: str):
    """An output folder, before any work: not an existing file, its parent exists (it is
    created at the end, when there is something to write)."""
    from pathlib import Path

    from ..errors import LidarfxError

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise LidarfxError(f"{out} exists and is not a folder")
    if not out.parent.is_dir() and str(out.parent) not in ("", "."):
        raise LidarfxError(f"output folder's parent does not exist: {out.parent}")
    return out


def check_picture_path(path: str) -> None:
    """Refuse a picture path before any work: not a .png, or its folder is missing."""
    from pathlib import Path

    from .._atomic import check_output_folder
    from ..errors import LidarfxError

    if Path(path).suffix.lower() != ".png":
        raise LidarfxError(f"picture {path}: pictures are PNG files; give a path ending in .png")
    check_output_folder(path)


def emit_summary(args, summary: dict, printer) -> None:
    """The end of a command: the summary as JSON on stdout with ``--json``, else
    ``printer(summary)`` (a table on stderr) unless ``-q``."""
    import sys

    from .. import _json

    if getattr(args, "json", False):
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not getattr(args, "quiet", False):
        printer(summary)
