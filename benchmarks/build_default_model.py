#!/usr/bin/env python
"""Build the model shipped with lidarfx (``--model default``), reproducibly; its card is
docs/default-model.md.  Run by hand::

    python benchmarks/build_default_model.py                  # train, write src/lidarfx/data/models/default.skops
    python benchmarks/build_default_model.py --out m.skops    # somewhere else
    python benchmarks/build_default_model.py --check          # rebuild into a temporary file and compare with the shipped one

What it does is exactly ``lidarfx classify train`` with the default pipeline and nothing but the
class map::

    lidarfx classify train test_data_77050_627755_LA93_IGN69.laz test_data_77055_627755_LA93_IGN69.laz \\
        test_data_77060_627755_LA93_IGN69.laz --model default.skops --classes ground=2,vegetation=3+4+5,building=6

plus three entries in the model's metadata that the CLI cannot set: the training files by their
names (not this machine's paths), ``name``, ``card`` and ``licence`` (``classify info default --json``).
The fit is seeded (seed 0) and does not depend on the thread count, so a rebuild predicts exactly
what the shipped model predicts (``--check`` compares the class probabilities of every point of
the three tiles); only ``created`` and the timings differ.

The data: three contiguous 50 m × 50 m IGN LiDAR HD tiles (Lambert-93, ~30 pts/m²) from
``IGNF/ign-pdal-tools`` (MIT), data © IGN, Licence Ouverte / Etalab 2.0; found in
``$LIDARFX_REAL_DATA`` or ``../shared/data/real`` (SOURCES.md there).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("LIDARFX_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
TILES = [f"test_data_{t}_627755_LA93_IGN69.laz" for t in ("77050", "77055", "77060")]
CLASSES = "ground=2,vegetation=3+4+5,building=6"
OUT = REPO / "src" / "lidarfx" / "data" / "models" / "default.skops"
META = {
    "name": "lidarfx default model: ground / vegetation / building for ALS (IGN LiDAR HD)",
    "card": "docs/default-model.md",
    "licence": "model: MIT (lidarfx); training data: IGN LiDAR HD tiles 77050/77055/77060_627755 "
               "(IGNF/ign-pdal-tools test data, repository MIT), data published by IGN under the "
               "Licence Ouverte / Etalab 2.0",
}


def ensure_lidarfx_importable() -> None:
    import importlib.util

    if importlib.util.find_spec("lidarfx") is None:
        sys.path.insert(0, str(REPO / "src"))


def build(out: Path, log) -> "object":
    import lidarfx
    from lidarfx.classify import train

    missing = [t for t in TILES if not (DATA / t).is_file()]
    if missing:
        raise SystemExit(f"training tiles not found in {DATA}: {', '.join(missing)} (set LIDARFX_REAL_DATA)")
    clouds = []
    for t in TILES:
        c = lidarfx.read(DATA / t)
        c.meta["name"] = t  # the file name, not this machine's path
        clouds.append(c)
    model = train(clouds, classes=CLASSES, seed=0, log=log)
    model.meta = {**model.meta, **META}
    model.save(out)
    log(f"model -> {out} ({out.stat().st_size / 1e6:.2f} MB)")
    return model


def check(log) -> int:
    """Rebuild into a temporary file and compare its probabilities with the shipped model's."""
    import numpy as np

    import lidarfx
    from lidarfx.classify import load_model

    shipped = load_model(OUT)
    with tempfile.TemporaryDirectory() as d:
        fresh = build(Path(d) / "default.skops", log)
        worst = 0.0
        for t in TILES:
            c = lidarfx.read(DATA / t)
            p0, _ = shipped.predict_proba(c)
            p1, _ = fresh.predict_proba(c)
            worst = max(worst, float(np.abs(p0 - p1).max()))
            log(f"{t}: largest probability difference {np.abs(p0 - p1).max():.2e}")
    same = shipped.meta["config"] == fresh.meta["config"] and shipped.feature_names == fresh.feature_names
    print(f"rebuild {'reproduces' if same and worst < 1e-9 else 'DIFFERS FROM'} the shipped model "
          f"(configuration {'equal' if same else 'different'}, largest probability difference {worst:.2e})")
    return 0 if same and worst < 1e-9 else 1


def main(argv: list[str] | None = None) -> int:
    ensure_lidarfx_importable()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=OUT, help="model file to write (default: the package's)")
    ap.add_argument("--check", action="store_true", help="rebuild into a temporary file and compare")
    args = ap.parse_args(argv)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    if args.check:
        rc = check(log)
    else:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        build(args.out, log)
        rc = 0
    log(f"{time.perf_counter() - t0:.1f} s")
    return rc


if __name__ == "__main__":
    sys.exit(main())
