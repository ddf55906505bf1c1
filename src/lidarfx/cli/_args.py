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


def finite_numbers(counts: tuple[int, ...], what: str):
    """An argparse type: comma-separated finite numbers, as many as one of ``counts``
    (``what`` names the value in the one-line error, e.g. "a position x,y[,z]")."""

    def parse(text: str) -> list[float]:
        n = len(text.split(","))
        try:
            vals = numbers(text, n if n in counts else counts[-1], what)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        if not all(math.isfinite(v) for v in vals):
            raise argparse.ArgumentTypeError(f"{what} must be finite numbers, got {text!r}")
        return vals

    return parse


xyz = finite_numbers((3,), "a position x,y,z")
"""argparse type for a position ``x,y,z`` (e.g. ``--scanner 12.5,-3.0,1.7``): finite numbers."""


NUMBER_LIST_OPTIONS = ("--scanner", "--origin", "--rotation", "--reference-plane", "--range",
                       "--from", "--to", "--normal", "--bounds")
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


def check_output_dir(path: str, files: tuple[str, ...] | None = None):
    """An output folder, before any work: not an existing file, its parent exists (it is
    created at the end, when there is something to write).  Without ``--force`` the folder must
    be new or empty (a command's products never mix with another run's), or, when the command
    writes only the ``files`` named (a report's ``index.html``), none of those may exist."""
    from pathlib import Path

    from .._atomic import check_new_file, check_new_folder
    from ..errors import LidarfxError

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise LidarfxError(f"{out} exists and is not a folder")
    if not out.parent.is_dir() and str(out.parent) not in ("", "."):
        raise LidarfxError(f"output folder's parent does not exist: {out.parent}")
    if files is None:
        check_new_folder(out)
    else:
        for name in files:
            check_new_file(out / name)
    return out


def check_picture_path(path: str) -> None:
    """Refuse a picture path before any work: not a .png, or its folder is missing."""
    from pathlib import Path

    from .._atomic import check_output_folder
    from ..errors import LidarfxError

    if Path(path).suffix.lower() != ".png":
        raise LidarfxError(f"picture {path}: pictures are PNG files; give a path ending in .png")
    check_output_folder(path)


def add_line_outputs(p, what: str, picture: str, cloud: str) -> None:
    """The outputs of a line product beside its GeoJSON (``what``: "lines", "members"):
    ``--dxf``, ``--csv [CSV]`` (with the JSON of the vertices), ``--picture``, ``--cloud``;
    checked by :func:`line_output_paths`."""
    p.add_argument("--dxf", default=None, metavar="DXF", help=f"also write the {what} as DXF 3-D polylines")
    p.add_argument("--csv", nargs="?", const="", default=None, metavar="CSV",
                   help=f"also write the per-{what[:-1]} table (default path: OUTPUT with .csv) and its JSON with "
                        "the vertices")
    p.add_argument("--picture", default=None, metavar="PNG", help=picture)
    p.add_argument("--cloud", default=None, metavar="OUT", help=cloud)


def line_output_paths(args, what: str = "lines") -> dict:
    """The paths of :func:`add_line_outputs`, checked before any work: ``geojson``, ``dxf``,
    ``csv``, ``json`` (the CSV's vertices, ``.lines.json``), ``picture``, ``cloud`` (None when
    not asked for); each with its extension, not the input, in an existing folder, all distinct."""
    from pathlib import Path

    from .._atomic import check_not_same_file, check_output_folder
    from ..errors import LidarfxError
    from ..io import check_output_path

    out = Path(args.output)
    if out.suffix.lower() not in (".geojson", ".json"):
        raise LidarfxError(f"{args.output}: the {what} are GeoJSON; give a path ending in .geojson")
    paths: dict = {"geojson": args.output, "dxf": args.dxf, "csv": None, "json": None,
                   "picture": args.picture, "cloud": args.cloud}
    if args.dxf is not None and Path(args.dxf).suffix.lower() != ".dxf":
        raise LidarfxError(f"{args.dxf}: give a DXF path ending in .dxf")
    if args.csv is not None:
        csv = args.csv or str(out.with_suffix(".csv"))
        if Path(csv).suffix.lower() != ".csv":
            raise LidarfxError(f"{csv}: give a table path ending in .csv")
        paths["csv"] = csv
        paths["json"] = str(Path(csv).with_suffix(".lines.json"))
    if args.picture:
        check_picture_path(args.picture)
    if args.cloud:
        check_not_same_file(args.input, args.cloud)
        check_output_path(args.cloud)
    given = [str(Path(v).resolve()) for v in paths.values() if v]
    if len(set(given)) < len(given):
        raise LidarfxError("two outputs have the same path; give each output its own file")
    for v in paths.values():
        if v:
            check_not_same_file(args.input, v)
            check_output_folder(v)
    return paths


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
