"""The chunking options every per-point command shares, and the switch to a chunked run."""
from __future__ import annotations

import sys
from pathlib import Path

TILE_HELP = """chunks (docs/scaling.md): INPUT may also be a folder of LAS/LAZ tiles or a
quoted pattern ("tiles/*.laz"); OUTPUT a .las/.laz file, or a folder that gets
one file per input tile, in the input's order.  Large inputs run in chunks
with a buffer on Dask; where the algorithm is local every point's result
equals the in-memory run's (docs/scaling.md says which and by how much).
--chunk-size and --buffer are metres, converted for inputs in feet."""


def add_tile_options(p) -> None:
    """``--chunk-size``, ``--buffer``, ``--workers``, ``--scheduler``, ``--resume``, ``--work-dir``."""
    g = p.add_argument_group("chunks (inputs larger than memory; docs/scaling.md)")
    g.add_argument("--chunk-size", type=float, default=None, metavar="SIZE",
                   help="side of the square chunks, m; 0 = all in memory "
                        "(default: in memory when the input fits, else chosen from its density and the free memory)")
    g.add_argument("--buffer", type=float, default=None, metavar="SIZE",
                   help="how far around each chunk points are read, m (default: what the "
                        "command's neighbourhoods reach)")
    g.add_argument("--workers", type=int, default=None, metavar="N", help="parallel chunks (default: one per core)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the chunks on this dask.distributed scheduler, e.g. tcp://10.0.0.5:8786 "
                        "(the workers must reach INPUT and OUTPUT under the same paths)")
    g.add_argument("--resume", action="store_true", help="continue a killed chunked run: finished chunks are kept")
    g.add_argument("--work-dir", default=None, metavar="DIR",
                   help="folder of the run's pieces, parts and manifest (default: OUTPUT.lidarfx-work)")


def inputs_of(text: str) -> list[str] | str:
    """A file or folder as given; a pattern with * ? [ expanded (sorted), or a one-line error
    (:func:`lidarfx.tiles.catalog.inputs_of`)."""
    from ..tiles.catalog import inputs_of as expand

    return expand(text)


def wants_tiles(args, command: str, by_size: bool = True) -> bool:
    """A chunked run: asked for by an option, or the input is several files, or a folder, or
    (``by_size``: when the command's options run in chunks as given) it holds more points than
    one chunk may (:func:`lidarfx.tiles.plan.chunk_points_budget`).  For a chunked run the
    output is checked here, before any work: an existing output file, or a non-empty output
    folder, needs ``--force`` (``--resume`` too: resuming is not replacing a finished output)."""
    tiled = _wants_tiles(args, command, by_size)
    if tiled:
        from .._atomic import check_new_file, check_new_folder

        out = Path(args.output)
        if out.suffix.lower() in (".las", ".laz"):
            check_new_file(out)
        else:
            check_new_folder(out)
    return tiled


def _wants_tiles(args, command: str, by_size: bool) -> bool:
    from ..errors import LidarfxError

    if args.chunk_size == 0:
        if args.resume or args.scheduler:
            raise LidarfxError("--chunk-size 0 runs in memory; --resume and --scheduler need chunks")
        return False
    if args.chunk_size is not None or args.scheduler or args.resume or args.buffer is not None \
            or args.workers is not None:
        return True
    src = inputs_of(args.input)
    if isinstance(src, list) or Path(src).is_dir():
        return True
    if Path(args.output).suffix.lower() not in (".las", ".laz") and not Path(args.output).suffix:
        return True  # an output folder: one file per input tile
    if not by_size or Path(src).suffix.lower() not in (".las", ".laz") or not Path(src).is_file():
        return False  # a missing input is the in-memory run's error
    from ..tiles import open_catalog
    from ..tiles.plan import chunk_points_budget, default_workers

    return open_catalog(src).points > chunk_points_budget(default_workers())


def run_tiles(args, command: str, options: dict) -> int:
    """Run ``command`` in chunks and print its summary (``--json``: on stdout)."""
    from .. import _json
    from ..errors import LidarfxError
    from ..tiles import run_tiled

    if getattr(args, "report", None):
        raise LidarfxError("--report is written by runs in memory; a chunked run writes no report "
                           "(make one of an output file with lidarfx report, or use --chunk-size 0)")
    progress = False if args.quiet else None
    res = run_tiled(inputs_of(args.input), args.output, command, options, chunk_size=args.chunk_size,
                    buffer=args.buffer, workers=args.workers, scheduler=args.scheduler, resume=args.resume,
                    work_dir=args.work_dir, progress=progress)
    summary = {"input": args.input, "output": args.output, "command": command, **res.as_dict()}
    if getattr(args, "json", False):
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        sec = res.seconds
        print(f"{res.points:,} points in {res.chunks} chunks of {res.chunk_size:g} m (buffer {res.buffer:g} m, "
              f"{res.workers} workers{', ' + str(res.resumed) + ' resumed' if res.resumed else ''}) -> "
              f"{', '.join(res.outputs[:3])}{' ...' if len(res.outputs) > 3 else ''} "
              f"(split {sec['split']:.1f} s, chunks {sec['chunks']:.1f} s, merge {sec['merge']:.1f} s)",
              file=sys.stderr)
    return 0
