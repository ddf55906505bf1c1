"""``lidarfx select IN OUT --where EXPR``: keep the points where an expression holds."""
from __future__ import annotations

import argparse
import sys
import time

from .. import _json
from ._args import add_columns, read_input

EPILOG = """examples:
  lidarfx select seg.laz planes.laz --where "segment_id >= 0 and segment_size > 50 and planarity > 0.5"
  lidarfx select in.laz ground.laz --where "classification in [2, 9]"
  lidarfx select in.laz rest.laz --where "classification in [2, 9]" --invert
  lidarfx select feat.laz steep.laz --where "slope > 60 and not (z - 100 < 2.5)"
  lidarfx select feat.laz sc.laz --where "planarity_r0.50 > 0.7 or `my attr` % 2 == 1"

grammar: comparisons < <= > >= == != (chains like 0 < x < 5), and / or / not,
parentheses, + - * / % ** on attributes and numbers, "in [..]" / "not in [..]".
Names: the file's attributes plus x, y, z.  Comparisons with NaN are False.
No function calls, attribute access, indexing or strings: the expression is
parsed by lidarfx's own parser, never evaluated as Python.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "select",
        help="keep the points where an attribute expression holds",
        description="Select points by criteria: a safe expression over attributes.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="output point cloud with the selected points")
    p.add_argument("-w", "--where", required=True, metavar="EXPR", help='condition, e.g. "segment_id >= 0 and planarity > 0.5"')
    p.add_argument("--invert", action="store_true", help="keep the points where EXPR does NOT hold")
    add_columns(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io
    from ..select import evaluate, parse

    expr = parse(args.where)  # syntax errors before reading a large file
    t0 = time.perf_counter()
    cloud, progress = read_input(args)
    t1 = time.perf_counter()
    mask = evaluate(cloud, expr)
    if args.invert:
        mask = ~mask
    out = cloud.subset(mask)
    io.write(out, args.output, progress=progress)
    t2 = time.perf_counter()
    kept, total = int(mask.sum()), len(cloud)
    summary = {
        "input": str(args.input),
        "output": str(args.output),
        "where": args.where,
        "invert": bool(args.invert),
        "kept": kept,
        "total": total,
        "share": round(kept / total, 6) if total else 0.0,
        "seconds": {"read": round(t1 - t0, 3), "select_write": round(t2 - t1, 3)},
    }
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        share = f" ({100 * kept / total:.1f} %)" if total else ""
        print(f"kept {kept:,} of {total:,} points{share} -> {args.output}", file=sys.stderr)
        if kept == 0:
            print("warning: no point matched; the output is empty", file=sys.stderr)
    return 0
