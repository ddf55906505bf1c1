#!/usr/bin/env python
"""A pipeline against the same commands in a row: ``lidarfx run`` vs four ``lidarfx`` processes.

Run by hand (not collected by pytest)::

    python benchmarks/bench_pipeline.py                      # the IGN tile 77055_627755, best of 3
    python benchmarks/bench_pipeline.py --input scan.laz --repeat 5 --json bench.json
    python benchmarks/bench_pipeline.py --chunks 25 --workers 2   # both in chunks on Dask

What it does:

1. writes the pipeline ``read → ground (--hag) → features (-r 1, eigen,plane,density) →
   classify (--model default) → select (classification == 6) → write`` to the work folder;
2. runs, as whole processes, ``lidarfx run pipeline.json`` and the four commands in a row
   ``lidarfx ground IN g.laz --hag``, ``lidarfx features g.laz f.laz -r 1 ...``,
   ``lidarfx classify predict f.laz c.laz --model default``,
   ``lidarfx select c.laz s.laz --where "classification == 6"``; once each untimed (numba
   loads or compiles its kernels), then ``--repeat`` times each, alternating; the best wall
   time and the least CPU time (user + system of the processes) count: on a busy machine the CPU
   time is the steadier figure;
3. checks that both end with the same file, byte for byte, and prints both times and their
   ratio.

With ``--chunks S`` both run in chunks of S m on ``--workers`` (an embedded Dask cluster):
the pipeline fused per chunk (classify with ``"ground": "attribute"`` and
``"min_building_area": 0``, as chunks need), the first three commands each in chunks with the
same options and ``select`` in memory; the outputs are compared point by point (their headers
differ).

The pipeline saves three interpreter starts with their imports, kernel loads and the default
model's load, and three LAZ writes and reads of the intermediate clouds with their features.
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
DEFAULT_INPUT = HERE.parents[1] / "shared/data/real/test_data_77055_627755_LA93_IGN69.laz"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--input", type=Path, default=DEFAULT_INPUT, help="LAS/LAZ file (default: %(default)s)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs of each; the best counts (default %(default)s)")
    p.add_argument("--workdir", type=Path, default=None, help="keep the outputs there (default: a temporary folder)")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    p.add_argument("--chunks", type=float, default=None, metavar="S", help="run both in chunks of S m")
    p.add_argument("--workers", type=int, default=1, help="with --chunks: Dask workers (default %(default)s)")
    return p.parse_args(argv)


def lidarfx(*args: str) -> None:
    env = {**os.environ, "LIDARFX_COMPILE_NOTICE": "0"}
    cmd = [sys.executable, "-m", "lidarfx", *args, "-q", "--force"]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{res.stderr}")


def _children_cpu() -> float:
    """User + system CPU seconds of the finished child processes so far."""
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def same_points(a_path: str, b_path: str) -> bool:
    """Every point and attribute of two files equal (NaN equals NaN)."""
    import numpy as np

    import lidarfx as lf

    a, b = lf.read(a_path), lf.read(b_path)
    if len(a) != len(b) or not np.array_equal(a.xyz, b.xyz) or sorted(a.names) != sorted(b.names):
        return False
    for n in a.names:
        x, y = np.asarray(a[n]), np.asarray(b[n])
        if not (np.array_equal(x, y, equal_nan=True) if x.dtype.kind == "f" else np.array_equal(x, y)):
            return False
    return True


def main(argv=None) -> int:
    args = parse_args(argv)
    if not args.input.is_file():
        raise SystemExit(f"input not found: {args.input}")
    work = args.workdir or Path(tempfile.mkdtemp(prefix="lidarfx-bench-pipeline-"))
    work.mkdir(parents=True, exist_ok=True)
    src = str(args.input)
    g, f, c, s, out = (str(work / n) for n in ("g.laz", "f.laz", "c.laz", "s.laz", "pipeline.laz"))
    pipe = work / "pipeline.json"
    pipe.write_text(json.dumps({"pipeline": [
        {"type": "read", "path": src},
        {"type": "ground", "hag": True},
        {"type": "features", "radius": 1.0, "features": "eigen,plane,density"},
        {"type": "classify", "model": "default",
         **({"ground": "attribute", "min_building_area": 0} if args.chunks else {})},
        {"type": "select", "where": "classification == 6"},
        {"type": "write", "path": out},
    ]}, indent=1))
    chunks = ["--chunk-size", f"{args.chunks:g}", "--workers", str(args.workers)] if args.chunks else []
    rules = ["--ground", "attribute", "--min-building-area", "0"] if args.chunks else []

    def pipeline() -> None:
        lidarfx("run", str(pipe), *chunks)

    def commands() -> None:
        lidarfx("ground", src, g, "--hag", *chunks)
        lidarfx("features", g, f, "-r", "1", "--features", "eigen,plane,density", *chunks)
        lidarfx("classify", "predict", f, c, "--model", "default", *rules, *chunks)
        lidarfx("select", c, s, "--where", "classification == 6")

    print(f"input {src}; work folder {work}", flush=True)
    pipeline()  # warm-up: kernels compiled or loaded, files cached
    commands()
    times: dict[str, list[float]] = {"pipeline": [], "commands": []}
    cpu: dict[str, list[float]] = {"pipeline": [], "commands": []}
    for r in range(args.repeat):
        for name, fn in (("pipeline", pipeline), ("commands", commands)):
            c0 = _children_cpu()
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
            cpu[name].append(_children_cpu() - c0)
            print(f"run {r + 1}: {name} {times[name][-1]:.2f} s wall, {cpu[name][-1]:.2f} s CPU", flush=True)
    same = Path(out).read_bytes() == Path(s).read_bytes() if not args.chunks else same_points(out, s)
    best = {k: min(v) for k, v in times.items()}
    best_cpu = {k: min(v) for k, v in cpu.items()}
    ratio = best["commands"] / best["pipeline"]
    ratio_cpu = best_cpu["commands"] / best_cpu["pipeline"]
    print(f"\n{'':38s} {'wall':>8s} {'CPU':>8s}")
    if args.chunks:
        print(f"in chunks of {args.chunks:g} m, {args.workers} worker(s)")
    print(f"{'pipeline (lidarfx run, 1 process)':38s} {best['pipeline']:7.2f}s {best_cpu['pipeline']:7.2f}s")
    print(f"{'commands in a row (4 processes)':38s} {best['commands']:7.2f}s {best_cpu['commands']:7.2f}s")
    print(f"{'ratio commands / pipeline':38s} {ratio:8.2f} {ratio_cpu:8.2f}")
    print(f"same output {'points' if args.chunks else 'file'}: {'yes' if same else 'NO'}")
    if args.json:
        Path(args.json).write_text(json.dumps({"input": src, "repeat": args.repeat, "chunks": args.chunks,
                                               "workers": args.workers if args.chunks else None, "wall": times, "cpu": cpu,
                                               "best_wall": best, "best_cpu": best_cpu, "ratio_wall": ratio,
                                               "ratio_cpu": ratio_cpu, "same_output": same}, indent=1))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
