#!/usr/bin/env python
"""Structure classes and edge lines: speed against the feature engine, and the edge run on a real city block.

Run by hand (not collected by pytest)::

    python benchmarks/bench_structures.py                    # 1 M points, best of 3 (~2 min on 2 cores)
    python benchmarks/bench_structures.py --points 200000 --repeat 1
    python benchmarks/bench_structures.py --json bench.json

What it measures (targets of the structure / edge-line issue):

1. ``lidarfx eigenclass IN OUT -r 0.5`` against ``lidarfx features IN OUT -r 0.5
   --features eigen`` on the same 1 M-point LAS file (the synthetic terrain of
   ``bench_features.py``), both as whole CLI processes, best of ``--repeat``, in
   the same run; and the same pair in-process (``classify_structures`` against
   ``compute_features(cloud, "eigen")``).  Target: eigenclass ≤ 1.5 × features.
2. ``lidarfx edges TO_core_last_zoom.laz lines.geojson`` as a whole process
   (213 k points of downtown Toronto), best of ``--repeat``.  Target: ≤ 20 s on
   2 cores.  Also prints the share of the Toronto City Hall outline
   (``TO_city_hall.shp``, plan) within 0.5 m and 1 m of a found line.

One untimed warm-up run of each command loads (or compiles) the numba kernels.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REAL = HERE.parent.parent / "shared" / "data" / "real"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--points", type=int, default=1_000_000, help="points of the synthetic terrain (default 1 M)")
    p.add_argument("--radius", type=float, default=0.5, help="radius of both commands (default 0.5 m)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per measurement; the best counts (default 3)")
    p.add_argument("--threads", type=int, default=None, help="numba threads (default: all cores)")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    return p.parse_args(argv)


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def run(cmd: list[str]) -> None:
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"command failed ({r.returncode}): {' '.join(cmd)}\n{r.stderr}")


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.threads:
        for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = str(args.threads)
    sys.path.insert(0, str(HERE))
    from bench_features import ensure_lidarfx_importable, make_terrain, write_las

    ensure_lidarfx_importable()
    import numba

    import lidarfx

    res: dict = {"points": args.points, "radius": args.radius, "repeat": args.repeat,
                 "threads": numba.get_num_threads(), "lidarfx": lidarfx.__version__,
                 "date": time.strftime("%Y-%m-%d")}
    print(f"lidarfx {lidarfx.__version__}, numba threads {res['threads']}, {args.points:,} points, r = {args.radius}")
    py = [sys.executable, "-m", "lidarfx"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        las = work / "terrain.las"
        write_las(make_terrain(args.points, 42)[0], las)
        r = str(args.radius)
        feat = py + ["features", str(las), str(work / "f.laz"), "-r", r, "--features", "eigen", "-q"]
        eig = py + ["eigenclass", str(las), str(work / "e.laz"), "-r", r, "-q"]
        run(feat)
        run(eig)  # warm-up (numba cache)
        res["cli_features_eigen_s"] = best_of(lambda: run(feat), args.repeat)
        res["cli_eigenclass_s"] = best_of(lambda: run(eig), args.repeat)
        print(f"CLI  features --features eigen : {res['cli_features_eigen_s']:.2f} s")
        print(f"CLI  eigenclass                : {res['cli_eigenclass_s']:.2f} s")
        cloud = lidarfx.read(las)
        lidarfx.compute_features(cloud, "eigen", radius=args.radius)
        lidarfx.classify_structures(cloud, args.radius)
        res["api_features_eigen_s"] = best_of(lambda: lidarfx.compute_features(cloud, "eigen", radius=args.radius),
                                              args.repeat)
        res["api_eigenclass_s"] = best_of(lambda: lidarfx.classify_structures(cloud, args.radius), args.repeat)
        print(f"API  compute_features(eigen)   : {res['api_features_eigen_s']:.2f} s")
        print(f"API  classify_structures       : {res['api_eigenclass_s']:.2f} s")

        to = REAL / "TO_core_last_zoom.laz"
        if to.exists():
            edges = py + ["edges", str(to), str(work / "to.geojson"), "-q"]
            run(edges)
            res["cli_edges_toronto_s"] = best_of(lambda: run(edges), args.repeat)
            print(f"CLI  edges TO_core_last_zoom   : {res['cli_edges_toronto_s']:.2f} s")
            shp = REAL / "TO_city_hall.shp"
            try:
                import numpy as np
                import shapefile
                from shapely.geometry import LineString, MultiLineString

                from lidarfx.vector import read_geojson

                lines, _ = read_geojson(work / "to.geojson")
                outline = LineString(np.array(shapefile.Reader(str(shp)).shapes()[0].points))
                found = MultiLineString([LineString(p.ring[:, :2]) for p in lines])
                d = np.array([found.distance(outline.interpolate(s)) for s in np.arange(0.0, outline.length, 0.25)])
                res["toronto_outline_within_0_5m"] = float((d <= 0.5).mean())
                res["toronto_outline_within_1m"] = float((d <= 1.0).mean())
                print(f"City Hall outline within 0.5 m: {100 * res['toronto_outline_within_0_5m']:.1f} %, "
                      f"within 1 m: {100 * res['toronto_outline_within_1m']:.1f} % ({outline.length:.0f} m)")
            except (ImportError, OSError) as exc:
                print(f"outline figures skipped: {exc}")
        else:
            print(f"edges on Toronto skipped: {to} not found")

    ratio_cli = res["cli_eigenclass_s"] / res["cli_features_eigen_s"]
    ratio_api = res["api_eigenclass_s"] / res["api_features_eigen_s"]
    res["ratio_cli"], res["ratio_api"] = ratio_cli, ratio_api
    print()
    print(f"eigenclass / features eigen (CLI): {ratio_cli:.2f}  target <= 1.5  {'PASS' if ratio_cli <= 1.5 else 'FAIL'}")
    print(f"eigenclass / features eigen (API): {ratio_api:.2f}")
    if "cli_edges_toronto_s" in res:
        t = res["cli_edges_toronto_s"]
        print(f"edges on TO_core_last_zoom.laz:   {t:.1f} s  target <= 20 s  {'PASS' if t <= 20 else 'FAIL'}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
