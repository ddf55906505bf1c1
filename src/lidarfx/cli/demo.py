"""``lidarfx demo``: the main job on synthetic scenes with ground truth, one report linking them."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import emit_summary

EPILOG = """examples:
  lidarfx demo                               # writes ./lidarfx-demo/, open lidarfx-demo/index.html
  lidarfx demo --out /tmp/fx                 # another folder
  lidarfx demo --scenes powerline,dike       # some of the scenes
  lidarfx demo --seed 7 --json               # other random scenes; figures as JSON on stdout

scenes (lidarfx.synth, each with its ground truth):
  facade     features + a classifier trained on one facade scan, applied to another
  rockface   joint sets of a rock face (stereonet, Fisher statistics, spacing)
  powerline  wires, catenaries and pylons of a corridor
  house      3-D edge lines of a house (ridge, eaves)
  dike       breaklines of a dike and a ditch in ALS terrain
Each scene's folder holds the scene (LAZ), the products (LAZ, GeoJSON, DXF, CSV,
PNG) and an HTML report (3-D viewer with the products drawn in); index.html
links them with every figure against the scene's truth and its target.
The first run compiles the numba kernels; they are cached after that.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job on bundled synthetic scenes and write one HTML report",
        description="Run features, classification, joint sets, power lines, edges and breaklines on synthetic "
                    "scenes with ground truth; write the products and an HTML report linking them.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="lidarfx-demo", help="output folder (created; default ./lidarfx-demo)")
    p.add_argument("--scenes", default=None, metavar="A,B",
                   help="comma-separated scenes (default: all: facade,rockface,powerline,house,dike)")
    p.add_argument("--seed", type=int, default=None, help="seed of every scene (default: each scene's own)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress, no table")
    p.set_defaults(func=run)


def run(args) -> int:
    from .._atomic import overwriting

    with overwriting(True):  # the demo's folder is its own: a second run replaces it (no --force)
        return _run(args)


def _run(args) -> int:
    from rich.console import Console

    from ..demo import SCENES, run_demo
    from ..errors import LidarfxError
    from ..synth._common import make_rng

    console = Console(stderr=True)
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()] if args.scenes else list(SCENES)
    unknown = [s for s in scenes if s not in SCENES]
    if unknown or not scenes:
        raise LidarfxError(f"unknown demo scene {unknown[0] if unknown else args.scenes!r}; "
                           f"the scenes are {', '.join(SCENES)}")
    if args.seed is not None:
        make_rng(args.seed)  # a bad seed is refused before the folder is made
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise LidarfxError(f"{out} exists and is not a folder")
    created = next((p for p in reversed([out, *out.parents]) if not p.exists()), None)  # topmost new folder
    from rich.markup import escape

    # soft_wrap: rich neither wraps nor crops a line (a long path stays whole; the terminal folds it)
    say = (lambda m: None) if args.quiet or args.json else (lambda m: console.print(m, soft_wrap=True))
    say(f"[bold]lidarfx demo[/]: {len(scenes)} scenes -> {escape(str(out))}/")
    t0 = time.perf_counter()
    try:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise LidarfxError(f"cannot create output folder {out}: {exc.strerror}") from None
        res = run_demo(out, scenes, seed=args.seed, progress=lambda m: say(f"  {escape(m)}"))
        from .. import _json
        from .._atomic import atomic_path

        with atomic_path(out / "summary.json") as tmp:
            tmp.write_text(_json.dumps(res, indent=2) + "\n")
    except BaseException:
        if created is not None:  # no folder left behind by a failed run
            import shutil

            shutil.rmtree(created, ignore_errors=True)
        raise
    res["summary"] = str(out / "summary.json")
    res["seconds"] = round(time.perf_counter() - t0, 2)
    emit_summary(args, res, lambda s: _print_summary(console, s))
    return 0


def _print_summary(console, s: dict) -> None:
    """The figures as a plain table on ``console``: every column as wide as its longest value,
    lines never wrapped nor cropped by rich, so no scene, measure, target or path is cut."""
    from rich.markup import escape

    rows = []
    for sc in s["scenes"]:
        for f in sc["figures"]:
            v = f["value"]
            mark = "" if f["pass"] is None else ("[green]ok[/]" if f["pass"] else "[red]missed[/]")
            rows.append((str(sc["name"]), str(f["measure"]), "" if v is None else f"{v:g}", str(f["target"]), mark))
    head = ("scene", "measure", "value", "target")
    w = [max(len(r[i]) for r in [head, *rows]) for i in range(4)]

    def line(r) -> str:
        text = f"{r[0]:<{w[0]}}  {r[1]:<{w[1]}}  {r[2]:>{w[2]}}  {r[3]:<{w[3]}}"
        return escape(text) + (f"  {r[4]}" if len(r) > 4 and r[4] else "")

    console.print("[bold]figures against the scenes' truth[/]", soft_wrap=True)
    console.print(f"[bold]{line(head).rstrip()}[/]", soft_wrap=True, highlight=False)
    for r in rows:
        console.print(line(r).rstrip(), soft_wrap=True, highlight=False)
    console.print(f"{sum(sc['points'] for sc in s['scenes']):,} points in {len(s['scenes'])} scenes, "
                  f"{s['seconds']:.1f} s -> open {escape(str(s['index']))}", soft_wrap=True)
