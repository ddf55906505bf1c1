"""``lidarfx merge FILES... OUT``: several clouds into one, headers reconciled or refused."""
from __future__ import annotations

import argparse
import sys

from ._args import add_columns, columns_of, emit_summary

EPILOG = """examples:
  lidarfx merge a.laz b.laz c.laz all.laz
  lidarfx merge tiles/ all.laz                                 # every .las / .laz of a folder
  lidarfx merge "tiles/*.laz" extra.las all.laz --json
  lidarfx merge scan1.ply scan2.xyz both.ply --columns x,y,z,intensity

PDAL: filters.merge / pdal merge; LAStools: lasmerge; lidR: rbind / readLAS(files);
CloudCompare: Edit > Merge.

The output holds every point of every input, file after file:
  CRS          the same in every input that has one, else refused (reproject first)
  point format the smallest of the inputs' family holding every field (1 + 2 -> 3,
               3 + 6 -> 7); scan_angle_rank becomes scan_angle (0.006 deg steps)
  extra bytes  the union by name; one name with two types is refused (naming both
               files); missing values: no-data, else NaN / 0
  scale        the finest of the inputs; offsets so that every coordinate fits
               32-bit integers (refused when the extent cannot)
Coordinates are exact when the scales and offsets allow it, else within half the
output scale; every other field is copied.  LAS/LAZ into LAS/LAZ is streamed
(memory does not grow with the inputs); other formats are merged in memory.
docs/everyday.md#merge.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "merge",
        help="merge point clouds into one (formats, scales, offsets, CRS and extra bytes reconciled)",
        description="Merge several point clouds into one file; LAS/LAZ streamed.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="+", metavar="FILE", help="input point clouds, folders of tiles or quoted patterns")
    p.add_argument("output", help="the merged point cloud (format from the extension)")
    add_columns(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..merge import merge_files
    from ._tiles import inputs_of

    paths: list[str] = []
    for item in args.inputs:
        got = inputs_of(item)
        paths += got if isinstance(got, list) else [got]
    summary = merge_files(paths, args.output, columns=columns_of(args), progress=False if args.quiet else None)
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    las = s.get("las")
    fmt = ""
    if las:
        exact = all(las["coordinates_exact"].values())
        fmt = (f" (LAS {las['version']} point format {las['point_format']}, scale "
               f"{', '.join(f'{v:g}' for v in las['scales'])}, {las['crs'] or 'no CRS'}; coordinates "
               f"{'exact' if exact else 'within half the scale'})")
    print(f"{s['points']:,} points of {len(s['inputs'])} files -> {s['output']}{fmt}, {s['mode']}", file=sys.stderr)
