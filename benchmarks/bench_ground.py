#!/usr/bin/env python
"""Ground-filter benchmark on the ISPRS filter-test samples (and timings on real tiles).

Run by hand (not collected by pytest)::

    PYTHONPATH=src python benchmarks/bench_ground.py                  # errors with the defaults
    PYTHONPATH=src python benchmarks/bench_ground.py --timings        # + speed on other real tiles
    PYTHONPATH=src python benchmarks/bench_ground.py --tuning         # the tuning grid + leave-one-out
    PYTHONPATH=src python benchmarks/bench_ground.py --steep          # dense tiles made steep
    PYTHONPATH=src python benchmarks/bench_ground.py --json out.json  # also save every number

What it does:

1. reads the 8 ISPRS samples ``samp*-utm.laz`` from ``../shared/data/real``
   (``--data`` to change), hides their classes from the filter (only x, y, z and
   the return numbers are passed) and runs :func:`lidarfx.ground.classify_ground`
   with the default parameters;
2. prints type I, type II and total error per sample (Sithole & Vosselman 2004)
   and the mean over the samples;
3. ``--timings``: seconds of ``classify_ground``, ``height_above_ground`` and
   ``dtm`` (1 m) on other real tiles (IGN 30 pts/m², autzen, Topography, pont,
   12AN2), best of 3 after a warm-up;
4. ``--tuning``: the grid of parameter sets the defaults were chosen from
   (docs/ground.md): mean total error of every set, the best set, and the
   leave-one-out figure (for each sample, the set that is best on the other 7
   samples, scored on the held-out one).  One process; a few minutes.
5. ``--steep``: dense ALS on steep terrain.  The three labelled IGN tiles
   (30 pts/m², flat) as they are and as three terrain-sheared copies each
   (:func:`lidarfx.classify.pipeline.terrain_shear`, seeds 100-102: z + a smooth
   random surface with slopes up to about 45°, labels unchanged); reference ground
   = class 2, object = classes 3-6.  Errors of a small grid of opening slopes,
   cells and scalars (docs/ground.md §9).
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parents[1] / "shared" / "data" / "real"
SAMPLES = ["samp11", "samp21", "samp23", "samp31", "samp41", "samp51", "samp53", "samp61"]
IGN_TILES = [f"test_data_{t}_627755_LA93_IGN69.laz" for t in (77050, 77055, 77060)]
STEEP_GRID = {"slope": [0.2, 0.3, 0.4, 0.5], "cell": [1.0, 1.5], "scalar": [1.0, 1.5]}
TIMING_FILES = [
    "test_data_77050_627755_LA93_IGN69.laz",
    "autzen_trim.laz",
    "Topography.laz",
    "pont.laz",
    "12AN2_20.laz",
]

# The tuning grid (docs/ground.md).  The final classification (threshold,
# scalar) is cheap, so it is scanned for every provisional DTM.
GRID = {
    "cell": [1.0, 1.25, 1.5],
    "slope": [0.15, 0.2, 0.25],
    "window": [15.0, 21.0],
    "threshold": [0.4, 0.5, 0.6, 0.7, 0.8],
    "scalar": [1.0, 1.25, 1.5, 1.75, 2.0],
}


def load(data: Path):
    import lidarfx
    from lidarfx import PointCloud

    out = []
    for s in SAMPLES:
        f = data / f"{s}-utm.laz"
        if not f.exists():
            sys.exit(f"missing {f}")
        c = lidarfx.read(f)
        bare = PointCloud(c.xyz, {k: c[k] for k in ("return_number", "number_of_returns")})
        out.append((s, bare, c["classification"] == 2))
    return out


def errors_table(samples, params=None):
    from lidarfx.ground import classify_ground, ground_errors

    rows = []
    for name, bare, ref in samples:
        t0 = time.perf_counter()
        mask = classify_ground(bare, **(params or {}))
        sec = time.perf_counter() - t0
        e = ground_errors(mask, ref)
        e.update(sample=name, seconds=round(sec, 3))
        rows.append(e)
    return rows


def print_table(rows) -> None:
    print(f"{'sample':8s} {'points':>7s} {'type I %':>9s} {'type II %':>9s} {'total %':>8s} {'s':>6s}")
    for r in rows:
        print(f"{r['sample']:8s} {r['n_points']:7d} {100 * r['type_i']:9.2f} {100 * r['type_ii']:9.2f} "
              f"{100 * r['total']:8.2f} {r['seconds']:6.2f}")
    m = {k: np.mean([r[k] for r in rows]) for k in ("type_i", "type_ii", "total")}
    print(f"{'mean':8s} {'':7s} {100 * m['type_i']:9.2f} {100 * m['type_ii']:9.2f} {100 * m['total']:8.2f}")


def tuning(samples):
    """Total error of every grid set on every sample, the best set and leave-one-out."""
    from lidarfx.surface.grid import bilinear, cell_index, gradient_slope
    from lidarfx.ground.smrf import provisional_dtm

    locals_ = [(n, b.xyz - b.xyz.min(axis=0), ref) for n, b, ref in samples]
    sets, table = [], []
    for cell, slope, window in itertools.product(GRID["cell"], GRID["slope"], GRID["window"]):
        surfs = []
        for _, xyz, _ in locals_:
            s = provisional_dtm(xyz, cell=cell, slope=slope, window=window)
            i, j = cell_index(xyz[:, :2], s.spec)
            surfs.append((xyz[:, 2] - bilinear(s.grid, s.spec, xyz[:, :2]), gradient_slope(s.grid, cell)[i, j]))
        for thr, sc in itertools.product(GRID["threshold"], GRID["scalar"]):
            tot = []
            for (_, xyz, ref), (res, g) in zip(locals_, surfs):
                pred = np.abs(res) <= thr + sc * g
                tot.append(np.mean(pred != ref))
            sets.append({"cell": cell, "slope": slope, "window": window, "threshold": thr, "scalar": sc})
            table.append(tot)
        print(f"  cell {cell} slope {slope} window {window}: best mean total "
              f"{100 * min(np.mean(t) for t in table[-25:]):.2f} %", flush=True)
    table = np.array(table)  # sets x samples
    means = table.mean(axis=1)
    best = int(np.argmin(means))
    loo = []
    for k in range(len(SAMPLES)):
        others = np.delete(table, k, axis=1).mean(axis=1)
        b = int(np.argmin(others))
        loo.append({"sample": SAMPLES[k], "chosen": sets[b], "held_out_total": float(table[b, k])})
    return {
        "grid": GRID,
        "best": {"params": sets[best], "mean_total": float(means[best]),
                 "per_sample_total": dict(zip(SAMPLES, map(float, table[best])))},
        "leave_one_out": {"per_sample": loo, "mean_total": float(np.mean([r["held_out_total"] for r in loo]))},
    }


def steep(data: Path):
    """Errors on the IGN tiles, flat and terrain-sheared, for the STEEP_GRID sets."""
    import lidarfx
    from lidarfx.classify.pipeline import terrain_shear
    from lidarfx.ground import classify_ground, ground_errors

    clouds = []
    for name in IGN_TILES:
        f = data / name
        if not f.exists():
            sys.exit(f"missing {f}")
        c = lidarfx.read(f)
        cls = np.asarray(c["classification"])
        keep = np.isin(cls, [2, 3, 4, 5, 6])
        for seed in (None, 100, 101, 102):
            cc = c if seed is None else terrain_shear(c, seed=seed)
            bare = lidarfx.PointCloud(cc.xyz, {k: c[k] for k in ("return_number", "number_of_returns")})
            clouds.append((seed is not None, bare, cls == 2, keep))
    out = []
    print(f"{'slope':>5s} {'cell':>4s} {'scalar':>6s}   flat: I % / II % / total %   sheared: I % / II % / total %")
    for slope, cell, scalar in itertools.product(STEEP_GRID["slope"], STEEP_GRID["cell"], STEEP_GRID["scalar"]):
        p = {"slope": slope, "cell": cell, "scalar": scalar}
        errs = {False: [], True: []}
        for sheared, bare, ref, keep in clouds:
            e = ground_errors(classify_ground(bare, **p)[keep], ref[keep])
            errs[sheared].append([e["type_i"], e["type_ii"], e["total"]])
        r = {**p, "flat": np.mean(errs[False], axis=0).tolist(), "sheared": np.mean(errs[True], axis=0).tolist()}
        out.append(r)
        print(f"{slope:5.2f} {cell:4.1f} {scalar:6.2f}   " + "  ".join(
            " / ".join(f"{100 * v:.2f}" for v in r[k]) + "     " for k in ("flat", "sheared")), flush=True)
    return out


def timings(data: Path):
    import lidarfx
    from lidarfx.ground import classify_ground, dtm, height_above_ground

    out = []
    for name in TIMING_FILES:
        f = data / name
        if not f.exists():
            continue
        c = lidarfx.read(f)
        classify_ground(c)  # warm-up (numba cache, imports)

        def best(fn):
            ts = []
            for _ in range(3):
                t0 = time.perf_counter()
                res = fn()
                ts.append(time.perf_counter() - t0)
            return min(ts), res

        tc, mask = best(lambda: classify_ground(c))
        th, _ = best(lambda: height_above_ground(c, mask))
        td, r = best(lambda: dtm(c, 1.0, ground=mask))
        out.append({"file": name, "points": len(c), "ground": int(mask.sum()), "classify_s": round(tc, 3),
                    "hag_s": round(th, 3), "dtm_s": round(td, 3), "dtm_shape": list(r.shape)})
        print(f"{name:40s} {len(c):8d} pts  classify {tc:6.2f} s  hag {th:6.2f} s  dtm {td:6.2f} s", flush=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--timings", action="store_true")
    ap.add_argument("--tuning", action="store_true")
    ap.add_argument("--steep", action="store_true", help="IGN tiles flat and terrain-sheared (docs/ground.md §9)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()

    from lidarfx.ground import DEFAULTS, classify_ground

    samples = load(args.data)
    classify_ground(samples[0][1])  # warm-up
    print(f"defaults: {DEFAULTS}")
    rows = errors_table(samples)
    print_table(rows)
    result = {"defaults": DEFAULTS, "samples": rows,
              "mean": {k: float(np.mean([r[k] for r in rows])) for k in ("type_i", "type_ii", "total")}}
    if args.timings:
        result["timings"] = timings(args.data)
    if args.tuning:
        t = tuning(samples)
        print(f"best grid set: {t['best']['params']}  mean total {100 * t['best']['mean_total']:.2f} %")
        for r in t["leave_one_out"]["per_sample"]:
            print(f"  leave-one-out {r['sample']}: {100 * r['held_out_total']:.2f} %  with {r['chosen']}")
        print(f"leave-one-out mean total {100 * t['leave_one_out']['mean_total']:.2f} %")
        result["tuning"] = t
    if args.steep:
        result["steep"] = steep(args.data)
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
