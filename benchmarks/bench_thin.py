#!/usr/bin/env python
"""Block thinning of a dense TLS scan: ``lidarfx thin`` on an 87.7 M-point synthetic lattice tower.

Run by hand (not collected by pytest)::

    python benchmarks/bench_thin.py                          # 87.7 M points (the scan of issue 28)
    python benchmarks/bench_thin.py --points 5000000 --json bench.json
    python benchmarks/bench_thin.py --baseline               # also the memory of reading it all at once

What it does:

1. generates a TLS-like scan of a lattice steel tower once and caches it as LAZ in ``--workdir``
   (default: ``<temp>/lidarfx-bench-thin``; a rerun with the same ``--points`` and ``--seed``
   skips this step).  The tower is :func:`lidarfx.synth.tower` (45 m, 9 panels, angle-profile
   members, bolts, 2 mm noise) sampled again and again with new seeds, so the union is one
   dense sampling; around it the ground of a 30 m disc, sampled from the two scanner positions
   of the tower's truth with the 1/r² fall-off of a terrestrial scanner.  60 % of the points are
   on the tower, 40 % on the ground; classes 15 (tower) and 2 (ground), intensity, GPS time and
   the scanner as point source id, LAS 1.4 point format 6, 0.1 mm scale, UTM-sized offsets.
   Generation is chunk-wise: one tower sampling or one block of ground points at a time goes
   to the LAZ writer, so it runs in bounded memory too.
2. runs ``lidarfx thin big.laz thin.laz --cell 0.05 -q`` as a whole process ``--repeat``
   times, each under ``bench_features.peak_rss_mb`` (``/usr/bin/time -v``, else getrusage)
   and timed by ``bench_features.best_of``: the best wall time and the largest peak resident
   memory count.  Target: peak ≤ 2 GiB.
3. checks the answer on the output: one point per occupied 5 cm cell (all cells distinct) and
   prints points in / out.
4. with ``--baseline``: the peak memory of ``laspy.read`` of the whole file (what an in-memory
   tool needs at least: the point records alone).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
OFFSET = (500_000.0, 5_000_000.0, 0.0)  # UTM-sized coordinates
TOWER = {"height": 45.0, "base_width": 8.0, "top_width": 2.0, "n_panels": 9}
TOWER_SHARE = 0.6
GROUND_RADIUS = 30.0
CHUNK = 2_000_000
TARGET_GIB = 2.0


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--points", type=int, default=87_700_000, help="points of the scan (default %(default)s)")
    p.add_argument("--cell", type=float, default=0.05, help="thinning cell (default %(default)s m)")
    p.add_argument("--repeat", type=int, default=1, help="timed runs; the best counts (default %(default)s)")
    p.add_argument("--seed", type=int, default=28, help="seed of the scene (default %(default)s)")
    p.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "lidarfx-bench-thin",
                   help="where the generated scan is cached (default %(default)s)")
    p.add_argument("--baseline", action="store_true", help="also the peak memory of reading the whole file with laspy")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    args = p.parse_args(argv)
    if args.points < 100_000 or args.repeat < 1 or not args.cell > 0:
        p.error("--points must be >= 100000, --repeat >= 1, --cell > 0")
    return args


# --------------------------------------------------------------------------- the scan
def _header(seed: int):
    import laspy
    import numpy as np

    h = laspy.LasHeader(point_format=6, version="1.4")
    h.scales = np.full(3, 0.0001)
    h.offsets = np.array(OFFSET)
    h.system_identifier = "lidarfx bench_thin"
    h.generating_software = f"bench_thin seed {seed}"
    return h


def _records(header, xyz, cls, intensity, source, t0: float):
    import laspy
    import numpy as np

    rec = laspy.ScaleAwarePointRecord.zeros(len(xyz), header=header)
    rec.x, rec.y, rec.z = xyz[:, 0] + OFFSET[0], xyz[:, 1] + OFFSET[1], xyz[:, 2] + OFFSET[2]
    rec.classification = cls
    rec.intensity = intensity
    rec.point_source_id = source
    rec.return_number = np.ones(len(xyz), np.uint8)
    rec.number_of_returns = np.ones(len(xyz), np.uint8)
    rec.gps_time = t0 + np.arange(len(xyz)) * 1e-6  # 1 MHz scan
    return rec


def _ground(rng, n: int, scanners):
    """``n`` ground points in the disc around the tower, from the scanners with density ∝ 1/r²
    (a uniform range r): a terrestrial scan of the surroundings."""
    import numpy as np

    out, have = [], 0
    while have < n:
        m = int(1.3 * (n - have)) + 1000
        which = rng.integers(0, len(scanners), m)
        sc = np.asarray(scanners)[which]
        r = rng.uniform(1.5, 2.0 * GROUND_RADIUS, m)
        phi = rng.uniform(0.0, 2 * math.pi, m)
        x, y = sc[:, 0] + r * np.cos(phi), sc[:, 1] + r * np.sin(phi)
        ok = np.hypot(x, y) <= GROUND_RADIUS
        x, y, src = x[ok], y[ok], which[ok]
        z = 0.15 * np.sin(x / 7.0) * np.cos(y / 9.0) + 0.01 * x + rng.normal(0.0, 0.003, len(x))
        out.append((np.column_stack([x, y, z]), src))
        have += len(x)
    xyz = np.vstack([o[0] for o in out])[:n]
    return xyz, np.concatenate([o[1] for o in out])[:n]


def make_scan(path: Path, points: int, seed: int) -> dict:
    """Write the scan chunk by chunk (see the module docstring); returns its composition."""
    import laspy
    import numpy as np

    import lidarfx

    # points of one sampling = a × density (members) + b (bolts, a fixed number each): two probes
    p1, p2 = (lidarfx.synth.tower(density=d, seed=seed, **TOWER) for d in (1000.0, 2000.0))
    scanners = [s[:2] for s in p1.meta["truth"]["scanners"]]
    a = (len(p2) - len(p1)) / 1000.0
    b = len(p1) - 1000.0 * a
    n_tower = int(round(TOWER_SHARE * points))
    per_pass = 2_500_000
    passes = max(1, math.ceil(n_tower / per_pass))
    density = max(10.0, (n_tower / passes - b) / a)  # points per m² of one sampling
    header = _header(seed)
    tmp = path.with_suffix(".part.laz")
    rng = np.random.default_rng(seed)
    done, t = 0, 0.0
    with laspy.open(tmp, mode="w", header=header, do_compress=True) as writer:
        left = n_tower
        for k in range(passes):
            c = lidarfx.synth.tower(density=density, seed=seed * 1000 + k, **TOWER)
            take = min(len(c), left) if k == passes - 1 else len(c)
            xyz = c.xyz[:take]
            inten = rng.integers(800, 2400, take).astype(np.uint16)
            writer.write_points(_records(header, xyz, np.full(take, 15, np.uint8), inten, np.full(take, k % 2, np.uint16), t))
            done += take
            left -= take
            t += take * 1e-6
            print(f"  tower sampling {k + 1}/{passes}: {done:,} points", file=sys.stderr, flush=True)
        n_ground = points - done
        for a in range(0, n_ground, CHUNK):
            m = min(CHUNK, n_ground - a)
            xyz, src = _ground(rng, m, scanners)
            inten = rng.integers(200, 1500, m).astype(np.uint16)
            writer.write_points(_records(header, xyz, np.full(m, 2, np.uint8), inten, src.astype(np.uint16), t))
            done += m
            t += m * 1e-6
        print(f"  ground: {n_ground:,} points", file=sys.stderr, flush=True)
    os.replace(tmp, path)
    return {"points": done, "tower_points": points - n_ground, "ground_points": n_ground, "tower_samplings": passes,
            "tower_density_per_sampling": round(density, 1), "tower": TOWER, "ground_radius": GROUND_RADIUS}


def cached_scan(workdir: Path, points: int, seed: int) -> tuple[Path, dict, float | None]:
    """The scan file, generated when it is not in ``workdir`` yet; its facts and the generation seconds."""
    import laspy

    workdir.mkdir(parents=True, exist_ok=True)
    path = workdir / f"tower_{points}_s{seed}.laz"
    facts_path = path.with_suffix(".json")
    if path.exists() and facts_path.exists():
        with laspy.open(path) as r:
            if int(r.header.point_count) == points:
                return path, json.loads(facts_path.read_text()), None
    print(f"generating {points:,} points -> {path}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    facts = make_scan(path, points, seed)
    seconds = time.perf_counter() - t0
    facts_path.write_text(json.dumps(facts, indent=2))
    return path, facts, seconds


# --------------------------------------------------------------------------- checks
def distinct_cells(path: Path, cell: float) -> tuple[int, int]:
    """Points of a (thinned) file and its distinct cells, read chunk-wise."""
    import numpy as np

    from lidarfx.io import las
    from lidarfx.thin import cell_indices

    keys, n = [], 0
    for _, rec, header in las.iter_records(path):
        ijk = cell_indices(las.record_xyz(rec, header), cell)
        keys.append(ijk)
        n += len(rec)
    ijk = np.vstack(keys) if keys else np.zeros((0, 3), np.int64)
    return n, len(np.unique(ijk, axis=0))


def main(argv=None) -> int:
    args = parse_args(argv)
    sys.path.insert(0, str(HERE))
    from bench_features import best_of, ensure_lidarfx_importable, peak_rss_mb

    ensure_lidarfx_importable()
    import lidarfx

    res: dict = {"lidarfx": lidarfx.__version__, "date": time.strftime("%Y-%m-%d"), "cpus": os.cpu_count(),
                 "cell": args.cell}
    src, facts, gen_s = cached_scan(args.workdir, args.points, args.seed)
    res["scan"] = {**facts, "file": str(src), "bytes": src.stat().st_size,
                   "generated_seconds": None if gen_s is None else round(gen_s, 1)}
    out = args.workdir / "thin.laz"
    cmd = [sys.executable, "-m", "lidarfx", "thin", str(src), str(out), "--cell", f"{args.cell:g}", "-q"]
    print("running: " + " ".join(cmd), file=sys.stderr, flush=True)
    peaks: list[tuple[float, str]] = []  # every timed run also measures its peak memory
    res["seconds"] = round(best_of(lambda: peaks.append(peak_rss_mb(cmd)), args.repeat), 2)
    mb, how = max(peaks)
    res["peak_rss_mb"], res["peak_rss_method"] = round(mb, 1), how
    n_out, cells = distinct_cells(out, args.cell)
    res["kept"], res["kept_cells_distinct"] = n_out, cells == n_out
    res["points_per_second"] = round(args.points / res["seconds"])
    if args.baseline:
        probe = [sys.executable, "-c", f"import laspy; laspy.read({str(src)!r})"]
        bmb, _ = peak_rss_mb(probe)
        res["baseline_laspy_read_peak_rss_mb"] = round(bmb, 1)
    res["target"] = {"peak_gib": TARGET_GIB, "pass": res["peak_rss_mb"] <= TARGET_GIB * 1024}

    sc = res["scan"]
    print()
    print(f"scan: {sc['points']:,} points ({sc['tower_points']:,} tower, {sc['ground_points']:,} ground), "
          f"{sc['bytes'] / 2**20:,.0f} MiB LAZ" + (f", generated in {sc['generated_seconds']:.0f} s" if gen_s else " (cached)"))
    print(f"lidarfx thin --cell {args.cell:g}: {res['kept']:,} points kept "
          f"({100 * res['kept'] / sc['points']:.2f} %), one per occupied cell: {res['kept_cells_distinct']}")
    print(f"wall time {res['seconds']:.1f} s ({res['points_per_second'] / 1e6:.2f} M points/s), "
          f"peak RSS {res['peak_rss_mb']:,.0f} MB ({res['peak_rss_method']})")
    if "baseline_laspy_read_peak_rss_mb" in res:
        b = res["baseline_laspy_read_peak_rss_mb"]
        print(f"baseline: laspy.read of the whole file peaks at {b:,.0f} MB ({b / res['peak_rss_mb']:.1f} x thin)")
    print(f"target peak <= {TARGET_GIB:g} GiB: {'PASS' if res['target']['pass'] else 'FAIL'}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
