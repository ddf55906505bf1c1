#!/usr/bin/env python
"""Feature-engine benchmark: lidarfx against jakteristics and pgeof on the same file.

Run by hand (not collected by pytest)::

    python benchmarks/bench_features.py                     # 1 M points, best of 3
    python benchmarks/bench_features.py --points 100000 --repeat 1
    python benchmarks/bench_features.py --json bench.json   # also save every number

What it does (details and the meaning of every line in ``benchmarks/README.md``):

1. generates a deterministic synthetic terrain at 100 points/m² (1 M points =
   100 m × 100 m): smooth undulating ground, 2 cm Gaussian noise, UTM-sized
   coordinates (E 500 000, N 5 000 000), written once as LAS 1.4 to a temporary
   folder;
2. times, best of ``--repeat`` runs each,

   a. lidarfx in-process ``compute_features``: ``eigen`` at r = 0.5 m,
      ``eigen,plane,density`` at r = 0.5, ``eigen`` at r = 0.1 / 0.3 / 0.5 and
      ``all`` at r = 0.5 (numba kernels warmed up first, untimed);
   b. jakteristics in-process (its 27 features, r = 0.5) and its CLI as a whole
      process on the same LAS file;
   c. pgeof in-process: its own radius search + ``compute_features`` (11
      features), and ``compute_features_selected`` (radius search inside, all 14
      feature ids);
   d. the lidarfx CLI as a whole process (``python -m lidarfx features IN OUT -r
      0.5 --features eigen,plane,density -q``; one untimed warm-up run first);
   e. the peak resident memory of that CLI process, compared with the size of its
      input and output arrays;

3. prints a table of seconds and ratios, and the performance targets of issue 3
   with PASS / FAIL.

Thread counts: ``--threads`` (default: all cores) is exported as
``NUMBA_NUM_THREADS`` / ``OMP_NUM_THREADS`` / ``OPENBLAS_NUM_THREADS`` /
``MKL_NUM_THREADS`` before numpy or numba are imported, passed to jakteristics
as ``num_threads`` / ``-t`` and inherited by every subprocess.  pgeof's
taskflow executor always uses every hardware thread (it has no setting).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

REPO = Path(__file__).resolve().parents[1]
RADIUS = 0.5
RADII = (0.1, 0.3, 0.5)
DENSITY = 100.0  # points per m²
OFFSET = (500_000.0, 5_000_000.0, 300.0)  # UTM-sized coordinates
CLI_FEATURES = "eigen,plane,density"

# --------------------------------------------------------------------------- options


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--points", type=int, default=1_000_000, help="number of points (default 1,000,000)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per measurement; the best counts (default 3)")
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1, help="threads for every tool (default: all cores)")
    p.add_argument("--json", type=Path, default=None, help="write every number to this JSON file")
    p.add_argument("--workdir", type=Path, default=None, help="keep the LAS files here instead of a temporary folder")
    p.add_argument("--seed", type=int, default=42, help="seed of the synthetic terrain (default 42)")
    args = p.parse_args(argv)
    if args.points < 1000 or args.repeat < 1 or args.threads < 1:
        p.error("--points must be >= 1000, --repeat and --threads >= 1")
    return args


def pin_threads(n: int) -> None:
    """Export thread counts before numpy / numba are imported (subprocesses inherit them)."""
    for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(n)


def ensure_lidarfx_importable() -> None:
    """Use the repository's ``src`` when lidarfx is not installed (also for subprocesses)."""
    import importlib.util

    if importlib.util.find_spec("lidarfx") is None:
        src = str(REPO / "src")
        sys.path.insert(0, src)
        os.environ["PYTHONPATH"] = os.pathsep.join([src] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])


# --------------------------------------------------------------------------- data


def make_terrain(n: int, seed: int):
    """Deterministic undulating terrain at ``DENSITY`` points/m², UTM offsets, 2 cm noise."""
    import numpy as np

    rng = np.random.default_rng(seed)
    side = math.sqrt(n / DENSITY)
    x = rng.uniform(0.0, side, n)
    y = rng.uniform(0.0, side, n)
    z = (
        2.0 * np.sin(2 * np.pi * x / 37.0) * np.cos(2 * np.pi * y / 53.0)  # hills
        + 0.5 * np.sin(2 * np.pi * (x + y) / 11.0)  # shorter waves (slopes up to ~35°, median ~16°)
        + 0.01 * x  # a gentle regional tilt
        + rng.normal(0.0, 0.02, n)  # 2 cm noise
    )
    return np.column_stack([x + OFFSET[0], y + OFFSET[1], z + OFFSET[2]]), side


def write_las(xyz, path: Path) -> int:
    """Write xyz as LAS 1.4 point format 6 (mm scale); returns the point record length in bytes."""
    import laspy
    import numpy as np

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(xyz.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.return_number = np.ones(len(xyz), np.uint8)
    las.number_of_returns = np.ones(len(xyz), np.uint8)
    las.write(str(path))
    return int(header.point_format.size)


# --------------------------------------------------------------------------- timing


def best_of(fn: Callable[[], Any], repeat: int) -> float:
    """Best wall-clock seconds of ``repeat`` calls."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run_process(cmd: list[str]) -> None:
    """Run a command; raise with its stderr when it fails."""
    res = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({res.returncode}):\n{res.stderr[-2000:]}")


def peak_rss_mb(cmd: list[str]) -> tuple[float, str]:
    """Peak resident set size (MB) of one run of ``cmd`` and how it was measured."""
    gnu_time = shutil.which("time") or ("/usr/bin/time" if os.path.exists("/usr/bin/time") else None)
    if gnu_time:
        res = subprocess.run([gnu_time, "-v", *cmd], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        m = re.search(r"Maximum resident set size \(kbytes\):\s*(\d+)", res.stderr)
        if res.returncode == 0 and m:
            return int(m.group(1)) / 1024.0, "/usr/bin/time -v"
    # fallback: a fresh Python parent whose only child is the command
    probe = (
        "import resource, subprocess, sys; r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL); "
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss if r.returncode == 0 else -1)"
    )
    out = subprocess.run([sys.executable, "-c", probe, *cmd], capture_output=True, text=True, check=True).stdout
    kb = int(out.strip().splitlines()[-1])
    if kb < 0:
        raise RuntimeError(f"{' '.join(cmd)} failed")
    return kb / 1024.0, "getrusage(RUSAGE_CHILDREN)"


# --------------------------------------------------------------------------- measurements


def bench_lidarfx(cloud, repeat: int, res: dict) -> None:
    """a. in-process lidarfx."""
    from lidarfx.features import compute_features

    import numpy as np

    small = cloud.subset(np.arange(min(20_000, len(cloud))))
    runs = {
        "lidarfx_eigen": dict(features="eigen", radius=RADIUS),
        "lidarfx_eigen_plane_density": dict(features=CLI_FEATURES, radius=RADIUS),
        "lidarfx_eigen_3radii": dict(features="eigen", radii=list(RADII)),
        "lidarfx_all": dict(features="all", radius=RADIUS),
    }
    for name, kw in runs.items():
        compute_features(small, progress=False, **kw)  # warm-up: load / compile the numba kernels
        res["seconds"][name] = best_of(lambda: compute_features(cloud, progress=False, **kw), repeat)
        print(f"  {name:32s} {res['seconds'][name]:8.3f} s", flush=True)
    counts = compute_features(cloud, "n_neighbours", radius=RADIUS, query=np.arange(0, len(cloud), 50), progress=False)
    res["median_neighbours_r0.5"] = float(np.median(counts["n_neighbours"]))


def bench_jakteristics(xyz, las_in: Path, workdir: Path, threads: int, repeat: int, res: dict) -> None:
    """b. jakteristics in-process and as a CLI process."""
    import jakteristics
    from jakteristics.constants import FEATURE_NAMES

    res["versions"]["jakteristics"] = jakteristics.__version__
    res["jakteristics_features"] = len(FEATURE_NAMES)
    res["seconds"]["jakteristics_inproc"] = best_of(
        lambda: jakteristics.compute_features(xyz, RADIUS, feature_names=list(FEATURE_NAMES), num_threads=threads), repeat
    )
    print(f"  {'jakteristics_inproc':32s} {res['seconds']['jakteristics_inproc']:8.3f} s", flush=True)
    out = workdir / "jakteristics_out.las"
    cmd = [sys.executable, "-m", "jakteristics", str(las_in), str(out), "--search-radius", str(RADIUS), "--num-threads", str(threads)]
    res["commands"]["jakteristics_cli"] = " ".join(cmd)
    res["seconds"]["jakteristics_cli"] = best_of(lambda: run_process(cmd), repeat)
    print(f"  {'jakteristics_cli':32s} {res['seconds']['jakteristics_cli']:8.3f} s", flush=True)
    res["peak_rss_mb"]["jakteristics_cli"], _ = peak_rss_mb(cmd)


def bench_pgeof(xyz, repeat: int, res: dict) -> None:
    """c. pgeof in-process (float32 local coordinates: pgeof computes in single precision)."""
    import numpy as np
    import pgeof

    try:
        from importlib.metadata import version

        res["versions"]["pgeof"] = version("pgeof")
    except Exception:  # pragma: no cover - metadata missing
        res["versions"]["pgeof"] = "?"
    local32 = np.ascontiguousarray(xyz - xyz.min(axis=0), dtype=np.float32)
    local64 = np.ascontiguousarray(xyz - xyz.min(axis=0))
    # pgeof's radius search returns dense (n, max_knn) arrays: use the smallest power of two
    # above the largest neighbour count (found untimed), so no neighbour is dropped and no
    # memory is wasted on padding
    max_knn = 32
    while True:
        idx, _ = pgeof.radius_search(local32, local32, RADIUS, max_knn)
        most = int((idx >= 0).sum(axis=1).max())
        del idx
        if most < max_knn:
            break
        max_knn *= 2
    res["pgeof_max_neighbours"] = most
    res["pgeof_max_knn"] = max_knn
    print(f"  (largest neighbour count {most}, pgeof max_knn = {max_knn})")

    def search_and_features():
        idx, _ = pgeof.radius_search(local32, local32, RADIUS, max_knn)
        valid = idx >= 0
        nn = idx[valid].astype(np.uint32)
        ptr = np.zeros(len(idx) + 1, np.uint32)
        np.cumsum(valid.sum(axis=1), out=ptr[1:])
        return pgeof.compute_features(local32, nn, ptr, k_min=3)

    res["seconds"]["pgeof_search_features"] = best_of(search_and_features, repeat)
    print(f"  {'pgeof_search_features':32s} {res['seconds']['pgeof_search_features']:8.3f} s", flush=True)
    ids = list(pgeof.EFeatureID.__members__.values())
    res["pgeof_selected_features"] = len(ids)
    res["seconds"]["pgeof_selected"] = best_of(lambda: pgeof.compute_features_selected(local64, RADIUS, max_knn, ids), repeat)
    print(f"  {'pgeof_selected':32s} {res['seconds']['pgeof_selected']:8.3f} s", flush=True)


def bench_lidarfx_cli(las_in: Path, workdir: Path, repeat: int, res: dict) -> None:
    """d. + e. the lidarfx CLI as a whole process, and its peak memory."""
    out = workdir / "lidarfx_out.las"
    cmd = [sys.executable, "-m", "lidarfx", "features", str(las_in), str(out), "-r", str(RADIUS), "--features", CLI_FEATURES, "-q"]
    res["commands"]["lidarfx_cli"] = " ".join(cmd)
    run_process(cmd)  # warm-up: numba cache, page cache
    res["seconds"]["lidarfx_cli"] = best_of(lambda: run_process(cmd), repeat)
    print(f"  {'lidarfx_cli':32s} {res['seconds']['lidarfx_cli']:8.3f} s", flush=True)
    res["peak_rss_mb"]["lidarfx_cli"], res["peak_rss_method"] = peak_rss_mb(cmd)
    # the fixed cost (interpreter, imports, compiled kernels): the same command on 1,000 points
    tiny = workdir / "tiny.las"
    write_las(make_terrain(1000, 0)[0], tiny)
    base = cmd[:4] + [str(tiny), str(workdir / "tiny_out.las")] + cmd[6:]
    res["peak_rss_mb"]["lidarfx_cli_1000_points"], _ = peak_rss_mb(base)


# --------------------------------------------------------------------------- report


def fmt_ratio(a: float | None, b: float | None) -> str:
    return f"{a / b:6.2f}x" if a and b else "     -"


def report(res: dict) -> list[dict]:
    """Print the table and the targets; return the targets as dicts."""
    s = res["seconds"]
    n = res["points"]
    jak_cli, jak_in, pg = s.get("jakteristics_cli"), s.get("jakteristics_inproc"), s.get("pgeof_search_features")
    rows = [
        ("lidarfx eigen r=0.5 (in-process)", "lidarfx_eigen"),
        ("lidarfx eigen,plane,density r=0.5", "lidarfx_eigen_plane_density"),
        ("lidarfx eigen r=0.1,0.3,0.5", "lidarfx_eigen_3radii"),
        ("lidarfx all r=0.5", "lidarfx_all"),
        ("lidarfx CLI eigen,plane,density (process)", "lidarfx_cli"),
        (f"jakteristics {res.get('jakteristics_features', 27)} features (in-process)", "jakteristics_inproc"),
        ("jakteristics CLI (process)", "jakteristics_cli"),
        ("pgeof radius_search + compute_features", "pgeof_search_features"),
        (f"pgeof compute_features_selected ({res.get('pgeof_selected_features', 14)})", "pgeof_selected"),
    ]
    print()
    print(f"{res['points']:,} points, r = {RADIUS} m (median {res.get('median_neighbours_r0.5', float('nan')):.0f} neighbours), "
          f"best of {res['repeat']}, {res['threads']} threads")
    head = f"{'measurement':46s} {'seconds':>8s} {'Mpts/s':>7s} {'/jak CLI':>8s} {'/jak in':>8s} {'/pgeof':>8s}"
    print(head)
    print("-" * len(head))
    for label, key in rows:
        t = s.get(key)
        if t is None:
            print(f"{label:46s} {'skipped':>8s}")
            continue
        print(f"{label:46s} {t:8.3f} {n / t / 1e6:7.2f} {fmt_ratio(t, jak_cli):>8s} {fmt_ratio(t, jak_in):>8s} {fmt_ratio(t, pg):>8s}")

    mem = res["peak_rss_mb"]
    io_mb = res["io_arrays_mb"]
    print()
    print(f"input + output arrays: {io_mb['total']:.1f} MB (xyz {io_mb['xyz']:.1f} + {res['cli_feature_count']} float32 features "
          f"{io_mb['features']:.1f} + LAS records {io_mb['las_records']:.1f})")
    if "lidarfx_cli" in mem:
        print(f"lidarfx CLI peak RSS: {mem['lidarfx_cli']:.1f} MB ({res['peak_rss_method']}); "
              f"same command on 1,000 points (fixed cost): {mem['lidarfx_cli_1000_points']:.1f} MB; "
              f"ratio {mem['lidarfx_cli'] / io_mb['total']:.2f}x "
              f"(above the fixed cost: {(mem['lidarfx_cli'] - mem['lidarfx_cli_1000_points']) / io_mb['total']:.2f}x)")
    if "jakteristics_cli" in mem:
        print(f"jakteristics CLI peak RSS: {mem['jakteristics_cli']:.1f} MB")

    def target(name: str, value: float | None, limit: float, op: str, unit: str) -> dict:
        ok = None if value is None else (value <= limit if op == "<=" else value >= limit)
        return {"target": name, "value": value, "limit": limit, "op": op, "unit": unit,
                "status": "n/a" if ok is None else ("PASS" if ok else "FAIL")}

    def ratio(a, b):
        return a / b if a and b else None

    targets = [
        target("CLI eigen,plane,density vs jakteristics CLI", ratio(s.get("lidarfx_cli"), jak_cli), 0.25, "<=", "x"),
        target("eigen in-process throughput", n / s["lidarfx_eigen"] / 1e6 if s.get("lidarfx_eigen") else None, 1.0, ">=", "M pts/s"),
        target("three radii vs one radius (eigen)", ratio(s.get("lidarfx_eigen_3radii"), s.get("lidarfx_eigen")), 1.5, "<=", "x"),
        target("`all` vs jakteristics in-process", ratio(s.get("lidarfx_all"), jak_in), 1.0, "<=", "x"),
        target("CLI peak memory vs input+output arrays", ratio(mem.get("lidarfx_cli"), io_mb["total"]), 2.0, "<=", "x"),
    ]
    print()
    print("targets (issue 3)")
    for t in targets:
        val = "-" if t["value"] is None else f"{t['value']:.2f} {t['unit']}"
        print(f"  {t['status']:4s}  {t['target']:44s} {val:>14s}   (target {t['op']} {t['limit']} {t['unit']})")
    return targets


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    pin_threads(args.threads)
    ensure_lidarfx_importable()

    import numba
    import numpy as np

    import lidarfx
    from lidarfx.features import resolve

    res: dict[str, Any] = {
        "points": args.points,
        "repeat": args.repeat,
        "threads": args.threads,
        "radius": RADIUS,
        "seconds": {},
        "peak_rss_mb": {},
        "commands": {},
        "versions": {"python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__,
                     "lidarfx": lidarfx.__version__},
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform()},
    }
    print(f"numba threads: {numba.get_num_threads()} (NUMBA_NUM_THREADS={os.environ['NUMBA_NUM_THREADS']}); "
          f"jakteristics num_threads: {args.threads}; pgeof: taskflow default = all {os.cpu_count()} hardware threads; "
          f"OPENBLAS/OMP/MKL_NUM_THREADS={args.threads}")

    tmp = None
    workdir = args.workdir
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="lidarfx-bench-")
        workdir = Path(tmp.name)
    workdir.mkdir(parents=True, exist_ok=True)
    try:
        xyz, side = make_terrain(args.points, args.seed)
        las_in = workdir / "terrain.las"
        t0 = time.perf_counter()
        record = write_las(xyz, las_in)
        print(f"terrain: {args.points:,} points, {side:.1f} m x {side:.1f} m, {DENSITY:.0f} pts/m², "
              f"written to {las_in} in {time.perf_counter() - t0:.1f} s ({las_in.stat().st_size / 2**20:.1f} MB)")

        cloud = lidarfx.read(las_in)
        xyz = cloud.xyz  # exactly what every tool reads back from the file
        nfeat = len(resolve(CLI_FEATURES).names)
        res["cli_feature_count"] = nfeat
        res["io_arrays_mb"] = {
            "xyz": xyz.nbytes / 2**20,
            "features": nfeat * len(xyz) * 4 / 2**20,
            "las_records": record * len(xyz) / 2**20,
        }
        res["io_arrays_mb"]["total"] = sum(res["io_arrays_mb"].values())

        print("a. lidarfx in-process")
        bench_lidarfx(cloud, args.repeat, res)
        print("b. jakteristics")
        try:
            bench_jakteristics(np.ascontiguousarray(xyz), las_in, workdir, args.threads, args.repeat, res)
        except ImportError as exc:
            print(f"  skipped: {exc}")
        print("c. pgeof")
        try:
            bench_pgeof(xyz, args.repeat, res)
        except ImportError as exc:
            print(f"  skipped: {exc}")
        print("d./e. lidarfx CLI (whole process) and its peak memory")
        bench_lidarfx_cli(las_in, workdir, args.repeat, res)

        res["targets"] = report(res)
    finally:
        if tmp is not None:
            tmp.cleanup()
    if args.json:
        args.json.write_text(json.dumps(res, indent=2))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
