#!/usr/bin/env python
"""Compile lidarfx's kernels ahead of time into ``src/lidarfx/data/kernels.zip``.

Run by hand from the repository after changing a kernel module (or a module a kernel module
imports) — ``tests/test_prebuilt.py`` fails until the bundle matches the sources again::

    python tools/build_kernels.py            # about 3-4 minutes on 2 cores

It runs a workload (the demo and the commands below) in a fresh process with an empty
``NUMBA_CACHE_DIR`` and ``NUMBA_CPU_NAME=x86-64-v3``, then packs numba's cache files with a
manifest (numba and Python versions, platform, processor model, the SHA-256 of the sources the
kernels were compiled from).  ``lidarfx._prebuilt`` installs them on import when all of it
matches the user's machine.
"""
from __future__ import annotations

import argparse
import ast
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOT = REPO / "src" / "lidarfx"
sys.path.insert(0, str(REPO / "src"))

WORKLOAD = r'''
import numpy as np
import lidarfx
from lidarfx import synth, io
from lidarfx.features import compute_features
from lidarfx.neighbors import NeighborIndex
from lidarfx.cli import main

out = __import__("pathlib").Path(OUT)
rng = np.random.default_rng(0)
# features: every family, sphere / cylinder / kNN, one and several radii, a query subset
xyz = rng.uniform(0, 20, (20000, 3))
pc = lidarfx.PointCloud(xyz)
for kw in (dict(radius=1.0), dict(radii=[0.5, 1.0]), dict(neighbourhood="cylinder", radius=1.0),
           dict(neighbourhood="knn", k=20)):
    compute_features(pc, "all", progress=False, **kw)
compute_features(pc, "eigen", radius=1.0, query=np.arange(100), progress=False)
NeighborIndex(xyz, 1.0).query_radius(xyz[:10], 1.0)
# the commands a first hour uses, through the CLI as a user runs them
files = []
for name, cloud in (("terrain", synth.terrain(size=60.0)), ("house", synth.house())):
    p = out / f"{name}.laz"
    io.write(cloud, p)
    files.append(p)
for p in files:
    for argv in (["ground", str(p), str(out / "g.laz"), "-q"],
                 ["dtm", str(out / "g.laz"), str(out / "d.tif"), "-q"],
                 ["segment", str(p), str(out / "s.laz"), "-q"],
                 ["eigenclass", str(p), str(out / "e.laz"), "-q"],
                 ["thin", str(p), str(out / "t.laz"), "--cell", "0.5", "-q"],
                 ["render", str(p), str(out / "r.png"), "--by", "z", "-q"],
                 ["render", str(p), str(out / "r2.png"), "--shading", "hillshade", "--view", "front", "-q"],
                 ["convert", str(p), str(out / "a.ply"), "--ascii"],
                 ["convert", str(out / "a.ply"), str(out / "b.laz")],
                 ["features", str(p), str(out / "f.laz"), "-r", "1", "--features", "eigen,plane", "-q"]):
        try:
            main(["--force", *argv])  # the same outputs for both files
        except SystemExit:
            pass
'''


def kernel_sources(root: Path = ROOT) -> list[str]:
    """The kernel modules (those that use numba) and every package module they import, transitively
    (module level), as sorted package-relative paths: the sources compiled code can depend on."""
    mods = {p.relative_to(root): p for p in root.rglob("*.py")}

    def targets(rel: Path, node) -> set[Path]:
        pkg = list(rel.parent.parts)
        if isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if not (node.module or "").startswith("lidarfx"):
                    return set()
                base = node.module.split(".")[1:]
            else:
                base = pkg[: len(pkg) - (node.level - 1)] + (node.module.split(".") if node.module else [])
            cands = [base] + [base + [a.name] for a in node.names]
        else:
            cands = [a.name.split(".")[1:] for a in node.names if a.name.startswith("lidarfx")]
        out = set()
        for c in cands:
            for f in ((Path(*c).with_suffix(".py"),) if c else ()) + (Path(*c, "__init__.py"),):
                if f in mods:
                    out.add(f)
        return out

    deps = {}
    for rel, p in mods.items():
        tree = ast.parse(p.read_text())
        deps[rel] = set().union(*[targets(rel, n) for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))])
    kernels = {rel for rel, p in mods.items() if re.search(r"\b(nb|numba)\.(njit|jit)\b", p.read_text())}
    seen, stack = set(kernels), list(kernels)
    while stack:
        for d in deps[stack.pop()]:
            if d not in seen:
                seen.add(d)
                stack.append(d)
    return sorted(str(p.as_posix()) for p in seen)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "data" / "kernels.zip", help="the bundle to write")
    args = ap.parse_args(argv)
    import llvmlite.binding as ll
    import numba
    from numba.core.caching import _CacheLocator

    from lidarfx import _prebuilt

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), NUMBA_CPU_NAME=_prebuilt.CPU_NAME, NUMBA_CPU_FEATURES="",
                   LIDARFX_PREBUILT="0", LIDARFX_COMPILE_NOTICE="0", PYTHONPATH=str(REPO / "src"))
        (Path(tmp) / "demo").mkdir()
        subprocess.run([sys.executable, "-m", "lidarfx", "demo", "--out", str(Path(tmp) / "demo"), "-q"],
                       env=env, check=True, cwd=tmp)
        (Path(tmp) / "w").mkdir()
        subprocess.run([sys.executable, "-c", f"OUT = {str(Path(tmp) / 'w')!r}\n" + WORKLOAD],
                       env=env, check=True, cwd=tmp)
        # numba's cache folder of each package folder -> the folder, to name the modules
        folders = {_CacheLocator.get_suitable_cache_subpath(str(p)): p.parent.relative_to(ROOT)
                   for p in ROOT.rglob("*.py")}
        entries: dict[str, list[str]] = {}
        payload: list[tuple[str, Path]] = []
        for f in sorted(cache.rglob("*.nb[ic]")):
            folder = folders.get(f.parent.name)
            if folder is None:
                continue
            module = (folder / (f.name.split(".")[0] + ".py")).as_posix()
            if not (ROOT / module).exists():
                continue
            entries.setdefault(module, []).append(f.name)
            payload.append((f"{module}/{f.name}", f))
        sources = kernel_sources()
        manifest = {
            "format": 1,
            "numba": numba.__version__,
            "python": _prebuilt.python_tag(),
            "triple": ll.get_process_triple(),
            "cpu_name": _prebuilt.CPU_NAME,
            "cpu_features": "",
            "cpu_needs": list(_prebuilt.CPU_NEEDS),
            "sources": sources,
            "digest": _prebuilt.sources_digest(sources),
            "built": datetime.date.today().isoformat(),
            "files": entries,
        }
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp_out = args.out.with_name(args.out.name + ".tmp")
        with zipfile.ZipFile(tmp_out, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("manifest.json", json.dumps(manifest, indent=1))
            for name, f in payload:
                zf.write(f, name)
        tmp_out.replace(args.out)
    n = sum(len(v) for v in entries.values())
    print(f"{args.out}: {n} files of {len(entries)} modules, {args.out.stat().st_size / 1e6:.1f} MB, "
          f"built in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
