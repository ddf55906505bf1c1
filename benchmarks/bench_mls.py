#!/usr/bin/env python
"""Mobile-mapping benchmark: lidarfx's default classifier against the usual open pipeline on
synthetic MLS streets (issue 31, item 3).  Run by hand (not collected by pytest)::

    python benchmarks/bench_mls.py                        # train on seed 1, test on seed 3 (~12 min)
    python benchmarks/bench_mls.py --validation           # test on seed 2 instead (the tuning scene)
    python benchmarks/bench_mls.py --json mls.json        # also save every number
    python benchmarks/bench_mls.py --skip-peer            # lidarfx only
    python benchmarks/bench_mls.py --also-rf              # + lidarfx with --classifier rf (an option)

Scenes: ``lidarfx.synth.street(length=80, density=300, seed=…)`` — road and sidewalks, facades on
both sides, lamp posts, utility poles and sign posts, overhead wires along and across the street,
street trees, parked cars; MLS sampling (dense near the driving line, 1/r beyond 5 m, no return
numbers).  The training scene (seed 1), the validation scene (seed 2, the only one any choice was
made on) and the test scene (seed 3) differ in everything the seed draws: building widths and
heights, alleys, pole, tree and car positions, wire sags.  Classes: ground 2, vegetation 5, building 6,
wire 14, pole 64, car 65 (noise 7 is ignored by both pipelines and in the metrics).

Pipelines, each timed as a whole (features of the training and test points, fit, predict every
test point):

* **lidarfx default** — ``lidarfx.classify.train(scene, classes=…)`` with nothing else, i.e. what
  ``lidarfx classify train scene.laz model.skops`` does: the default feature list without the return
  inputs (the scene has none, so the defaults leave them out), radii from the measured point
  spacing, capped height above ground from the SMRF filter, 20 000 training points per class + 10 000
  from a terrain-sheared copy, gradient boosting; then ``model.predict`` (with the small-building rule).
* **peer** — the usual open pipeline: jakteristics ``compute_features`` at 0.5, 1 and 2 m with all
  its 27 features, plus z above the scene's lowest point, NaN → 0, scikit-learn
  ``RandomForestClassifier(n_estimators=100, class_weight="balanced", n_jobs=-1)`` fitted on every
  labelled point of the training scene.

Prints OA, mean F1, per-class PA / UA / F1 of both (wire and pole marked), the seconds of each step,
the time ratio lidarfx / peer and the machine load before and after each pipeline.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
CLASSES = "ground=2,vegetation=5,building=6,wire=14,pole=64,car=65"
PEER_RADII = (0.5, 1.0, 2.0)
THIN = ("wire", "pole")
TRAIN_SEED, VALIDATION_SEED, TEST_SEED = 1, 2, 3


def ensure_lidarfx_importable() -> None:
    import importlib.util

    if importlib.util.find_spec("lidarfx") is None:
        sys.path.insert(0, str(REPO / "src"))


def load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:  # pragma: no cover
        return float("nan")


def scene(seed: int, length: float, density: float):
    import lidarfx

    cloud = lidarfx.synth.street(seed=seed, length=length, density=density)
    cloud.meta["name"] = f"street seed {seed}"
    return cloud


# --------------------------------------------------------------------------- peer
def peer(train, test, cmap, seed: int, log) -> dict[str, Any]:
    """jakteristics 0.5 / 1 / 2 m (all features) + z, balanced random forest on every training point."""
    import jakteristics
    import numpy as np
    from sklearn.ensemble import RandomForestClassifier

    from lidarfx.classify.evaluate import confusion_matrix

    names = list(jakteristics.FEATURE_NAMES)
    sec = {"features": 0.0}

    def features(cloud):
        xyz = np.ascontiguousarray(cloud.xyz - cloud.xyz.min(axis=0))
        cols = [jakteristics.compute_features(xyz, r, feature_names=names) for r in PEER_RADII]
        cols.append(xyz[:, 2:3])  # z above the scene's lowest point
        return np.nan_to_num(np.hstack(cols).astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)

    t = time.perf_counter()
    X = features(train)
    y = cmap.index_of(train["classification"])
    keep = y >= 0
    X, y = X[keep], y[keep]
    Xt = features(test)
    sec["features"] = time.perf_counter() - t
    log(f"  peer features: {len(train):,} + {len(test):,} points, {X.shape[1]} columns, {sec['features']:.1f} s")
    t = time.perf_counter()
    rf = RandomForestClassifier(n_estimators=100, class_weight="balanced", n_jobs=-1, random_state=seed).fit(X, y)
    sec["fit"] = time.perf_counter() - t
    log(f"  peer fit on {len(y):,} points: {sec['fit']:.1f} s")
    t = time.perf_counter()
    pred = rf.predict(Xt)
    sec["predict"] = time.perf_counter() - t
    ref = cmap.index_of(test["classification"])
    sec["total"] = sec["features"] + sec["fit"] + sec["predict"]
    return {"confusion": confusion_matrix(ref, np.where(ref >= 0, pred, 0), len(cmap)), "seconds": sec,
            "features": int(X.shape[1]), "train_points": int(len(y))}


# --------------------------------------------------------------------------- lidarfx
def lidarfx_default(train, test, cmap, log, **options) -> dict[str, Any]:
    """``lidarfx.classify.train`` with its defaults (``options``: e.g. ``classifier="rf"``), then predict."""
    import numpy as np

    from lidarfx.classify import train as fit
    from lidarfx.classify.evaluate import confusion_matrix

    sec = {}
    t = time.perf_counter()
    model = fit(train, classes=cmap, log=lambda m: log("  lidarfx " + m), **options)
    sec["train"] = time.perf_counter() - t
    t = time.perf_counter()
    rule: dict[str, Any] = {}
    codes = model.predict(test, stats=rule)
    sec["predict"] = time.perf_counter() - t
    sec["total"] = sec["train"] + sec["predict"]
    ref = cmap.index_of(test["classification"])
    pred = cmap.index_of(codes)
    return {"confusion": confusion_matrix(ref, np.where(ref >= 0, pred, 0), len(cmap)), "seconds": sec,
            "features": len(model.feature_names), "radii": model.radii,
            "feature_list": model.meta["config"]["features"], "defaults": model.meta["training"]["defaults"],
            "train_points": int(sum(model.meta["training"]["counts"]["used"].values())),
            "building_rule": rule or None}


# --------------------------------------------------------------------------- report
def summarise(res: dict[str, Any], cmap) -> dict[str, Any]:
    from lidarfx.classify.evaluate import metrics

    m = metrics(res["confusion"], list(cmap.names))
    return {"oa": m["oa"], "mean_f1": m["mean_f1"], "kappa": m["kappa"],
            "classes": {c["name"]: {k: c[k] for k in ("support", "pa", "ua", "f1", "iou")} for c in m["classes"]}}


def table(results: dict[str, dict[str, Any]], cmap) -> str:
    names = list(results)
    lines = ["| class | support | " + " | ".join(f"{n} F1 (PA / UA)" for n in names) + " |",
             "|---|---|" + "---|" * len(names)]
    for c in cmap.names:
        row = [f"**{c}**" if c in THIN else c, f"{results[names[0]]['summary']['classes'][c]['support']:,}"]
        for n in names:
            k = results[n]["summary"]["classes"][c]
            row.append(f"{k['f1']:.3f} ({k['pa']:.3f} / {k['ua']:.3f})")
        lines.append("| " + " | ".join(row) + " |")
    lines.append("| OA / mean F1 | | " + " | ".join(
        f"{results[n]['summary']['oa']:.4f} / {results[n]['summary']['mean_f1']:.4f}" for n in names) + " |")
    lines.append("| seconds | | " + " | ".join(f"{results[n]['seconds']['total']:.1f}" for n in names) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ensure_lidarfx_importable()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--length", type=float, default=80.0, help="street length (m), default %(default)s")
    ap.add_argument("--density", type=float, default=300.0, help="points/m² within 5 m of the driving line, "
                                                                  "default %(default)s")
    ap.add_argument("--train-seed", type=int, default=TRAIN_SEED)
    ap.add_argument("--test-seed", type=int, default=TEST_SEED)
    ap.add_argument("--validation", action="store_true",
                    help=f"test on the validation scene (seed {VALIDATION_SEED}) instead of the test scene")
    ap.add_argument("--skip-peer", action="store_true", help="lidarfx only")
    ap.add_argument("--also-rf", action="store_true",
                    help="also lidarfx with --classifier rf (its features, a random forest; an option, not the default)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the peer's random forest")
    ap.add_argument("--json", default=None, help="write every number to this JSON file")
    args = ap.parse_args(argv)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    from lidarfx.classify import ClassMap

    cmap = ClassMap.parse(CLASSES)
    test_seed = VALIDATION_SEED if args.validation else args.test_seed
    t = time.perf_counter()
    train, test = scene(args.train_seed, args.length, args.density), scene(test_seed, args.length, args.density)
    log(f"scenes: train seed {args.train_seed} {len(train):,} points, test seed {test_seed} {len(test):,} points "
        f"({time.perf_counter() - t:.1f} s)")
    results: dict[str, dict[str, Any]] = {}
    load0 = load()
    log(f"lidarfx default (load {load0:.2f})")
    res = lidarfx_default(train, test, cmap, log)
    res["load"] = [load0, load()]
    results["lidarfx default"] = res
    if args.also_rf:
        load0 = load()
        log(f"lidarfx --classifier rf (load {load0:.2f})")
        res = lidarfx_default(train, test, cmap, log, classifier="rf")
        res["load"] = [load0, load()]
        results["lidarfx rf"] = res
    if not args.skip_peer:
        load0 = load()
        log(f"peer: jakteristics {'/'.join(f'{r:g}' for r in PEER_RADII)} m + z + balanced RF (load {load0:.2f})")
        res = peer(train, test, cmap, args.seed, log)
        res["load"] = [load0, load()]
        results["peer"] = res
    for r in results.values():
        r["summary"] = summarise(r, cmap)
    print(f"\nMLS street, train seed {args.train_seed}, {'validation' if args.validation else 'test'} seed {test_seed} "
          f"(length {args.length:g} m, density {args.density:g}); per class F1 (PA / UA), wire and pole in bold\n")
    print(table(results, cmap))
    lx = results["lidarfx default"]
    print(f"\nlidarfx: {lx['features']} features at radii {', '.join(f'{r:g}' for r in lx['radii'])} m "
          f"({lx['train_points']:,} training points); train {lx['seconds']['train']:.1f} s, predict "
          f"{lx['seconds']['predict']:.1f} s; load {lx['load'][0]:.2f} -> {lx['load'][1]:.2f}")
    if "lidarfx rf" in results:
        rf = results["lidarfx rf"]
        print(f"lidarfx --classifier rf: train {rf['seconds']['train']:.1f} s, predict {rf['seconds']['predict']:.1f} s; "
              f"load {rf['load'][0]:.2f} -> {rf['load'][1]:.2f}")
    if "peer" in results:
        pr = results["peer"]
        print(f"peer: {pr['features']} features ({pr['train_points']:,} training points); features "
              f"{pr['seconds']['features']:.1f} s, fit {pr['seconds']['fit']:.1f} s, predict {pr['seconds']['predict']:.1f} s; "
              f"load {pr['load'][0]:.2f} -> {pr['load'][1]:.2f}")
        print(f"time ratio lidarfx / peer: {lx['seconds']['total'] / pr['seconds']['total']:.3f}")
        for c in THIN:
            a, b = lx["summary"]["classes"][c]["f1"], pr["summary"]["classes"][c]["f1"]
            print(f"{c}: lidarfx default F1 {a:.4f}, peer {b:.4f} -> {'lidarfx' if a > b else 'peer'} ahead by "
                  f"{abs(a - b):.4f}")
    if args.json:
        out = {"machine": platform.platform(), "cpus": os.cpu_count(), "args": vars(args), "test_seed": test_seed,
               "results": {k: {kk: vv for kk, vv in v.items()} for k, v in results.items()}}
        Path(args.json).write_text(json.dumps(out, indent=2, default=lambda o: getattr(o, "tolist", lambda: str(o))()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
