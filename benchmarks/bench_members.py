#!/usr/bin/env python
"""Member vectorisation of the synthetic lattice tower: found shares, errors and times.

Run by hand (not collected by pytest)::

    python benchmarks/bench_members.py                            # seeds 0-4, 1000 and 300 points/m²
    python benchmarks/bench_members.py --seeds 100,101,102,103,104   # the tuning seeds
    python benchmarks/bench_members.py --real ../shared/data/real/lone-star.laz --json bench.json

For every seed and density: :func:`lidarfx.synth.tower` (default geometry, bolts, 2 mm noise),
:func:`lidarfx.tower.vectorise_members` with its defaults (timed after an untimed warm-up
call that compiles the kernels), :func:`lidarfx.tower.members.score_members` against the
truth's centroid axes (found: within 2°, mean distance 0.05 m, 80 % of the length covered).
Prints per group (body legs, peak legs, braces, arms) found / total, the largest angle and
distance error of the found members and the label agreement, then the totals.  ``--real``
also times the files given (no truth: members, labels and time only).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
GROUPS = ("leg", "peak", "brace", "arm")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", default="0,1,2,3,4", help="seeds of the towers (default %(default)s)")
    p.add_argument("--densities", default="1000,300", help="points per m² on the flanges (default %(default)s)")
    p.add_argument("--real", nargs="*", default=[], help="point clouds to time as well (no truth)")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        import lidarfx
    except ImportError:  # run from a checkout
        sys.path.insert(0, str(HERE.parent / "src"))
        import lidarfx
    from lidarfx.tower import vectorise_members
    from lidarfx.tower.members import score_members

    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    densities = [float(d) for d in args.densities.split(",") if d.strip()]
    vectorise_members(lidarfx.synth.tower(seed=0, density=100, height=10.0, n_panels=2))  # warm-up: kernels
    rows = []
    for density in densities:
        totals = {g: [0, 0] for g in GROUPS}
        print(f"density {density:g} points/m²")
        for seed in seeds:
            cloud = lidarfx.synth.tower(seed=seed, density=density)
            t0 = time.perf_counter()
            res = vectorise_members(cloud)
            dt = time.perf_counter() - t0
            g = score_members(res, cloud.meta["truth"])["groups"]
            rows.append({"seed": seed, "density": density, "points": len(cloud), "seconds": round(dt, 2),
                         "members": len(res.lines), "labels": res.meta["labels"], "groups": g})
            for k in GROUPS:
                totals[k][0] += g[k]["found"]
                totals[k][1] += g[k]["total"]
            print(f"  seed {seed}: {len(cloud):,} points, {dt:.1f} s, {len(res.lines)} members  "
                  + "  ".join(f"{k} {g[k]['found']}/{g[k]['total']} (≤{g[k]['angle_max']}°, ≤{g[k]['distance_max']} m, "
                              f"labels {g[k]['label_agreement']})" for k in GROUPS))
        print("  total: " + "  ".join(f"{k} {f}/{n} ({f / n:.1%})" for k, (f, n) in totals.items()))
    real = []
    for path in args.real:
        cloud = lidarfx.read(path)
        t0 = time.perf_counter()
        res = vectorise_members(cloud)
        dt = time.perf_counter() - t0
        real.append({"file": str(path), "points": len(cloud), "seconds": round(dt, 2), "members": len(res.lines),
                     "labels": res.meta["labels"], "line_points": res.meta["line_points"],
                     "steps": res.meta["seconds"]})
        print(f"{Path(path).name}: {len(cloud):,} points, {dt:.1f} s, {len(res.lines)} members {res.meta['labels']}, "
              f"steps {res.meta['seconds']}")
    if args.json:
        Path(args.json).write_text(json.dumps({"towers": rows, "real": real}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
