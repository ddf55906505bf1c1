#!/usr/bin/env python
"""Classification benchmark: the usual open pipeline against lidarfx's default, same split.

Run by hand (not collected by pytest)::

    python benchmarks/bench_classify.py                       # both pipelines, IGN tiles (~10 min)
    python benchmarks/bench_classify.py --json bench.json     # also save every number
    python benchmarks/bench_classify.py --skip-baseline       # lidarfx only (~1–2 min)
    python benchmarks/bench_classify.py --facade              # Lang's facade experiment on the synthetic facade
    python benchmarks/bench_classify.py --loto                # both pipelines, leave one training tile out

The split (issue 5 acceptance): train on the three contiguous IGN LiDAR HD tiles
``test_data_77050/77055/77060_627755_LA93_IGN69.laz``; test on ``crop_1.laz`` and
``pont.laz`` (same survey programme, other places, never used for training or for
choosing the default).  Classes: ground 2, vegetation 3+4+5, building 6; every
other class (1, 64, 65, 9, 17, 66, 67) is ignored in training and in the metrics.
Virtual points (return number 0, IGN class 66) are dropped from both pipelines
before anything else: they are synthetic and have no returns.

Pipelines, each timed as a whole (read files, features of training and test
points, fit, predict every usable test point):

* **baseline** — the usual open pipeline: jakteristics' 27 features at radii 1, 2
  and 3 m for every point (its defaults: all cores), plus z above the file's lowest
  point, NaN → 0, scikit-learn ``RandomForestClassifier(n_estimators=100,
  class_weight="balanced", n_jobs=-1)`` on every labelled training point.  z above
  the file minimum is meaningless on hilly test files, so the same pipeline
  **without z** is scored too (same features, its own forest; its time is the
  shared read + features time plus its own fit and predict).
* **lidarfx** — ``lidarfx.classify.train`` with its defaults (HistGradientBoosting,
  the default feature list at 1, 2, 3 m + capped height above ground from the
  SMRF filter, 20 000 training points per class + 10 000 from a terrain-sheared
  copy, neighbour clouds thinned to ≈ 40 pts/m²) and ``model.predict``.

Prints OA, mean F1, per-class PA / UA / F1 / IoU (confusion matrix rows =
reference, columns = predicted), seconds of each step, the time ratio and the
acceptance check (OA ≥ 0.965, mean F1 ≥ 0.95, lidarfx time ≤ 1/3 of the baseline).
The machine load (1-minute load average) is printed before and after each pipeline:
the timings are wall-clock and other processes on the same cores change them.

``--loto`` scores both pipelines on the training tiles only: each of the three tiles
is predicted by a model trained on the other two, and the confusion matrices are
pooled. This is the split closest to "tiles of the same survey" that the training data
allows, and it reads no test file.
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
DATA = Path(os.environ.get("LIDARFX_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
TRAIN = [f"test_data_{t}_627755_LA93_IGN69.laz" for t in ("77050", "77055", "77060")]
TEST = ["crop_1.laz", "pont.laz"]
CLASSES = "ground=2,vegetation=3+4+5,building=6"
BASE_RADII = (1.0, 2.0, 3.0)
TARGET_OA, TARGET_F1, TARGET_RATIO = 0.965, 0.95, 1.0 / 3.0


def ensure_lidarfx_importable() -> None:
    import importlib.util

    if importlib.util.find_spec("lidarfx") is None:
        sys.path.insert(0, str(REPO / "src"))


def load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:  # pragma: no cover
        return float("nan")


def read_usable(path: Path):
    """Read a file and drop virtual / withheld / synthetic points (same rule for both pipelines)."""
    import lidarfx
    from lidarfx.classify import usable_mask

    cloud = lidarfx.read(path)
    mask = usable_mask(cloud)
    return cloud if mask.all() else cloud.subset(mask)


# --------------------------------------------------------------------------- baseline
def baseline(train_paths, test_paths, cmap, seed: int, log) -> dict[str, dict[str, Any]]:
    """The usual pipeline, with z (as specified) and without z; features computed once."""
    import jakteristics
    import numpy as np
    from sklearn.ensemble import RandomForestClassifier

    from lidarfx.classify.evaluate import confusion_matrix

    names = list(jakteristics.FEATURE_NAMES)
    shared = {"read": 0.0, "features": 0.0}

    def features(cloud):
        xyz = np.ascontiguousarray(cloud.xyz - cloud.xyz.min(axis=0))
        cols = [jakteristics.compute_features(xyz, r, feature_names=names) for r in BASE_RADII]
        cols.append(xyz[:, 2:3])  # z above the file's lowest point (the last column)
        return np.nan_to_num(np.hstack(cols).astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)

    Xs, ys = [], []
    for p in train_paths:
        t = time.perf_counter()
        c = read_usable(p)
        shared["read"] += time.perf_counter() - t
        t = time.perf_counter()
        y = cmap.index_of(c["classification"])
        keep = y >= 0
        Xs.append(features(c)[keep])
        ys.append(y[keep])
        shared["features"] += time.perf_counter() - t
        log(f"  baseline features {p.name}: {len(c):,} points")
    tests = []
    for p in test_paths:
        t = time.perf_counter()
        c = read_usable(p)
        shared["read"] += time.perf_counter() - t
        t = time.perf_counter()
        tests.append((p.name, features(c), cmap.index_of(c["classification"])))
        shared["features"] += time.perf_counter() - t
        log(f"  baseline features {p.name}: {len(c):,} points")
    X, y = np.vstack(Xs), np.concatenate(ys)
    k = len(cmap)
    out = {}
    for label, cols in (("with z", slice(None)), ("without z", slice(0, -1))):
        sec = dict(shared)
        t = time.perf_counter()
        rf = RandomForestClassifier(n_estimators=100, class_weight="balanced", n_jobs=-1,
                                    random_state=seed).fit(X[:, cols], y)
        sec["fit"] = time.perf_counter() - t
        log(f"  baseline ({label}) fit on {len(y):,} points: {sec['fit']:.1f} s")
        cms = {}
        sec["predict"] = 0.0
        for name, F, ref in tests:
            t = time.perf_counter()
            pred = rf.predict(F[:, cols])
            sec["predict"] += time.perf_counter() - t
            cms[name] = confusion_matrix(ref, np.where(ref >= 0, pred, 0), k)
        sec["total"] = sec["read"] + sec["features"] + sec["fit"] + sec["predict"]
        out[label] = {"confusion": cms, "seconds": sec, "features": X[:, cols].shape[1], "train_points": int(len(y))}
    return out


# --------------------------------------------------------------------------- lidarfx
def lidarfx_default(train_paths, test_paths, cmap, seed: int, log, classifier: str = "hgb") -> dict[str, Any]:
    import numpy as np

    from lidarfx.classify import train
    from lidarfx.classify.evaluate import confusion_matrix

    sec = {"read": 0.0, "train": 0.0, "predict": 0.0}
    t_all = time.perf_counter()
    t = time.perf_counter()
    clouds = [read_usable(p) for p in train_paths]
    sec["read"] += time.perf_counter() - t
    t = time.perf_counter()
    model = train(clouds, classes=cmap, classifier=classifier, seed=seed, log=lambda m: log("  lidarfx " + m))
    sec["train"] = time.perf_counter() - t
    k = len(cmap)
    cms, rules = {}, {}
    for p in test_paths:
        t = time.perf_counter()
        c = read_usable(p)
        sec["read"] += time.perf_counter() - t
        t = time.perf_counter()
        rule: dict[str, int] = {}
        codes = model.predict(c, stats=rule)
        sec["predict"] += time.perf_counter() - t
        ref = cmap.index_of(c["classification"])
        pred = cmap.index_of(codes)
        cms[p.name] = confusion_matrix(ref, np.where(ref >= 0, pred, 0), k)
        rules[p.name] = rule or None
        log(f"  lidarfx predicted {p.name}: {len(c):,} points"
            + (f"; building clusters {rule['components']:,}, small ones relabelled {rule['relabelled_components']:,} "
               f"({rule['relabelled_points']:,} points), see-through ones {rule['see_through_components']:,} "
               f"({rule['see_through_points']:,} points)" if rule else ""))
    sec["total"] = time.perf_counter() - t_all
    return {"confusion": cms, "building_rule": rules, "seconds": sec, "features": len(model.feature_names),
            "train_points": int(sum(model.meta["training"]["counts"]["used"].values())),
            "training_seconds": model.meta["training"]["seconds"]}


# --------------------------------------------------------------------------- Lang's facade experiment
FACADE_CLASSES = "ground=2,vegetation=5,wall=6,roof=64,window=65,clutter=66"  # Lang's six; noise 7 ignored
CHEHATA = "eigen,plane,msac,height"  # Chehata et al. 2009 (airborne): eigenvalues, local (robust) plane, heights
LANG_TLS = "histogram,distribution"  # Lang's TLS features: height-difference histogram, spatial distribution


def facade_experiment(seed: int, max_per_class: int, log) -> list[dict[str, Any]]:
    """RF vs NB, Chehata features with / without Lang's TLS features, r = 0.5 m vs 0.1/0.3/0.5 m.

    Three facade scenes (seeds 1, 2, 3; ~90 000 points each, like Lang's three scenes of
    ~70 000).  Per configuration: 3-fold CV with random folds (Lang's M-fold
    cross-validation), 3-fold CV with spatial blocks of 4 m (buffered: twice the largest
    radius, the default of ``evaluate``), scene transfer
    (train on scene 1, test on scenes 2 and 3: same house, new sampling, vegetation
    and clutter) and transfer to a taller house (train on scene 1, test on a
    three-storey house with 10 m walls — Lang's §3.2 situation: wall points above
    the training walls' 7 m).  Normals are oriented towards the scanner; no
    thinning, no terrain augmentation (TLS).
    """
    import lidarfx
    from lidarfx.classify import evaluate, evaluate_model, train

    scenes = [lidarfx.synth.facade(seed=s) for s in (1, 2, 3)]
    tall = lidarfx.synth.facade(seed=4, wall_height=10.0, n_floors=3)
    scanner = scenes[0].meta["truth"]["scanner"]
    rows = []
    for feats_label, feats in (("Chehata", CHEHATA), ("Chehata + TLS", CHEHATA + "," + LANG_TLS)):
        for radii_label, radii in (("0.5", [0.5]), ("0.1/0.3/0.5", [0.1, 0.3, 0.5])):
            for clf in ("nb", "rf"):
                params = dict(classes=FACADE_CLASSES, features=feats, radii=radii, classifier=clf, scanner=scanner,
                              max_disc_points=None, terrain_augment=0, max_per_class=max_per_class, seed=seed)
                t0 = time.perf_counter()
                rep = evaluate(scenes, cv=3, block_size=4.0, **params)
                model = train(scenes[0], **params)
                tr = evaluate_model(model, scenes[1:])
                tt = evaluate_model(model, [tall])
                row = {"features": feats_label, "radii": radii_label, "classifier": clf,
                       "n_features": len(rep["features"]),
                       "random": rep["sections"]["cv_random"]["metrics"],
                       "blocks": rep["sections"]["cv_blocks"]["metrics"],
                       "transfer": tr["metrics"], "tall": tt["metrics"], "seconds": time.perf_counter() - t0}
                rows.append(row)
                log(f"  facade {feats_label} r={radii_label} {clf}: random OA {row['random']['oa']:.3f}, "
                    f"blocks OA {row['blocks']['oa']:.3f}, transfer OA {row['transfer']['oa']:.3f}, "
                    f"taller house OA {row['tall']['oa']:.3f} "
                    f"({row['seconds']:.0f} s)")
    return rows


def facade_table(rows: list[dict[str, Any]]) -> str:
    def cls(m, name, key):
        return next(c[key] for c in m["classes"] if c["name"] == name)

    head = ("| features | radii (m) | classifier | n | random 3-fold OA | mean F1 | window PA | window UA "
            "| 4 m blocks OA | mean F1 | scene 1 → 2, 3 OA | mean F1 | scene 1 → taller house OA | mean F1 "
            "| wall PA there |")
    out = [head, "|" + "---|" * 15]
    for r in rows:
        ra, bl, tr, tt = r["random"], r["blocks"], r["transfer"], r["tall"]
        out.append(f"| {r['features']} | {r['radii']} | {r['classifier'].upper()} | {r['n_features']} | "
                   f"{ra['oa']:.3f} | {ra['mean_f1']:.3f} | {cls(ra, 'window', 'pa'):.3f} | "
                   f"{cls(ra, 'window', 'ua'):.3f} | {bl['oa']:.3f} | {bl['mean_f1']:.3f} | "
                   f"{tr['oa']:.3f} | {tr['mean_f1']:.3f} | {tt['oa']:.3f} | {tt['mean_f1']:.3f} | "
                   f"{cls(tt, 'wall', 'pa'):.3f} |")
    return "\n".join(out)


# --------------------------------------------------------------------------- report
def summarise(name: str, res: dict[str, Any], cmap) -> dict[str, Any]:
    import numpy as np

    from lidarfx.classify.evaluate import _metrics_for, format_metrics

    pooled = sum(res["confusion"].values())
    res["metrics"] = _metrics_for(np.asarray(pooled), cmap)
    res["per_file"] = {f: _metrics_for(cm, cmap) for f, cm in res["confusion"].items()}
    print(f"\n=== {name}: {res['features']} features, {res['train_points']:,} training points ===")
    for f, m in res["per_file"].items():
        print(f"  {f}: OA {m['oa']:.4f}, mean F1 {m['mean_f1']:.4f} ({m['points']:,} points)")
    print(format_metrics(res["metrics"], "  all test points pooled:"))
    print("  seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in res["seconds"].items()))
    res["confusion"] = {f: cm.tolist() for f, cm in res["confusion"].items()}
    return res


def baseline_name(variant: str) -> str:
    """Report name of a baseline variant ("with z" / "without z")."""
    return ("baseline: jakteristics 1/2/3 m + z + balanced RF" if variant == "with z"
            else "baseline: jakteristics 1/2/3 m + balanced RF (no z)")


def leave_one_tile_out(train_paths, cmap, args, log) -> int:
    """Both pipelines, each training tile predicted by a model of the other two; pooled."""
    pooled: dict[str, dict[str, Any]] = {}
    for held in train_paths:
        rest = [q for q in train_paths if q != held]
        log(f"held out: {held.name}")
        runs = {"lidarfx default (hgb)": lidarfx_default(rest, [held], cmap, args.seed, log)}
        if not args.skip_baseline:
            for k, v in baseline(rest, [held], cmap, args.seed, log).items():
                runs[baseline_name(k)] = v
        for name, r in runs.items():
            acc = pooled.setdefault(name, {"confusion": {}, "seconds": {}, "features": r["features"],
                                           "train_points": 0})
            acc["confusion"].update(r["confusion"])
            acc["train_points"] += r["train_points"]
            for k2, v2 in r["seconds"].items():
                acc["seconds"][k2] = acc["seconds"].get(k2, 0.0) + v2
    results = {name: summarise(name + " (leave one tile out)", r, cmap) for name, r in pooled.items()}
    print("\n=== summary: leave one tile out (training tiles only; seconds summed over the 3 folds) ===")
    print(f"{'pipeline':<52} {'OA':>7} {'mean F1':>8} {'seconds':>8}")
    for name, r in results.items():
        print(f"{name:<52} {r['metrics']['oa']:>7.4f} {r['metrics']['mean_f1']:>8.4f} {r['seconds']['total']:>8.1f}")
    if args.json:
        args.json.write_text(json.dumps({"split": "leave one tile out", "train": TRAIN, "classes": CLASSES,
                                         "results": results}, indent=2, default=float))
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=DATA, help=f"folder of the IGN files (default {DATA})")
    p.add_argument("--json", type=Path, default=None, help="write every number to this JSON file")
    p.add_argument("--skip-baseline", action="store_true", help="run lidarfx only")
    p.add_argument("--also-rf", action="store_true", help="also run lidarfx's features with a random forest")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--facade", action="store_true", help="run Lang's facade experiment instead (~4 min on 2 cores)")
    p.add_argument("--loto", action="store_true",
                   help="leave one training tile out instead of the test files (training data only)")
    p.add_argument("--facade-per-class", type=int, default=5000,
                   help="training points per class in the facade experiment (default 5000)")
    args = p.parse_args(argv)
    ensure_lidarfx_importable()
    if args.facade:
        log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
        rows = facade_experiment(args.seed, args.facade_per_class, log)
        print(facade_table(rows))
        if args.json:
            args.json.write_text(json.dumps(rows, indent=2, default=float))
        return 0
    import lidarfx
    import sklearn
    from lidarfx.classify import ClassMap

    train_paths = [args.data / f for f in TRAIN]
    test_paths = [args.data / f for f in TEST]
    missing = [str(q) for q in train_paths + ([] if args.loto else test_paths) if not q.is_file()]
    if missing:
        print(f"missing data files: {', '.join(missing)}", file=sys.stderr)
        return 2
    cmap = ClassMap.parse(CLASSES)
    log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
    print(f"lidarfx {lidarfx.__version__}, scikit-learn {sklearn.__version__}, python {platform.python_version()}, "
          f"{os.cpu_count()} cores")
    print(f"train: {', '.join(TRAIN)}\ntest:  {'leave one tile out' if args.loto else ', '.join(TEST)}\nclasses: {CLASSES} (others ignored)")
    # warm-up (numba compile / cache load), untimed
    from lidarfx.classify import CloudSample, LidarFeatures

    warm = read_usable(train_paths[0])
    LidarFeatures().transform(CloudSample(warm, range(0, len(warm), 50)))
    if args.loto:
        return leave_one_tile_out(train_paths, cmap, args, log)
    out: dict[str, Any] = {"lidarfx_version": lidarfx.__version__, "sklearn_version": sklearn.__version__,
                           "cores": os.cpu_count(), "train": TRAIN, "test": TEST, "classes": CLASSES}
    runs = [("lidarfx default (hgb)", lambda: lidarfx_default(train_paths, test_paths, cmap, args.seed, log))]
    if args.also_rf:
        runs.append(("lidarfx features + random forest",
                     lambda: lidarfx_default(train_paths, test_paths, cmap, args.seed, log, classifier="rf")))
    if not args.skip_baseline:
        runs.append(("baseline", lambda: baseline(train_paths, test_paths, cmap, args.seed, log)))
    results = {}
    for name, fn in runs:
        l0 = load()
        res = fn()
        l1 = load()
        parts = {baseline_name(k): v for k, v in res.items()} if name == "baseline" else {name: res}
        for n2, r2 in parts.items():
            r2["load_before"], r2["load_after"] = l0, l1
            results[n2] = summarise(n2, r2, cmap)
        print(f"  load average before/after: {l0:.2f} / {l1:.2f}")
    out["results"] = results
    lf = results["lidarfx default (hgb)"]
    ok_acc = lf["metrics"]["oa"] >= TARGET_OA and lf["metrics"]["mean_f1"] >= TARGET_F1
    print("\n=== summary ===")
    print(f"{'pipeline':<52} {'OA':>7} {'mean F1':>8} {'seconds':>8}")
    for name, r in results.items():
        print(f"{name:<52} {r['metrics']['oa']:>7.4f} {r['metrics']['mean_f1']:>8.4f} {r['seconds']['total']:>8.1f}")
    print(f"accuracy target OA >= {TARGET_OA}, mean F1 >= {TARGET_F1}: {'PASS' if ok_acc else 'FAIL'}")
    base_name = baseline_name("with z")
    if base_name in results:
        ratio = lf["seconds"]["total"] / results[base_name]["seconds"]["total"]
        out["time_ratio"] = ratio
        print(f"time ratio lidarfx / baseline = {ratio:.3f} (target <= {TARGET_RATIO:.3f}): "
              f"{'PASS' if ratio <= TARGET_RATIO else 'FAIL'}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
