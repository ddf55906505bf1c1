"""``lidarfx classify train|predict|evaluate``: supervised point classification."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .. import _json
from ._args import add_columns, check_output, check_picture_path, columns_of, read_clouds, xyz
from ._report import ReportJob, add_report_option
from ._tiles import TILE_HELP, add_tile_options, inputs_of, run_tiles, wants_tiles

EPILOG = """examples:
  # train on labelled tiles (ground / vegetation 3+4+5 / building; other classes ignored)
  lidarfx classify train tile1.laz tile2.laz tile3.laz --model als.skops --classes 2,3+4+5,6
  # classify a new cloud (writes the LAS classification field; --confidence adds a float32 attribute)
  lidarfx classify predict new.laz new_classified.laz --model als.skops --confidence
  # honest evaluation: 3-fold CV with random AND spatial-block folds (20 m blocks; training points within
  # twice the largest radius of a held-out block left out, --buffer), report in ./eval
  lidarfx classify evaluate tile*.laz --classes 2,3+4+5,6 --cv 3 --spatial-blocks 20 --out eval
  # leave one tile out, and train on the tiles / test on other files
  lidarfx classify evaluate tile*.laz --classes 2,3+4+5,6 --leave-one-out --test other1.laz other2.laz
  # a trained model on labelled files; what a model file holds
  lidarfx classify evaluate other1.laz other2.laz --model als.skops --out eval_test
  lidarfx classify info als.skops
  # Lang's facade experiment: random forest vs naive Bayes on a TLS facade, multi-scale 0.1/0.3/0.5 m
  lidarfx synth facade facade.laz --seed 1
  #   (TLS: no thinning, no terrain augmentation, normals towards the scanner)
  lidarfx classify evaluate facade.laz --classifier nb \\
      --classes ground=2,vegetation=5,wall=6,roof=64,window=65,clutter=66 \\
      --features eigen,plane,msac,height,histogram,distribution -r 0.1 -r 0.3 -r 0.5 --cv 3 \\
      --scanner 6,-12,1.6 --max-disc-points 0 --terrain-augment 0 --spatial-blocks 4

defaults: gradient boosting (--classifier hgb), features = the ALS default list
(eigen, plane, slope-adaptive echo ratio, histogram, distribution at 1, 2 and
3 m; return_ratio, number_of_returns, height_above_ground capped at 5 m), at most
20 000 training points per class plus 10 000 per class from one terrain-sheared
copy of the training files, class-balanced.  The defaults adapt to the training
files and say so: without return numbers (TLS, MLS) the two return inputs are
left out, and for clouds denser than ALS (point spacing below 0.16 m) the radii
are r, 2r, 3r with r from the measured spacing (a disc of r holds 125 points);
both are recorded in the model.  --model default (predict, evaluate, info) is
the model shipped with lidarfx, trained on three IGN LiDAR HD tiles
(docs/default-model.md).  Metrics: OA, kappa, per class PA
(producer's accuracy = recall), UA (user's accuracy = precision), F1, IoU,
support, with 95 % intervals of OA, kappa and mean F1 from a bootstrap of
20 m blocks; confusion matrix rows = reference, columns = predicted.
Virtual points (return number 0), withheld and synthetic points are neither
neighbours nor classified.  Prediction warns when a cloud has less than half
the density of the sparsest training file (--density-augment trains for
sparser clouds).  See docs/classification.md.
"""

TRAIN_EPILOG = """examples:
  lidarfx classify train a.laz b.laz --model m.skops --classes 2,3+4+5,6
  lidarfx classify train scan.laz model.skops   # the model as the last file; defaults fitted to the scan
  lidarfx classify train a.laz --model m.skops --classes ground=2,vegetation=3+4+5:5,building=6 \\
      --classifier rf --features eigen,height -r 0.5 -r 1 --max-per-class 50000
  # a model for clouds sparser than the training files (copies with 1/2, 1/4, 1/8 of the pulses)
  lidarfx classify train a.laz b.laz --model m.skops --classes 2,3+4+5,6 --density-augment 0.5,0.25,0.125
"""

PREDICT_EPILOG = """examples:
  lidarfx classify predict new.laz out.laz --model m.skops
  # features already in the file (for the default model: these groups at 1, 2 and 3 m)
  lidarfx features new.laz new_fx.laz -r 1 -r 2 -r 3 --features eigen,plane,density,histogram,distribution
  lidarfx classify predict new_fx.laz out.laz --model m.skops --precomputed
  lidarfx classify predict delivered.laz out.laz --model m.skops --ground class   # the file's class 2 is the ground
  lidarfx classify predict new.laz out.laz --model m.skops --picture classes.png  # + a plan-view class map
  lidarfx classify predict new.laz out.laz --model m.skops --probabilities  # + probability_ground, ... per point
  # in chunks (a folder of tiles, or a large file): the height above ground from the input, no building rule
  lidarfx ground tiles/ hag/ --hag
  lidarfx classify predict hag/ out/ --model m.skops --ground attribute --min-building-area 0
  lidarfx classify predict big.laz out.laz --model m.skops --ground attribute --min-building-area 0 \\
      --chunk-size 200 --workers 4 --resume

""" + TILE_HELP


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")


def _add_train_options(p: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    g = p.add_argument_group("model")
    g.add_argument("-f", "--features", default=None,
                   help="comma-separated feature groups / names, plus height_above_ground, number_of_returns, "
                        "return_number, intensity, intensity_norm, z, pulse_above, pulse_below "
                        "(default: the ALS list of docs/classification.md §6; when a training file has no return "
                        "numbers (none, all 0, or every point 1 of 1: TLS, MLS) the default leaves out return_ratio "
                        "and number_of_returns and says so); 'default' is that list and -NAME takes "
                        "a group or name out of what came before it, e.g. default,-return_ratio,-number_of_returns")
    g.add_argument("-r", "--radius", type=float, action="append", default=None,
                   help="neighbourhood radius in m (repeat for multi-scale). Default: from the measured point "
                        "spacing of the sparsest training file (median distance to the 20th neighbour): 1, 2, 3 m "
                        "for ALS (spacing 0.16 m or more, up to about 40 pts/m²); for denser clouds (MLS, TLS, "
                        "dense ALS) r, 2r, 3r with r the radius of a disc holding 125 points at that spacing, e.g. "
                        "0.32, 0.64, 0.96 m at a 5 cm spacing. The radii and the spacing are recorded in the model "
                        "(classify info --json)")
    g.add_argument("--classes", default=None,
                   help="class map: 2,3+4+5,6 (merge with +, name with ground=2; unlisted classes are ignored); "
                        "default: every class found except 0, 1, 7, 18")
    g.add_argument("--ignore", default=None, help="comma-separated class codes to leave out, e.g. 64 (without --classes: "
                        "besides 0,1,7,18, which are always left out then)")
    g.add_argument("--classifier", choices=["hgb", "rf", "nb"], default="hgb",
                   help="hgb = gradient boosting (default), rf = random forest, nb = Gaussian naive Bayes")
    g.add_argument("--n-estimators", type=int, default=None,
                   help="trees (rf, default 100) or boosting iterations (hgb, default 300)")
    g.add_argument("--max-per-class", type=int, default=20000,
                   help="training points drawn per class (0 = all), default %(default)s")
    g.add_argument("--no-balance", action="store_true", help="no class-balanced sample weights")
    g.add_argument("--ground", choices=["smrf", "class"], default="smrf",
                   help="ground for height_above_ground: SMRF filter (default, label-free) or the file's class 2")
    g.add_argument("--hag-cap", type=float, default=5.0,
                   help="cap of height_above_ground in m (0 = none), default %(default)s")
    g.add_argument("--max-disc-points", type=float, default=125.0,
                   help="thin denser neighbour clouds to this mean number of points per disc of the smallest "
                        "radius (125 = 40 pts/m² at 1 m; 0 = never thin), default %(default)s")
    g.add_argument("--terrain-augment", type=int, default=1,
                   help="terrain-sheared copies of the training files added to the training sample "
                        "(0 = none), default %(default)s")
    g.add_argument("--density-augment", default=None, metavar="F[,F...]",
                   help="add copies of the training files thinned to these fractions of their pulses "
                        "(e.g. 0.5,0.25,0.125) for models that will classify sparser clouds; default none")
    g.add_argument("-n", "--neighbourhood", "--neighborhood", choices=["sphere", "cylinder", "knn"], default="sphere",
                   help="neighbourhood: sphere of each radius (default), vertical cylinder of each radius, "
                        "or the k nearest points (-k)")
    g.add_argument("-k", type=int, default=None, help="neighbours for --neighbourhood knn")
    g.add_argument("--scanner", type=xyz, default=None, help="scanner position x,y,z (TLS normals)")
    g.add_argument("--bins", type=int, default=10, help="bins of the height-difference histogram")
    g.add_argument("--precomputed", action="store_true",
                   help="read neighbourhood features from the files' attributes instead of computing them")
    g.add_argument("--min-building-area", type=float, default=None, metavar="M2",
                   help="predicted-building clusters (points 1 m apart linked) with a smaller plan footprint "
                        "(convex hull, m²) that do not reach the cloud's edge get their next most probable "
                        "class; 0 = off; stored in the model; default 10 with the default features (ALS, also "
                        "any --features list containing 'default'), 0 with other --features")
    g.add_argument("--max-multi-return-share", type=float, default=None, metavar="S",
                   help="with the rule above: a predicted-building cluster of at least that area in which more "
                        "than this share of the points come from pulses with several returns (a tree crown lets "
                        "the laser through, a roof does not) gets its next class too; 1 = off; stored in the "
                        "model; default 0.5")
    g.add_argument("--seed", type=int, default=0, help="seed of the training sample and the classifier (default 0)")
    g.add_argument("--jobs", type=int, default=None,
                   help="threads of the classifier fit (rf: all cores; hgb: the cores idle when the fit "
                        "starts, see docs)")
    return g


def _fractions(text: str | None) -> list[float] | None:
    from ..errors import LidarfxError

    if text is None:
        return None
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise LidarfxError(f"--density-augment takes comma-separated fractions like 0.5,0.25, got {text!r}") from None
    if not vals or not all(0.0 < v < 1.0 for v in vals):
        raise LidarfxError(f"--density-augment fractions must be between 0 and 1 (exclusive), got {text!r}")
    return vals


def register(sub) -> None:
    p = sub.add_parser(
        "classify",
        help="supervised classification: train, predict, evaluate",
        description="Supervised point classification: train a model on labelled clouds, "
                    "classify new clouds, evaluate with random and spatial-block cross-validation.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    cs = p.add_subparsers(dest="classify_command", metavar="SUBCOMMAND", parser_class=type(p))

    t = cs.add_parser("train", help="train a model on labelled files", epilog=TRAIN_EPILOG,
                      description="Train a point classifier on labelled point clouds and save it (skops).",
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    t.add_argument("files", nargs="+", metavar="FILE",
                   help="labelled training clouds; the last one may be the output model (.skops) instead of --model")
    t.add_argument("-m", "--model", default=None, help="output model file (.skops)")
    _add_train_options(t)
    add_columns(t)
    _add_common(t)
    t.set_defaults(func=run_train)

    pr = cs.add_parser("predict", help="classify a cloud with a trained model", epilog=PREDICT_EPILOG,
                       description="Classify every point of a cloud with a trained model; writes the "
                                   "classification field (and optionally the confidence and per-class probabilities).",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    pr.add_argument("input", help="input point cloud")
    pr.add_argument("output", help="output point cloud (format from the extension)")
    pr.add_argument("-m", "--model", required=True,
                    help="model file written by 'lidarfx classify train', or 'default': the model shipped with "
                         "lidarfx (ground / vegetation / building, trained on IGN LiDAR HD; docs/default-model.md)")
    pr.add_argument("--confidence", action="store_true", help="add a float32 'confidence' attribute (top probability)")
    pr.add_argument("--probabilities", action="store_true",
                    help="add one float32 attribute per class, probability_<class name>: the classifier's "
                         "probabilities (before the building rule)")
    pr.add_argument("--precomputed", action="store_true",
                    help="read the neighbourhood features from the input's attributes")
    pr.add_argument("--ground", choices=["smrf", "class", "attribute"], default=None,
                    help="ground surface for height_above_ground: 'class' = the input's class 2 (e.g. the data "
                         "provider's ground classification) instead of the SMRF filter, 'attribute' = the input's "
                         "height_above_ground attribute (lidarfx ground --hag; needed in chunks); default: the model's")
    pr.add_argument("--picture", default=None, metavar="PNG",
                    help="also write a plan-view map of the predicted classes (class of the highest point per cell)")
    pr.add_argument("--min-building-area", type=float, default=None, metavar="M2",
                    help="object-size rule for buildings (see 'classify train --help'); 0 = off; default: the model's")
    pr.add_argument("--max-multi-return-share", type=float, default=None, metavar="S",
                    help="see-through test of that rule (see 'classify train --help'); 1 = off; default: the model's")
    add_columns(pr)
    add_report_option(pr)
    add_tile_options(pr)
    _add_common(pr)
    pr.set_defaults(func=run_predict)

    i = cs.add_parser("info", help="show what a model file holds (classes, features, training data)",
                      description="Show a model file's classes, features, radii, training files and their "
                                  "densities, sample counts and versions (loaded safely, nothing is executed).",
                      epilog="examples:\n  lidarfx classify info als.skops\n  lidarfx classify info als.skops --json\n",
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    i.add_argument("model", help="model file written by 'lidarfx classify train', or 'default' (the shipped model)")
    i.add_argument("--json", action="store_true", help="print JSON instead of a table")
    i.set_defaults(func=run_info)

    e = cs.add_parser("evaluate", help="cross-validate / test a model configuration", epilog=EPILOG,
                      description="Evaluate: M-fold CV with random and spatial-block folds, leave-one-file-out, "
                                  "train-on-A/test-on-B, or a trained model (--model) on labelled files.",
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    e.add_argument("files", nargs="+", help="labelled clouds (training files, or test files with --model)")
    e.add_argument("--cv", type=int, default=None,
                   help="M-fold cross-validation on FILES (default 3 unless --test/--leave-one-out/--model)")
    e.add_argument("--spatial-blocks", type=float, default=20.0, metavar="SIZE",
                   help="block size (m) of the spatial-block folds and of the bootstrap intervals, default "
                        "%(default)s; 0 = no block folds (intervals then use 20 m)")
    e.add_argument("--bootstrap", type=int, default=1000, metavar="N",
                   help="resamples of spatial blocks for the 95%% intervals of OA, kappa and mean F1, "
                        "default %(default)s; 0 = no intervals")
    e.add_argument("--buffer", type=float, default=None, metavar="M",
                   help="spatial blocks and leave-one-out: leave training points within M metres of the held-out "
                        "blocks / file out of that fold's training (default: twice the largest radius; 0 = none)")
    e.add_argument("--no-random-folds", action="store_true", help="skip the random-fold CV")
    e.add_argument("--leave-one-out", action="store_true", help="leave one file out (train on the others)")
    e.add_argument("--test", nargs="+", default=None, metavar="FILE",
                   help="train on FILES, test on these files (per file and pooled)")
    e.add_argument("-m", "--model", default=None,
                   help="evaluate this trained model on FILES (no training); 'default' = the model shipped with lidarfx")
    e.add_argument("--importance", action="store_true", help="impurity and permutation feature importance")
    e.add_argument("--backward-elimination", action="store_true",
                   help="Chehata-style backward feature elimination with a random forest (slow)")
    e.add_argument("--by-slope", action="store_true",
                   help="with --model or --test: also OA and PA per class in terrain-slope classes "
                        "(0-10, 10-20, 20-30, 30-45, 45-90 degrees; slope of a 1 m DTM of the SMRF ground)")
    e.add_argument("-o", "--out", default=None, metavar="DIR",
                   help="write report.txt, report.json and confusion_*.png to DIR; with --model or --test "
                        "also a plan-view error map errors_<file>.png per test file; importance.png and "
                        "backward_elimination.png with those options")
    g = _add_train_options(e)
    add_columns(e)
    add_report_option(e)
    _add_common(e)
    # what --model cannot use: the options that configure a training or a cross-validation
    # (g._group_actions: argparse's list of the "model" group's options)
    applies = {"precomputed", "min_building_area", "max_multi_return_share"}
    fixed = [a for a in g._group_actions if a.dest not in applies] + [
        a for a in e._actions if a.dest in ("buffer", "no_random_folds", "importance", "backward_elimination")]
    e.set_defaults(func=run_evaluate,
                   not_with_model=[(a.dest, a.default, a.option_strings[-1]) for a in fixed])

    def _usage(args) -> int:
        p.print_help(sys.stderr)
        return 2

    p.set_defaults(func=_usage)


def _log(args):
    if args.quiet:
        return lambda msg: None
    return lambda msg: print(msg, file=sys.stderr, flush=True)


def _config(args):
    from ..classify import TrainConfig

    return TrainConfig(
        features=args.features,
        radii=args.radius or None,  # None: the default radii (none for knn)
        neighbourhood=args.neighbourhood,
        k=args.k,
        scanner=args.scanner,
        hist_bins=args.bins,
        ground=args.ground,
        hag_cap=args.hag_cap or None,
        max_disc_points=args.max_disc_points or None,
        terrain_augment=args.terrain_augment,
        density_augment=_fractions(args.density_augment),
        precomputed=args.precomputed,
        classifier=args.classifier,
        n_estimators=args.n_estimators,
        max_per_class=args.max_per_class or None,
        balance=not args.no_balance,
        seed=args.seed,
        n_jobs=args.jobs,
        **({} if args.min_building_area is None else {"min_building_area": args.min_building_area}),
        **({} if args.max_multi_return_share is None else {"max_multi_return_share": args.max_multi_return_share}),
    )


def _ignore(args):
    from ..errors import LidarfxError

    if not args.ignore:
        return None
    try:
        codes = [int(v) for v in args.ignore.split(",") if v.strip()]
    except ValueError:
        raise LidarfxError(f"--ignore takes comma-separated class codes, got {args.ignore!r}") from None
    bad = [c for c in codes if not 0 <= c <= 255]
    if bad:
        raise LidarfxError(f"--ignore: class codes must be 0..255, got {bad[0]}")
    return codes


def run_train(args) -> int:
    from .._atomic import check_output_folder
    from ..classify import train
    from ..errors import LidarfxError

    if args.model is None:  # lidarfx classify train scan.laz model.skops: the model as the last file
        if len(args.files) < 2 or not str(args.files[-1]).lower().endswith(".skops"):
            raise LidarfxError("give the output model: --model M.skops, or M.skops as the last file")
        args.model = args.files.pop()
    if not str(args.model).lower().endswith(".skops"):
        raise LidarfxError(f"model file should end in .skops, got {args.model}")
    check_output_folder(args.model)  # before the training, not after it
    say = _log(args)
    t0 = time.perf_counter()
    model = train(read_clouds(args.files, args), classes=args.classes, ignore=_ignore(args), config=_config(args),
                  log=say)
    model.save(args.model)
    summary = {"model": args.model, "classes": model.classes.spec(), "features": len(model.feature_names),
               "radii": model.radii, "classifier": model.meta["config"]["classifier"],
               "min_building_area": model.min_building_area,
               "max_multi_return_share": model.max_multi_return_share,
               "training": model.meta["training"], "seconds": round(time.perf_counter() - t0, 3)}
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    say(f"model -> {args.model} ({model.classes.spec()}; {len(model.feature_names)} features; "
        f"{summary['seconds']:.1f} s)")
    return 0


def run_predict(args) -> int:
    import numpy as np

    from .. import io
    from ..classify import load_model

    if wants_tiles(args, "classify", by_size=False):  # its defaults (SMRF height, building rule) are not local
        from ..classify.model import model_path

        args.model = str(model_path(args.model))  # "default": the shipped model's file
        return _predict_tiles(args)
    check_output(args.input, args.output)
    if args.picture:
        check_picture_path(args.picture)
    report = ReportJob(args)
    say = _log(args)
    t0 = time.perf_counter()
    model = load_model(args.model)
    if args.precomputed:
        model.features.precomputed = True
    if args.ground:
        model.features.ground = args.ground
    cloud = io.read(args.input, columns=columns_of(args), progress=False if args.quiet else None)
    cloud.meta["name"] = args.input  # messages name the file as the user typed it
    model.check(cloud, args.input)
    t1 = time.perf_counter()
    _rule_overrides(model, args)
    opts = {}
    if Path(args.output).suffix.lower() in (".las", ".laz"):
        from ..io.las import format_for_classes

        top = max(int(c) for c in model.classes.codes)
        pf = format_for_classes(cloud.header, top)
        if pf is not None:  # decided before the work, not found out when writing
            opts["point_format"] = pf
            say(f"note: the model's class codes go up to {top}, which LAS point format "
                f"{cloud.header.point_format.id} cannot store (0-31); writing LAS 1.4 point format {pf}")
    out = model.classify(cloud, confidence=args.confidence, probabilities=args.probabilities,
                         progress=False if args.quiet else None)
    t2 = time.perf_counter()
    io.write(out, args.output, progress=False if args.quiet else None, **opts)
    t3 = time.perf_counter()
    cls = np.asarray(out["classification"])
    picture = args.picture or (report.picture("classes.png") if report.wanted else None)
    if picture:
        from ..classify import usable_mask
        from ..classify.pipeline import unit_to_metre
        from ..render import class_map

        idx = np.where(usable_mask(out), model.classes.index_of(cls), -1)  # an output code is in its group
        u = unit_to_metre(out)
        class_map(out.xyz[:, :2] * u, out.xyz[:, 2] * u, idx, list(model.classes.names), picture,
                  title=f"{Path(args.input).name} classified with {Path(args.model).name}")
        if args.picture:
            say(f"class map -> {args.picture}")
    counts = {int(c): int(n) for c, n in zip(*np.unique(cls, return_counts=True))}
    summary = {"input": args.input, "output": args.output, "model": args.model, "points": len(out),
               "predicted": int(out.meta["classify"]["predicted_points"]), "classes": counts,
               "density": out.meta["classify"].get("density"), "ground": model.features.ground,
               "min_building_area": model.min_building_area,
               "max_multi_return_share": model.max_multi_return_share,
               "small_buildings": out.meta["classify"].get("small_buildings"),
               "probabilities": dict(zip(model.probability_names(), model.classes.names)) if args.probabilities else None,
               "upgraded_point_format": opts.get("point_format"),
               "picture": args.picture,
               "seconds": {"read": round(t1 - t0, 3), "classify": round(t2 - t1, 3), "write": round(t3 - t2, 3)}}
    page = report.write(f"Classes of {Path(args.input).name}", summary, cloud=out, colour_by="classification",
                        labels={"classification": {int(c): n for c, n in zip(model.classes.codes, model.classes.names)}},
                        pictures=[(picture, "predicted classes (plan view)")] if picture else ())
    if page:
        summary["report"] = page
        say(f"report -> {page}")
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    sb = summary["small_buildings"]
    if sb:
        say(f"small-building rule ({model.min_building_area:g} m²): {sb['relabelled_components']:,} of "
            f"{sb['components']:,} predicted-building clusters relabelled ({sb['relabelled_points']:,} points)"
            + ("; see-through test not run: the file records no return numbers" if sb.get("see_through_untested")
               else f"; see-through test (> {model.max_multi_return_share:g} of the points multi-return): "
               f"{sb['see_through_components']:,} larger ones relabelled ({sb['see_through_points']:,} points)"
               if model.max_multi_return_share < 1 else ""))
    say(f"{len(out):,} points ({summary['predicted']:,} classified) -> {args.output}: "
        + ", ".join(f"class {c} {n:,}" for c, n in counts.items()) + f" ({t3 - t0:.1f} s)")
    return 0


def _predict_tiles(args) -> int:
    """``classify predict`` in chunks (lidarfx.tiles.proc_classes): the whole input's statistics
    first (one or two reads), then the chunks."""
    import warnings

    from ..classify.model import DENSITY_WARN_RATIO
    from ..errors import LidarfxError, LidarfxWarning
    from ..tiles.proc_classes import tile_model, classify_options

    if args.picture:
        raise LidarfxError("--picture draws the whole cloud, not in chunks: leave it out or use --chunk-size 0")
    opts = classify_options(args.model, inputs_of(args.input), ground=args.ground, precomputed=args.precomputed,
                            confidence=args.confidence, probabilities=args.probabilities,
                            min_building_area=args.min_building_area,
                            max_multi_return_share=args.max_multi_return_share)
    ref = tile_model(opts).training_density
    d = opts.get("density")
    if ref and d is not None and d < DENSITY_WARN_RATIO * ref:
        warnings.warn(f"{args.input}: {d:.1f} points/m² is {d / ref:.0%} of the sparsest training file's {ref:.1f}; "
                      "the model's neighbourhoods were learned on denser data and accuracy falls with density "
                      "(train on data like this, or with --density-augment)", LidarfxWarning, stacklevel=2)
    return run_tiles(args, "classify", opts)


def _rule_overrides(model, args) -> None:
    """--min-building-area / --max-multi-return-share given to predict or evaluate --model."""
    if args.min_building_area is not None:
        model.set_min_building_area(args.min_building_area)
    if args.max_multi_return_share is not None:
        model.set_max_multi_return_share(args.max_multi_return_share)


def run_info(args) -> int:
    from ..classify import load_model

    summary = {"model": str(args.model), **load_model(args.model).summary()}
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
        return 0
    print(model_text(summary))
    return 0


def model_text(m: dict, width: int | None = None) -> str:
    """:meth:`ClassifierModel.summary` as a plain two-column table for a terminal of ``width``
    columns (default: the terminal's).  A path, a class name or a feature name is never cut nor
    split over lines: the key column is as wide as the longest key, class names are padded to
    the longest one, lists wrap between their items only, and a line holding a long path is
    longer than the terminal rather."""
    import shutil
    import textwrap

    width = width or shutil.get_terminal_size().columns
    rows: list[tuple[str, list[str]]] = []
    key_w = len("training density")  # the longest key
    avail = max(20, width - key_w - 2)

    def items(parts: list[str], sep: str = ", ") -> list[str]:  # wrapped between the items only
        lines: list[str] = []
        for part in parts:
            if lines and len(lines[-1]) + len(sep) + len(part) + len(sep.rstrip()) <= avail:
                lines[-1] += sep + part
            else:
                if lines:
                    lines[-1] += sep.rstrip()
                lines.append(part)
        return lines

    def prose(text: str) -> list[str]:
        return textwrap.wrap(text, avail, break_long_words=False, break_on_hyphens=False) or [""]

    size = ", ".join(f"{v:,} {k.replace('_', ' ')}" for k, v in m.items() if k in ("boosting_iterations", "trees"))
    rows.append(("classifier", [m["classifier"] + (f" ({size})" if size else "")]))
    name_w = max((len(c["name"]) for c in m["classes"]), default=0)
    codes = ["+".join(map(str, c["codes"])) for c in m["classes"]]
    codes_w = max((len(c) for c in codes), default=0)
    rows.append(("classes", [f"{c['name']:<{name_w}}  codes {k:<{codes_w}}  -> {c['output_code']}"
                             for c, k in zip(m["classes"], codes)]))
    rows.append(("features", [f"{len(m['features'])} columns; radii {', '.join(f'{r:g}' for r in m['radii'])} m:"]
                 + items(list(m["features"]))))
    area = m.get("min_building_area") or 0
    share = m.get("max_multi_return_share") or 1.0
    rows.append(("small buildings", prose(f"clusters under {area:g} m² get their next class" + (
        f"; so do larger ones with more than {share:g} of their points from multi-return pulses" if share < 1 else "")
        if area else "no object-size rule")))
    cfg = m["config"]
    rows.append(("settings", items([f"ground {cfg['ground']}", f"HAG cap {cfg['hag_cap']}",
                                    f"max disc points {cfg['max_disc_points']}",
                                    f"terrain augment {cfg['terrain_augment']}",
                                    f"density augment {cfg.get('density_augment')}",
                                    f"max per class {cfg['max_per_class']}", f"seed {cfg['seed']}"])))
    files = m["training_files"]
    file_w = max((len(str(f["name"])) for f in files), default=0)
    rows.append(("training files", [f"{f['name']!s:<{file_w}}  {f['points']:,} points"
                                    + (f", {f['density']:.1f} pts/m²" if f.get("density") else "")
                                    for f in files] or ["n/a"]))
    if m["training_density"]:
        rows.append(("training density",
                     prose(f"{m['training_density']:.1f} pts/m² (sparsest file; prediction warns below half)")))
    rows.append(("training sample", items([f"{k} {v:,}" for k, v in m["training_counts"].items()]) or ["n/a"]))
    rows.append(("versions", items([f"lidarfx {m['lidarfx_version']}", f"scikit-learn {m['sklearn_version']}",
                                    f"created {m['created']}"])))
    lines = [f"{m['model']}  —  lidarfx classifier ({m['classifier']})"]
    for key, values in rows:
        lines += [f"{key if i == 0 else '':<{key_w}}  {v}".rstrip() for i, v in enumerate(values)]
    return "\n".join(lines)


def run_evaluate(args) -> int:
    from ..classify import evaluate, evaluate_model, format_report, load_model, write_report
    from ..classify.report import report_dir, report_json
    from ..errors import LidarfxError

    say = _log(args)
    page_job = ReportJob(args)
    if args.out:
        from .._atomic import check_new_folder

        report_dir(args.out, create=False)  # a file in the way fails before the work
        check_new_folder(args.out)  # without --force: a new or empty folder
    if args.spatial_blocks < 0:
        raise LidarfxError("--spatial-blocks must be >= 0 (0 = no block folds)")
    if args.bootstrap < 0:
        raise LidarfxError("--bootstrap must be >= 0 (0 = no intervals)")
    if args.model:
        given = [opt for dest, default, opt in args.not_with_model if getattr(args, dest) != default]
        if args.test or args.cv or args.leave_one_out or given:
            given = [o for o, on in (("--cv", args.cv), ("--test", args.test), ("--leave-one-out", args.leave_one_out))
                     if on] + given
            raise LidarfxError(f"--model evaluates a trained model on FILES with its own classes, features and "
                               f"settings; it does not take {', '.join(given)}")
        model = load_model(args.model)
        if args.precomputed:
            model.features.precomputed = True
        _rule_overrides(model, args)
        sec = evaluate_model(model, read_clouds(args.files, args), log=say, maps_dir=args.out, by_slope=args.by_slope,
                             bootstrap=args.bootstrap, ci_block_size=args.spatial_blocks or 20.0)
        report = {"lidarfx_version": model.meta.get("lidarfx_version"), "layout": sec["metrics"]["layout"],
                  "config": model.meta["config"], "features": model.feature_names,
                  "classes": model.classes.to_dict(), "class_spec": model.classes.spec(),
                  "train_files": model.meta["training"]["files"], "sections": {"test": sec},
                  "seconds": {"total": sec["seconds"]}, "model": args.model}
    else:
        cv = args.cv
        if cv is None and not args.test and not args.leave_one_out:
            cv = 3
        if args.by_slope and not args.test:
            raise LidarfxError("--by-slope breaks down the results on test files: give --test FILES or --model")
        if cv is not None and cv < 2:
            raise LidarfxError("--cv needs at least 2 folds")
        from ..classify.evaluate import check_buffer
        from ..classify.model import read_sources, resolve_defaults

        check_buffer(args.buffer, _config(args))  # before reading: a bad option is refused first
        # the defaults fitted to the training files as train fits them (return inputs, radii from the spacing)
        sources = read_sources(read_clouds(args.files, args))
        config, _ = resolve_defaults(_config(args), sources, say)
        report = evaluate(
            sources, test=read_clouds(args.test, args), cv=cv,
            block_size=args.spatial_blocks or None,
            buffer=args.buffer,
            random_cv=not args.no_random_folds, leave_one_out=args.leave_one_out, classes=args.classes,
            ignore=_ignore(args), config=config, importance=args.importance,
            eliminate=args.backward_elimination, log=say, maps_dir=args.out if args.test else None,
            by_slope=args.by_slope, bootstrap=args.bootstrap,
        )
    if args.out:
        written = write_report(report, args.out)
        say(f"report -> {', '.join(str(p) for p in written)}")
    if page_job.wanted:
        say(f"HTML report -> {_evaluation_page(page_job, report, args)}")
    if args.json:
        print(report_json(report))
    else:
        print(format_report(report))
    return 0


def _evaluation_page(job: ReportJob, report: dict, args) -> str:
    """The HTML page of ``classify evaluate``: the set-up, one row per section and per test file
    (OA, kappa, mean F1 and their intervals), the per-class table of each section, the confusion
    matrices, error maps and importances."""
    from ..classify import write_report

    cfg = report["config"]
    figures = {"classes": report.get("class_spec"), "classifier": cfg.get("classifier"),
               "features": len(report["features"]), "radii": list(cfg.get("radii", [])),
               "training files": [Path(f["name"]).name for f in report["train_files"]]}
    rows, classes = [], {}
    for key, sec in report["sections"].items():
        parts = [(sec["title"], sec["metrics"])]
        if key == "test" and len(sec["files"]) > 1:
            parts = [(f"test: {Path(n).name}", m) for n, m in sec["files"].items()] + [("test: pooled", sec["metrics"])]
        for title, m in parts:
            ci = m.get("ci") or {}
            rows.append({"section": title, "points": m["points"], "OA": m["oa"], "kappa": m["kappa"],
                         "mean F1": m["mean_f1"], "mean IoU": m["mean_iou"],
                         "mean F1 interval": "–".join(f"{v:.3f}" for v in ci["mean_f1"]) if ci else None})
            classes[title] = [{k: c[k] for k in ("name", "code", "support", "pa", "ua", "f1", "iou")} for c in m["classes"]]
    scratch = job.scratch() / "evaluate"
    pictures = [(str(p), p.stem.replace("_", " ")) for p in write_report(report, scratch) if p.suffix == ".png"]
    summary = {**figures, "sections": rows, **{f"classes: {t}": r for t, r in classes.items()}}
    return job.write("Classification evaluation", summary, pictures=pictures)
