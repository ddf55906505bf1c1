"""``lidarfx synth``: write a synthetic scene with ground truth."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .. import _json
from ..errors import LidarfxError
from ._args import numbers

EPILOG = """examples:
  lidarfx synth --list                                   # the available scenes
  lidarfx synth facade facade.laz --seed 1               # + facade.laz.truth.json
  lidarfx synth edge edge.npz --radius 0.5 --angle 120 --sampling grid
  lidarfx synth plane plane.laz --rotation random --noise 0.01 --origin 500000,5200000,300
  lidarfx synth powerline corridor.laz -p n_spans=4 -p "catenary_a=[900, 1200]"

The truth (exact parameters, class codes, catenaries, joint sets, breaklines ...)
is written as JSON beside the output: OUT + ".truth.json".  Truth coordinates
are local; add truth["origin"] for world coordinates.
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "synth",
        help="generate a synthetic scene with ground truth",
        description="Generate a deterministic synthetic point cloud with ground-truth attributes "
        "and write its truth as JSON beside it.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("kind", nargs="?", help="scene name (see --list)")
    p.add_argument("out", nargs="?", help="output file (.laz .las .ply .xyz .npz ...)")
    p.add_argument("--list", action="store_true", help="list the scene names and exit")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--density", type=float, help="main density knob (per m² / m / m³, see docs)")
    p.add_argument("--noise", type=float, help="Gaussian noise sigma in metres")
    p.add_argument("--sampling", choices=("random", "grid"), help="structures/terrain: random or grid")
    p.add_argument("--radius", type=float, help="structures: neighbourhood radius R (m)")
    p.add_argument("--angle", type=float, help="edge: dihedral angle (degrees)")
    p.add_argument("--rotation", help="structures: 'random' or 9 comma-separated matrix entries")
    p.add_argument("--origin", help="shift X,Y,Z added to all coordinates (e.g. UTM-sized)")
    p.add_argument(
        "-p", "--param", action="append", default=[], metavar="KEY=VALUE",
        help="any other generator parameter; VALUE is parsed as JSON when possible (repeatable)",
    )
    p.set_defaults(func=run)


def _numbers(text: str, n: int, what: str) -> list[float]:
    try:
        return numbers(text, n, what)
    except ValueError as exc:
        raise LidarfxError(str(exc)) from None


def _params(args: argparse.Namespace) -> dict[str, Any]:
    params: dict[str, Any] = {"seed": args.seed}
    for name in ("density", "noise", "sampling", "radius", "angle"):
        value = getattr(args, name)
        if value is not None:
            params[name] = value
    if args.rotation is not None:
        params["rotation"] = "random" if args.rotation == "random" else _numbers(args.rotation, 9, "--rotation")
    if args.origin is not None:
        params["origin"] = _numbers(args.origin, 3, "--origin")
    for item in args.param:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise LidarfxError(f"--param expects KEY=VALUE, got {item!r}")
        try:
            value = json.loads(raw)
        except (ValueError, RecursionError):  # not JSON (also an integer of over 4300 digits): the text itself
            value = raw
        params[key.strip()] = value
    return params


def run(args: argparse.Namespace) -> int:
    from .. import synth
    from ..io import write

    if args.list:
        width = max(map(len, synth.GENERATORS))
        for name, func in synth.GENERATORS.items():
            first = (func.__doc__ or "").strip().splitlines()[0] if func.__doc__ else ""
            print(f"{name:<{width}}  {first}")
        return 0
    if not args.kind:
        raise LidarfxError("give a scene name and an output file (or --list)")
    if args.kind not in synth.GENERATORS:
        raise LidarfxError(f"unknown synthetic scene {args.kind!r}; known: {', '.join(synth.GENERATORS)}")
    if not args.out:
        raise LidarfxError("missing output file")
    from .._atomic import atomic_path, check_output_folder
    from ..io import check_output_path

    out = Path(args.out)
    truth_path = Path(str(out) + ".truth.json")
    check_output_path(out)  # both outputs before the scene is generated
    check_output_folder(truth_path)
    cloud = synth.generate(args.kind, **_params(args))
    write(cloud, out)

    with atomic_path(truth_path, suffix=".json") as tmp:
        tmp.write_text(_json.dumps(cloud.meta["truth"], indent=1) + "\n", encoding="utf-8")
    print(f"{args.kind}: {len(cloud):,} points -> {out} (truth: {truth_path})")
    return 0
