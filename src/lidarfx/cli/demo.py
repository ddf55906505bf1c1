"""``lidarfx demo``: the main job on the bundled sample, outputs in one folder."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from .. import _json

EPILOG = """example:
  lidarfx demo                 # writes ./lidarfx-demo/
  lidarfx demo --out /tmp/fx   # another folder

The bundled sample is the synthetic TLS house facade of lidarfx.synth (seed 1:
ground, wall, roof, window, vegetation, clutter, noise with ground truth).  The
demo computes multi-scale eigen, plane, density and height features, writes the
cloud as LAZ with the features as extra-bytes dimensions, a JSON summary, a
per-class table and a picture.
"""

SHOWN = ("planarity", "linearity", "verticality", "sphericity", "echo_ratio", "z_range")


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job on the bundled sample",
        description="Compute features on the bundled facade sample and write LAZ, JSON and PNG outputs.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="lidarfx-demo", help="output folder (created; default ./lidarfx-demo)")
    p.add_argument("--seed", type=int, default=1, help="seed of the sample scene")
    p.set_defaults(func=run)


def run(args) -> int:
    from rich.console import Console

    from .. import synth
    from ..errors import LidarfxError

    console = Console(stderr=True)
    out = Path(args.out)
    t0 = time.perf_counter()
    scene = synth.facade(seed=args.seed)  # checks the seed before the folder is made
    created = next((p for p in reversed([out, *out.parents]) if not p.exists()), None)  # topmost new folder
    try:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise LidarfxError(f"cannot create output folder {out}: {exc.strerror}") from None
        _run(console, out, scene, t0)
    except BaseException:
        if created is not None:  # no folder left behind by a failed run
            import shutil

            shutil.rmtree(created, ignore_errors=True)
        raise
    return 0


def _run(console, out: Path, scene, t0: float) -> None:
    import numpy as np
    from rich.table import Table

    from .. import io
    from ..features import compute_features
    from ..render import feature_views

    io.write(scene, out / "facade.laz")
    radii = [0.1, 0.3, 0.5]
    console.print(f"[bold]lidarfx demo[/]: {len(scene):,} points, features at radii {radii} m")
    t1 = time.perf_counter()
    feats = compute_features(scene, ["eigen", "plane", "density", "height"], radii=radii, progress=False)
    t2 = time.perf_counter()
    io.write(feats, out / "facade_features.laz")
    t3 = time.perf_counter()

    classes = scene.meta.get("truth", {}).get("classes", {})
    code_name = {int(v): k for k, v in classes.items()}
    cls = np.asarray(scene["classification"])
    table = Table(title="mean feature per class (r = 0.50 m)")
    table.add_column("class")
    table.add_column("points", justify="right")
    for name in SHOWN:
        table.add_column(name, justify="right")
    per_class = {}
    for code in np.unique(cls):
        sel = cls == code
        label = code_name.get(int(code), str(int(code)))
        means = {n: float(np.nanmean(feats[f"{n}_r0.50"][sel])) for n in SHOWN}
        per_class[label] = {"code": int(code), "points": int(sel.sum()), **{k: round(v, 4) for k, v in means.items()}}
        table.add_row(label, f"{int(sel.sum()):,}", *[f"{means[n]:.3f}" for n in SHOWN])
    console.print(table)

    pic = feature_views(
        feats,
        ["classification", "planarity_r0.50", "verticality_r0.50", "linearity_r0.10"],
        out / "facade_features.png",
        view="front",
        labels={"classification": code_name},
        title="lidarfx demo: synthetic facade, classes and features (front view)",
    )
    summary = {
        "points": len(feats),
        "radii": radii,
        "features": feats.meta["features"],
        "seconds": {"features": round(t2 - t1, 3), "total": round(time.perf_counter() - t0, 3)},
        "per_class_r0.50": per_class,
        "outputs": {
            "scene": str(out / "facade.laz"),
            "features": str(out / "facade_features.laz"),
            "picture": str(pic),
        },
    }
    with open(out / "summary.json", "w") as fh:
        _json.dump(summary, fh, indent=2)
    console.print(
        f"features {t2 - t1:.2f} s, write {t3 - t2:.2f} s -> {out}/ "
        "(facade.laz, facade_features.laz, facade_features.png, summary.json)"
    )
