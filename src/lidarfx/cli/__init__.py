"""The ``lidarfx`` command line.  Thin: every command calls the Python API.

Each sub-command lives in its own module exposing ``register(subparsers)``; the
module list below is the only place that knows them all.
"""
from __future__ import annotations

import argparse
import importlib
import shlex
import sys
import warnings

from ..errors import EXIT_FAILURE, EXIT_USAGE, LidarfxError, LidarfxWarning, environment_failure

COMMAND_MODULES = ["info", "convert", "features", "synth", "demo", "segment", "select", "ground", "surface", "classify",
                   "eigenclass", "edges", "powerlines", "discontinuities", "colour", "breaklines", "thin", "section", "parts",
                   "members", "render", "report", "run", "crop", "merge", "filter", "reproject"]

EPILOG = """examples:
  lidarfx demo                                   # the main job on synthetic scenes -> lidarfx-demo/index.html
  lidarfx info scan.laz --json                   # points, bounds, classes, CRS
  lidarfx features in.laz out.laz -r 0.5 --features eigen,plane,density
  lidarfx synth facade facade.laz --seed 1       # generate a scene with ground truth
  lidarfx eigenclass roofs.laz struct.laz -r 1.5 # plane / border / edge / corner / line / volume
  lidarfx edges roofs.laz lines.geojson --dxf lines.dxf --csv
  lidarfx powerlines corridor.laz out/ --load-case temp=80   # wires, catenaries, sag, clearances
  lidarfx discontinuities face.laz out/ --scanner 5,-25,1.5  # joint sets, stereonet, spacing, overhangs
  lidarfx breaklines als.laz lines.geojson --dxf lines.dxf   # dike crests and toes, ditch edges (3-D)
  lidarfx colour face.laz rgb.laz --picture face.png        # RGB: aspect hue, slope saturation, shading
  lidarfx thin tower.laz tower_5cm.laz --cell 0.05          # one point per 5 cm cell, streamed
  lidarfx section tower.laz cut.laz --from -4,0 --to 4,0 --width 0.2 --image cut.png --by z
  lidarfx parts tower.laz out/                              # bolts, insulators, corona rings of a lattice tower
  lidarfx members tower.laz members.geojson --dxf members.dxf   # tower members as 3-D lines
  lidarfx render scan.laz scan.png --by class --view top      # a picture: z-buffered splats, eye-dome lighting
  lidarfx report scan.laz report/ -r 0.5                    # an HTML page with a 3-D viewer of the cloud
  lidarfx edges roofs.laz lines.geojson --report report/    # any analysis command: its run as an HTML page

units: lengths are metres; files in feet are converted (radii, distances, cells, widths, chunk
sizes, buffers); positions such as --scanner or --from are the file's coordinates.
"""


class _Parser(argparse.ArgumentParser):
    """argparse with our one-line error and exit code 2 (no usage block: the error names the
    ``--help`` to read)."""

    def error(self, message: str) -> None:  # pragma: no cover - exercised via CLI tests
        print(f"{self.prog}: error: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(
        prog="lidarfx",
        description="Per-point 3D features, segments, classes and vector products from LiDAR point clouds.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"lidarfx {__version__}")
    parser.add_argument("--force", action="store_true", default=argparse.SUPPRESS, help=FORCE_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    _add_force(sub)
    return parser


FORCE_HELP = "replace existing output files (without it an existing output is an error, before any work)"
NO_OUTPUT = {"lidarfx info", "lidarfx ground-eval", "lidarfx classify info", "lidarfx demo"}
"""Commands without --force: they write nothing, or (demo) always replace their own folder."""


def _add_force(sub) -> None:
    """``--force`` on every command that writes files (also accepted before the command)."""
    for p in dict.fromkeys(sub.choices.values()):
        nested = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        if nested:
            for a in nested:
                _add_force(a)
        elif p.prog not in NO_OUTPUT:
            p.add_argument("--force", action="store_true", default=argparse.SUPPRESS, help=FORCE_HELP)


class Terminated(KeyboardInterrupt):
    """SIGTERM during a run: raised where Python code runs next, so that temporary outputs are
    removed as after Ctrl-C (exit code 143)."""


def _catch_sigterm():
    """Turn SIGTERM into :class:`Terminated` for the run (main thread only); the previous handler,
    or None when it could not be set."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def _raise(signum, frame):
        raise Terminated()

    try:
        return signal.signal(signal.SIGTERM, _raise)
    except (ValueError, OSError):
        return None


def main(argv: list[str] | None = None) -> int:
    from ._args import join_number_lists

    parser = build_parser()
    given = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(join_number_lists(given))
    args.command_line = "lidarfx " + shlex.join(given)  # as typed, for the pages that record it
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    _default_show = warnings.showwarning

    def _show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, LidarfxWarning):  # one line, no source location
            print(f"lidarfx: warning: {message}", file=sys.stderr)
        else:
            _default_show(message, category, filename, lineno, file, line)

    warnings.showwarning = _show
    from .. import _numba_cache
    from .._atomic import OVERWRITE

    _numba_cache.announce_compiles()
    # the run replaces existing outputs only with --force (the Python API always does)
    token = OVERWRITE.set(bool(getattr(args, "force", False)))
    previous = _catch_sigterm()
    try:
        rc = args.func(args)
    except LidarfxError as exc:
        print(f"lidarfx: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE if environment_failure(exc) is not None else EXIT_USAGE
    except BrokenPipeError:  # e.g. `lidarfx info --json f.laz | head`: the reader left
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        where = f": {exc.filename}" if getattr(exc, "filename", None) else ""
        print(f"lidarfx: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return EXIT_USAGE
    except (OSError, MemoryError) as exc:  # the machine stopped the run: disk full, out of memory, ...
        print(f"lidarfx: error: {failure_line(exc)}", file=sys.stderr)
        return EXIT_FAILURE
    except Terminated:
        print("lidarfx: terminated", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print("lidarfx: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            import signal

            signal.signal(signal.SIGTERM, previous)
        OVERWRITE.reset(token)
        warnings.showwarning = _default_show
    return int(rc or 0)


def failure_line(exc: BaseException) -> str:
    """One line for an OSError or MemoryError that stopped a run, e.g. "no space left on device
    writing out.laz" (the file the error names)."""
    import errno

    if isinstance(exc, MemoryError):
        return "out of memory" + (f" ({exc})" if str(exc) else "")
    text = exc.strerror or " ".join(str(exc).split()) or type(exc).__name__
    text = text[:1].lower() + text[1:]
    name = getattr(exc, "filename", None)
    if not name:
        return text
    writing = exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS)
    return f"{text} writing {name}" if writing else f"{text}: {name}"


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
