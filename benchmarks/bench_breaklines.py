#!/usr/bin/env python
"""Structure lines: the whole ``lidarfx breaklines`` command on 1 M synthetic ground points.

Run by hand (not collected by pytest)::

    python benchmarks/bench_breaklines.py                  # 1 M ground points, best of 2 (~2 min on 2 cores)
    python benchmarks/bench_breaklines.py --points 250000 --repeat 1 --json bench.json

It generates ``lidarfx.synth.terrain`` (a dike and a ditch, 4 pts/m², 5 cm noise, 10 % of the
area under vegetation with 10 % of its points left in the ground class) with the tile size
chosen for about ``--points`` ground points, writes it as LAZ and, after an untimed warm-up run
on a small tile (numba cache), times ``python -m lidarfx breaklines IN lines.geojson -q`` as a
whole process, best of ``--repeat``.  Target: ≤ 60 s on 2 cores.  It also scores the lines
against the dike lines of the scene's truth (completeness, planimetric and height RMS); the
figures of all line kinds on the default tile are in docs/breaklines.md.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--points", type=int, default=1_000_000, help="about this many ground points (default %(default)s)")
    p.add_argument("--repeat", type=int, default=2, help="timed runs; the best counts (default %(default)s)")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    args = p.parse_args(argv)
    sys.path.insert(0, str(HERE))
    from bench_features import best_of, ensure_lidarfx_importable, run_process

    ensure_lidarfx_importable()
    import lidarfx
    from lidarfx.breaklines import line_distances
    from lidarfx.vector import read_geojson

    res: dict = {"lidarfx": lidarfx.__version__, "date": time.strftime("%Y-%m-%d")}
    size = math.sqrt(args.points / 4.0)
    kw = dict(density=4, noise=0.05, vegetation=0.1, off_terrain=0.1, seed=5)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cloud = lidarfx.synth.terrain(size=size, **kw)
        res["points"] = len(cloud)
        res["ground_points"] = int((cloud["classification"] == 2).sum())
        src = work / "terrain.laz"
        lidarfx.write(cloud, src)
        small = work / "small.laz"
        lidarfx.write(lidarfx.synth.terrain(size=60.0, **kw), small)
        run_process([sys.executable, "-m", "lidarfx", "breaklines", str(small), str(work / "w.geojson"), "-q"])
        out = work / "lines.geojson"
        cmd = [sys.executable, "-m", "lidarfx", "breaklines", str(src), str(out), "-q"]
        res["cli_seconds"] = best_of(lambda: run_process(cmd), args.repeat)
        lines, _ = read_geojson(out)
        truth = cloud.meta["truth"]["breaklines"]
        res["kinds"] = {}
        for kind in ("dike_crest", "dike_toe"):  # in a large tile the ditch is a whole ring: its truth is not one polyline
            d = line_distances(lines, [b["points"] for b in truth if b["kind"] == kind])
            res["kinds"][kind] = {k: d[k] for k in ("completeness", "rms_xy", "rms_z")}
    print(f"lidarfx {res['lidarfx']}: lidarfx breaklines on {res['ground_points']:,} ground points "
          f"({res['points']:,} in all, 4 pts/m², 5 cm noise, vegetation)")
    for kind, d in res["kinds"].items():
        print(f"  {kind:13s} completeness {d['completeness']:.3f}  RMS plan {d['rms_xy']:.3f} m  height {d['rms_z']:.3f} m")
    v = res["cli_seconds"]
    print(f"cli_seconds {v:9.1f}  target <= 60  {'PASS' if v <= 60 else 'FAIL'}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
