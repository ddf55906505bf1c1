"""``lidarfx thin IN OUT --cell 0.05``: block (voxel) thinning, one point per occupied cell, streamed."""
from __future__ import annotations

import argparse

from ._args import add_columns, columns_of, emit_summary

EPILOG = """examples:
  lidarfx thin tower.laz tower_5cm.laz --cell 0.05              # the point nearest each cell centre
  lidarfx thin tower.laz tower_5cm.laz --cell 0.05 --keep first
  lidarfx thin scan.laz ground_10cm.laz --cell 0.1 --keep lowest
  lidarfx thin scan.laz sample.laz --cell 0.2 --keep random --seed 7
  lidarfx thin scan.xyz thin.ply --cell 0.05 --columns x,y,z,intensity --json

cells: the cubes [i c, (i+1) c) x [j c, (j+1) c) x [k c, (k+1) c) of edge c
anchored at (0, 0, 0): the same grid for every file, so tiles thinned one by one
fit together (in a file in feet: a cell of --cell metres in feet, from 0 ft).
Exactly one point is kept per occupied cell:
  centre   nearest the cell centre (default)
  first    first in file order
  lowest   smallest z;  highest: largest z
  random   a random point (--seed; the same whatever the chunking)
Ties go to the point first in file order; kept points stay in file order.
LAS/LAZ input is read in chunks keeping only the winner of each cell and its
record; the kept records are written bit for bit (point format, attributes,
extra bytes, scales, offsets, CRS and VLRs unchanged), so memory grows with
the number of occupied cells (24 bytes + the record each; beyond 512 MiB of
records a second pass reads them again), not with the input.  Other formats
are read in memory.  docs/tower.md#block-thinning.
"""


def register(sub) -> None:
    from ..thin import KEEP

    p = sub.add_parser(
        "thin",
        help="block (voxel) thinning: one point per occupied cubic cell, streamed for LAS/LAZ",
        description="Keep exactly one point per occupied cubic cell of edge --cell (block / voxel thinning). "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz streamed; .ply/.xyz/.txt/.csv/.npz in memory)")
    p.add_argument("output", help="output point cloud (format from the extension)")
    p.add_argument("--cell", type=float, required=True, help="cell edge, m")
    p.add_argument("--keep", default="centre", choices=KEEP, help="which point of a cell is kept (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="--keep random: the seed (default %(default)s)")
    add_columns(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..thin import thin_file

    summary = thin_file(args.input, args.output, cell=args.cell, keep=args.keep, seed=args.seed,
                        columns=columns_of(args), progress=False if args.quiet else None)
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console

    console = Console(stderr=True)
    share = f" ({100 * s['share_kept']:.2f} %)" if s["share_kept"] is not None else ""
    console.print(f"[bold]{s['kept']:,}[/] of {s['points']:,} points kept{share}, one per occupied "
                  f"{s['cell']:g} m cell ({s['keep']}) -> {s['output']}")
    sec = s["seconds"]
    console.print(f"{s['mode']}: cells {sec['cells']:.2f} s, write {sec['write']:.2f} s")
