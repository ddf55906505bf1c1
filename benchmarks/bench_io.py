#!/usr/bin/env python
"""ASCII vs binary PLY: write and read seconds of ``lidarfx.io`` on a real ~519 k-point file.

Run by hand (not collected by pytest)::

    python benchmarks/bench_io.py                                 # /work/shared/data/real/lone-star.laz
    python benchmarks/bench_io.py --input scan.laz --repeat 5 --json bench.json
    python benchmarks/bench_io.py --cli                           # also `lidarfx convert IN OUT.ply [--ascii]`

It reads the input once (LAS/LAZ or anything ``lidarfx.read`` takes), then for binary and
ASCII PLY times, best of ``--repeat`` after an untimed warm-up (numba compiles or loads the
ASCII writer's kernels there):

* ``write`` — ``lidarfx.write(cloud, out.ply[, ascii=True])`` (atomic write included);
* ``read``  — ``lidarfx.read(out.ply)``.

Every run checks the answer: xyz and every attribute read back from the ASCII file equal the
ones read back from the binary file (bit for bit).  ``--cli`` adds the whole process
``python -m lidarfx convert IN OUT.ply [--ascii]`` (interpreter start, imports, LAZ read,
PLY write), the command of issue 31.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if importlib.util.find_spec("lidarfx") is None:  # run from a checkout without an install: use ./src
    sys.path.insert(0, str(HERE.parent / "src"))

DEFAULT_INPUT = Path("/work/shared/data/real/lone-star.laz")  # 518 862 points, LAS point format 1


def best_of(fn, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--input", type=Path, default=DEFAULT_INPUT, help="point cloud to convert (default %(default)s)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs; the best counts (default %(default)s)")
    p.add_argument("--workdir", type=Path, default=None, help="where the PLY files go (default: a temporary folder)")
    p.add_argument("--cli", action="store_true", help="also time `python -m lidarfx convert IN OUT.ply [--ascii]`")
    p.add_argument("--json", default=None, help="also write every number to this JSON file")
    args = p.parse_args(argv)
    if args.repeat < 1:
        p.error("--repeat must be >= 1")

    import numpy as np

    import lidarfx

    with tempfile.TemporaryDirectory() as tmp:
        work = args.workdir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        cloud = lidarfx.read(args.input)
        res = {"input": str(args.input), "points": len(cloud), "attributes": list(cloud.names),
               "repeat": args.repeat, "lidarfx_version": lidarfx.__version__, "date": time.strftime("%Y-%m-%d")}
        print(f"{args.input}: {len(cloud):,} points, {len(cloud.names)} attributes; best of {args.repeat}")
        back = {}
        for kind, opts in (("binary", {}), ("ascii", {"ascii": True})):
            out = work / f"bench_{kind}.ply"
            lidarfx.write(cloud, out, **opts)  # warm-up: numba kernels compiled or loaded
            w = best_of(lambda out=out, opts=opts: lidarfx.write(cloud, out, **opts), args.repeat)
            r = best_of(lambda out=out: lidarfx.read(out), args.repeat)
            back[kind] = lidarfx.read(out)
            res[kind] = {"write_s": round(w, 3), "read_s": round(r, 3), "bytes": out.stat().st_size}
            print(f"  {kind:6s} PLY  write {w:7.3f} s   read {r:7.3f} s   {out.stat().st_size / 1e6:7.1f} MB")
        a, b = back["ascii"], back["binary"]
        same = np.array_equal(a.xyz, b.xyz) and all(np.array_equal(a[n], b[n]) for n in b.names)
        res["ascii_equals_binary"] = bool(same)
        print(f"  ASCII / binary: write x{res['ascii']['write_s'] / res['binary']['write_s']:.1f}, "
              f"read x{res['ascii']['read_s'] / res['binary']['read_s']:.1f}; values read back equal: {same}")
        if args.cli:
            for kind, extra in (("binary", []), ("ascii", ["--ascii"])):
                out = work / f"cli_{kind}.ply"
                cmd = [sys.executable, "-m", "lidarfx", "convert", str(args.input), str(out), *extra]

                def run(cmd=cmd, out=out):
                    out.unlink(missing_ok=True)
                    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)

                s = best_of(run, args.repeat)
                res[f"cli_{kind}_s"] = round(s, 3)
                print(f"  lidarfx convert {kind:6s}: {s:7.3f} s   ({' '.join(cmd[1:])})")
        if args.json:
            Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
        return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
