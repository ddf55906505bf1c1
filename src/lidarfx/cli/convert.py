"""``lidarfx convert``: convert between LAS/LAZ, PLY, text and NumPy point clouds."""
from __future__ import annotations

import argparse
from typing import Any

EPILOG = """examples:
  lidarfx convert scan.laz scan.las                      # LAS header, CRS and VLRs pass through
  lidarfx convert points.txt points.laz --columns x,y,z,intensity,classification
  lidarfx convert oakland.xyz_label_conf oakland.ply --ascii
  lidarfx convert scan.laz scan.csv --precision 2

formats by extension: .las .laz .ply .xyz .txt .csv .pts .xyz_label_conf .npy .npz
"""


def register(subparsers: Any) -> None:
    """Add the ``convert`` sub-command."""
    p = subparsers.add_parser(
        "convert",
        help="convert between LAS/LAZ, PLY, text and NumPy point clouds",
        description="Convert a point cloud to another format (chosen by the output extension).\n"
        "The input is never modified; the output appears only when complete.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", metavar="IN", help="input point cloud")
    p.add_argument("output", metavar="OUT", help="output point cloud")
    p.add_argument(
        "--columns",
        metavar="SPEC",
        help="column names of a text / .npy input, comma-separated; '-' skips a column "
        "(e.g. x,y,z,intensity,-,classification)",
    )
    p.add_argument("--ascii", action="store_true", help="write PLY as text instead of binary")
    p.add_argument("--precision", type=int, metavar="N", help="decimals of x, y, z in text output, 0..17 (default 3)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Read ``args.input``, write ``args.output``; returns the exit code."""
    from pathlib import Path

    from ..errors import LidarfxError
    from ..io import FORMATS, read, write

    out_format = FORMATS.get(Path(args.output).suffix.lower())
    opts: dict[str, Any] = {}
    if args.ascii:
        if out_format != "ply":
            raise LidarfxError("--ascii applies to .ply output only")
        opts["ascii"] = True
    if args.precision is not None:
        if out_format != "ascii":
            raise LidarfxError("--precision applies to text output (.xyz .txt .csv .pts) only")
        from ..io.ascii import check_precision

        opts["precision"] = check_precision(args.precision)  # before reading
    from ._args import check_output

    check_output(args.input, args.output)  # the output before reading: format, folder, not over a file
    cloud = read(args.input, columns=args.columns)
    write(cloud, args.output, **opts)
    print(f"{args.input} -> {args.output}: {len(cloud):,} points, {len(cloud.names)} attributes")
    return 0
