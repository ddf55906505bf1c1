#!/usr/bin/env python
"""Speed of the z-buffered splat renderer (``lidarfx.render.splat``) on synthetic terrain.

Run by hand (not collected by pytest)::

    python benchmarks/bench_render.py                       # 1 M and 5 M points to 1600 x 1200
    python benchmarks/bench_render.py --points 1000000 20000000 --repeat 3 --json bench.json

For every size N it builds N points of a deterministic synthetic ALS-like terrain (uniform
x, y over a square of √(N / 20) m: 20 points/m²; z = smooth hills + 5 cm noise; 10 % of the
points are "vegetation" 2–15 m above the ground; UTM-sized coordinates) with per-point RGB
(uint16) and times, best of ``--repeat`` after an untimed warm-up (numba compiles or loads its
kernels there):

* ``render_points`` — frame, automatic point size, the splat kernel, eye-dome lighting and the
  composition of the RGB image (colours given), at ``--size``;
* ``render_picture`` — the whole PNG of ``lidarfx render --by z``: colour map over the 2–98 %
  range, render, key, scale bar, north arrow, atomic PNG write.

It prints seconds and points per second of both, and the disc radius the renderer chose.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if importlib.util.find_spec("lidarfx") is None:  # run from a checkout without an install: use ./src
    sys.path.insert(0, str(HERE.parent / "src"))


def scene(n: int, seed: int = 0):
    """N points of a synthetic terrain with vegetation, and uint16 RGB."""
    import numpy as np

    rng = np.random.default_rng(seed)
    side = (n / 20.0) ** 0.5
    xy = rng.uniform(0.0, side, (n, 2))
    z = 4.0 * np.sin(xy[:, 0] / 23.0) + 3.0 * np.cos(xy[:, 1] / 17.0) + rng.normal(0.0, 0.05, n)
    veg = rng.random(n) < 0.1
    z[veg] += rng.uniform(2.0, 15.0, int(veg.sum()))
    xyz = np.column_stack([xy, z]) + [500_000.0, 5_000_000.0, 100.0]
    rgb = rng.integers(0, 65536, (n, 3)).astype(np.uint16)
    return xyz, rgb


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--points", type=int, nargs="+", default=[1_000_000, 5_000_000], help="cloud sizes (default 1 M 5 M)")
    p.add_argument("--size", default="1600x1200", help="picture size WxH (default %(default)s)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs; the best counts (default %(default)s)")
    p.add_argument("--json", default=None, help="also write the numbers to this JSON file")
    args = p.parse_args(argv)

    import numpy as np

    import lidarfx
    from lidarfx.render.splat import parse_size, render_picture, render_points

    size = parse_size(args.size)
    xyz, rgb = scene(20_000)  # warm-up: compile or load the kernels
    render_points(xyz, rgb, size=size)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.png"
        render_picture(lidarfx.PointCloud(xyz), out, by="z", size=size)
        rows = []
        for n in args.points:
            xyz, rgb = scene(n)
            cloud = lidarfx.PointCloud(xyz)
            img = render_points(xyz, rgb, size=size)
            t_points = best_of(lambda xyz=xyz, rgb=rgb: render_points(xyz, rgb, size=size), args.repeat)
            t_picture = best_of(lambda cloud=cloud: render_picture(cloud, out, by="z", size=size), args.repeat)
            row = {"points": n, "size": list(size), "point_size_px": round(img.point_size, 3),
                   "covered": round(img.covered, 3), "render_points_s": round(t_points, 3),
                   "render_points_per_s": round(n / t_points), "render_picture_s": round(t_picture, 3),
                   "render_picture_per_s": round(n / t_picture)}
            rows.append(row)
            print(f"{n:>11,} points -> {size[0]}x{size[1]}: render_points {t_points:6.3f} s "
                  f"({n / t_points / 1e6:5.2f} M points/s), render_picture (PNG, --by z) {t_picture:6.3f} s "
                  f"({n / t_picture / 1e6:5.2f} M points/s); discs of {img.point_size:.2f} px, "
                  f"{img.covered:.0%} covered", flush=True)
    if args.json:
        import platform

        info = {"date": time.strftime("%Y-%m-%d"), "cpus": os.cpu_count(), "python": platform.python_version(),
                "numpy": np.__version__, "lidarfx": lidarfx.__version__, "repeat": args.repeat, "rows": rows}
        Path(args.json).write_text(json.dumps(info, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
