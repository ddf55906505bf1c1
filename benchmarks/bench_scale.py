#!/usr/bin/env python
"""Scale: ``lidarfx features --features eigen,plane,density -r 0.5`` on 1 M, 10 M and 87.7 M points.

Run by hand (not collected by pytest)::

    python benchmarks/bench_scale.py                                   # 1 M, 10 M, 87.7 M points
    python benchmarks/bench_scale.py --sizes 1000000,10000000 --json bench.json
    python benchmarks/bench_scale.py --sizes 87700000 --workers 2 --chunk-size 200

What it does:

1. generates, once per size, the undulating terrain of ``bench_features.make_terrain`` (100
   points/m², 2 cm noise, UTM-sized coordinates) strip by strip straight into one LAZ file
   (LAS 1.4, point format 6, mm scale) in ``--workdir``, so generation runs in bounded memory
   too; a rerun finds the cached file;
2. runs ``python -m lidarfx features IN OUT.las --features eigen,plane,density -r 0.5 --json``
   (``--ext .laz``: LAZ output)
   as a whole process (the command chooses in-memory or chunked by itself unless
   ``--chunk-size`` / ``--workers`` are given), sampling the resident memory of the process
   and all its children (the Dask workers) every 0.2 s: the peak of that sum counts;
3. prints wall seconds, points/s, peak memory and the chunking the command chose, and the
   targets: 87.7 M points in <= 10 min wall and <= 6 GiB peak on 2 cores, and throughput at
   the largest size within 0.5 x of the 1 M run's (near-linear).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
FEATURES = "eigen,plane,density"
RADIUS = 0.5
TARGET_SECONDS = 600.0
TARGET_GIB = 6.0
STRIP = 2_000_000


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="1000000,10000000,87700000", help="point counts, comma-separated")
    p.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "lidarfx-bench-scale",
                   help="where the generated inputs are cached (default %(default)s)")
    p.add_argument("--workers", type=int, default=None, help="passed to lidarfx features --workers")
    p.add_argument("--chunk-size", type=float, default=None, help="passed to lidarfx features --chunk-size")
    p.add_argument("--ext", default=".las", choices=[".las", ".laz"],
                   help="output format (default %(default)s: float features barely compress, and LAZ writing of "
                        "one file is serial)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--keep-output", action="store_true", help="keep the outputs in --workdir")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    return p.parse_args(argv)


def make_input(path: Path, n: int, seed: int) -> float:
    """Write ``n`` terrain points strip by strip (rows of y) into ``path``; returns seconds."""
    import laspy
    import numpy as np

    sys.path.insert(0, str(HERE))
    from bench_features import DENSITY, OFFSET

    t0 = time.perf_counter()
    side = math.sqrt(n / DENSITY)
    strips = max(1, math.ceil(n / STRIP))
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([OFFSET[0], OFFSET[1], 0.0])
    tmp = path.with_suffix(".part.laz")
    rng = np.random.default_rng(seed)
    with laspy.open(tmp, mode="w", header=header) as writer:
        done = 0
        for s in range(strips):
            m = n // strips + (1 if s < n % strips else 0)
            x = rng.uniform(0.0, side, m)
            y = rng.uniform(s * side / strips, (s + 1) * side / strips, m)
            z = (2.0 * np.sin(2 * np.pi * x / 37.0) * np.cos(2 * np.pi * y / 53.0)
                 + 0.5 * np.sin(2 * np.pi * (x + y) / 11.0) + 0.01 * x + rng.normal(0.0, 0.02, m))
            rec = laspy.ScaleAwarePointRecord.zeros(m, header=header)
            rec.x, rec.y, rec.z = x + OFFSET[0], y + OFFSET[1], z + OFFSET[2]
            rec.return_number = np.ones(m, np.uint8)
            rec.number_of_returns = np.ones(m, np.uint8)
            rec.gps_time = np.arange(done, done + m, dtype=np.float64) * 1e-5
            writer.write_points(rec)
            done += m
    os.replace(tmp, path)
    return time.perf_counter() - t0


def cached_input(workdir: Path, n: int, seed: int) -> tuple[Path, float | None]:
    import laspy

    workdir.mkdir(parents=True, exist_ok=True)
    path = workdir / f"terrain_{n}_s{seed}.laz"
    if path.exists():
        with laspy.open(path) as r:
            if int(r.header.point_count) == n:
                return path, None
    print(f"generating {n:,} points -> {path}", file=sys.stderr, flush=True)
    return path, make_input(path, n, seed)


class TreeMemory:
    """Peak of the summed resident memory of a process and all its descendants (psutil)."""

    def __init__(self, pid: int, every: float = 0.2):
        import psutil

        self.proc = psutil.Process(pid)
        self.every = every
        self.peak = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        import psutil

        while not self._stop.is_set():
            total = 0
            try:
                procs = [self.proc, *self.proc.children(recursive=True)]
            except psutil.Error:
                break
            for p in procs:
                try:
                    total += p.memory_info().rss
                except psutil.Error:
                    pass
            self.peak = max(self.peak, total)
            self._stop.wait(self.every)

    def stop(self) -> int:
        self._stop.set()
        self._thread.join()
        return self.peak


def run_features(src: Path, out: Path, args) -> dict:
    cmd = [sys.executable, "-m", "lidarfx", "features", str(src), str(out), "--features", FEATURES,
           "-r", f"{RADIUS:g}", "--json"]
    if args.workers is not None:
        cmd += ["--workers", str(args.workers)]
    if args.chunk_size is not None:
        cmd += ["--chunk-size", f"{args.chunk_size:g}"]
    print("running: " + " ".join(cmd), file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    mem = TreeMemory(proc.pid)
    stdout, stderr = proc.communicate()
    seconds = time.perf_counter() - t0
    peak = mem.stop()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{stderr[-2000:]}")
    summary = json.loads(stdout)
    return {"seconds": round(seconds, 1), "peak_mb": round(peak / 2**20, 1), "summary": summary}


def main(argv=None) -> int:
    args = parse_args(argv)
    sys.path.insert(0, str(HERE))
    from bench_features import ensure_lidarfx_importable

    ensure_lidarfx_importable()
    import lidarfx

    sizes = [int(v) for v in args.sizes.split(",") if v.strip()]
    res: dict = {"lidarfx": lidarfx.__version__, "date": time.strftime("%Y-%m-%d"), "cpus": os.cpu_count(),
                 "features": FEATURES, "radius": RADIUS, "runs": []}
    small = args.workdir / "warm.laz"
    if not small.exists():
        make_input(small, 20_000, 0)
    subprocess.run([sys.executable, "-m", "lidarfx", "features", str(small), str(args.workdir / "warm_out.laz"),
                    "--features", FEATURES, "-r", "0.5", "-q"], check=True)  # numba cache
    for n in sizes:
        src, gen = cached_input(args.workdir, n, args.seed)
        out = args.workdir / f"features_{n}{args.ext}"
        r = run_features(src, out, args)
        s = r["summary"]
        run = {"points": n, "input_mib": round(src.stat().st_size / 2**20, 1),
               "generated_seconds": None if gen is None else round(gen, 1), "seconds": r["seconds"],
               "points_per_second": round(n / r["seconds"]), "peak_mb": r["peak_mb"],
               "chunked": "chunks" in s,
               "output": args.ext, "steps": s.get("seconds"),
               **({k: s[k] for k in ("chunks", "chunk_size", "buffer", "workers", "largest_chunk_points")}
                  if "chunks" in s else {})}
        res["runs"].append(run)
        print(f"{n:>12,} points: {r['seconds']:8.1f} s  {run['points_per_second'] / 1e6:6.2f} M points/s  "
              f"peak {r['peak_mb']:8,.0f} MB  "
              + (f"{s['chunks']} chunks of {s['chunk_size']:g} m, {s['workers']} workers, largest chunk "
                 f"{s['largest_chunk_points']:,} points, steps {s['seconds']}" if "chunks" in s
                 else "in memory"), flush=True)
        if not args.keep_output:
            out.unlink(missing_ok=True)
    big = max(res["runs"], key=lambda r: r["points"])
    first = min(res["runs"], key=lambda r: r["points"])
    res["targets"] = {
        "seconds": {"value": big["seconds"], "limit": TARGET_SECONDS, "points": big["points"],
                    "pass": big["seconds"] <= TARGET_SECONDS},
        "peak_gib": {"value": round(big["peak_mb"] / 1024, 2), "limit": TARGET_GIB, "pass": big["peak_mb"] <= TARGET_GIB * 1024},
        "throughput_ratio": {"value": round(big["points_per_second"] / first["points_per_second"], 2), "limit": 0.5,
                             "pass": big["points_per_second"] >= 0.5 * first["points_per_second"]},
    }
    for name, t in res["targets"].items():
        print(f"{name:17s} {t['value']!s:>8}  target {'<=' if name != 'throughput_ratio' else '>='} {t['limit']}  "
              f"{'PASS' if t['pass'] else 'FAIL'}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
