"""What ``crop``, ``filter`` and ``reproject`` share: the chunk options (``crop`` has its own
``--buffer``, the area's), the switch to a chunked run and its summary."""
from __future__ import annotations

import argparse
import sys


def add_chunk_options(p, *, with_buffer: bool = True) -> None:
    """The chunk options of :func:`lidarfx.cli._tiles.add_tile_options`; without ``--buffer`` for a
    command whose chunks need none and whose ``--buffer`` means something else (crop)."""
    from ._tiles import add_tile_options

    if with_buffer:
        add_tile_options(p)
        return
    g = p.add_argument_group("chunks (inputs larger than memory; docs/scaling.md)")
    g.add_argument("--chunk-size", type=float, default=None, metavar="SIZE",
                   help="side of the square chunks, m; 0 = all in memory "
                        "(default: in memory when the input fits, else chosen from its density and the free memory)")
    g.add_argument("--workers", type=int, default=None, metavar="N", help="parallel chunks (default: one per core)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the chunks on this dask.distributed scheduler, e.g. tcp://10.0.0.5:8786")
    g.add_argument("--resume", action="store_true", help="continue a killed chunked run: finished chunks are kept")
    g.add_argument("--work-dir", default=None, metavar="DIR",
                   help="folder of the run's pieces, parts and manifest (default: OUTPUT.lidarfx-work)")


def tile_args(args, with_buffer: bool = True):
    """``args`` as :mod:`lidarfx.cli._tiles` reads them (``buffer`` = the chunk buffer)."""
    if with_buffer:
        return args
    return argparse.Namespace(**{**vars(args), "buffer": None})


def chunked(args, command: str, with_buffer: bool = True) -> bool:
    """Whether the run goes in chunks (:func:`lidarfx.cli._tiles.wants_tiles`; the output is
    checked there for a chunked run)."""
    from ._tiles import wants_tiles

    return wants_tiles(tile_args(args, with_buffer), command)


def run_chunked(args, command: str, options: dict, *, allow_empty: bool = True, empty_message: str = "",
                with_buffer: bool = True, extra: dict | None = None) -> dict:
    """Run ``command`` in chunks (:func:`lidarfx.tiles.proc_ops.run_ops`) and return its summary."""
    from ..tiles.proc_ops import run_ops
    from ._tiles import inputs_of

    a = tile_args(args, with_buffer)
    summary = run_ops(inputs_of(a.input), a.output, command, options, allow_empty=allow_empty,
                      empty_message=empty_message, chunk_size=a.chunk_size, buffer=a.buffer, workers=a.workers,
                      scheduler=a.scheduler, resume=a.resume, work_dir=a.work_dir,
                      progress=False if args.quiet else None)
    summary.update(extra or {})
    return summary


def print_chunked(s: dict, what: str) -> None:
    """One line on stderr for a chunked run."""
    sec = s.get("seconds", {})
    outs = s.get("outputs", [])
    print(f"{what}: {s['kept']:,} of {s['points']:,} points in {s['chunks']} chunks of {s['chunk_size']:g} m "
          f"({s['workers']} workers) -> {', '.join(outs[:3])}{' ...' if len(outs) > 3 else ''} "
          f"(split {sec.get('split', 0):.1f} s, chunks {sec.get('chunks', 0):.1f} s, merge {sec.get('merge', 0):.1f} s)",
          file=sys.stderr)
