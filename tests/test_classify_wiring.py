"""How lidarfx.classify's formulas are wired into train, evaluate, evaluate_model, classify and the CLI.

The formulas (confusion matrix, kappa, folds, buffers, hull areas) have unit tests of their own
(tests/test_classify.py, tests/test_objects.py); these tests check that the callers feed them the
right points and pass their settings on, each one against an independent computation:

* training never draws points of ignored codes (train → ``meta["training"]["counts"]``);
* ``evaluate_model``'s per-file and pooled confusion matrices (rows = reference, columns =
  predicted, ignored codes left out) and bootstrap intervals (blocks of different files apart);
* ``block_bootstrap``'s kappa interval; ``evaluate``'s buffer reaches the block CV;
* ``classify`` keeps the class of the points it does not predict;
* the building rule: its area threshold, and the confidence of a relabelled point;
* ``load_model`` refuses a classifier that does not fit the stored feature list / class map;
* the CLI's ``--ignore``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx.classify import (
    ClassMap,
    LidarFeatures,
    TrainConfig,
    block_bootstrap,
    block_buffer_mask,
    block_folds,
    block_ids,
    evaluate,
    evaluate_model,
    load_model,
    metrics,
    train,
    usable_mask,
)
from lidarfx.classify.objects import drop_small_objects
from lidarfx.cli import main
from lidarfx.errors import LidarfxError
from test_objects import _town

#: building first: the rule's column is neither the last one nor the one of the lowest code
CLASSES = "building=6,ground=2,vegetation=5"
FAST = {"features": "eigen,plane,height_above_ground", "radii": [1.0, 2.0], "classifier": "rf", "n_estimators": 10,
        "terrain_augment": 0}
MAX_PER_CLASS = 1500
BLOCK = 20.0  # bootstrap blocks of evaluate_model


def _scene(seed: int, size: float = 60.0, density: float = 20.0, hedges: bool = True, extras: bool = True,
           noise: float = 0.0) -> lidarfx.PointCloud:
    """``_town`` of tests/test_objects.py scaled to ``size`` m: ground (2), three flat houses (6),
    round tree crowns (5) and, with ``hedges``, six 2 × 2 m clipped hedges (5) that look like small
    roofs to a model trained without them.

    ``extras`` adds what the class map must leave out: 4 % of the ground as class 1 (ignored by
    default), part of a house as class 64, and 1 % each of virtual (return number 0, class 66),
    withheld (class 7) and synthetic (class 18) points.  ``noise``: that share of the usable ground
    points is labelled vegetation in the reference (an asymmetric confusion)."""
    town = _town(seed, hedges=hedges, size=size, density=density)
    xyz, cls = town.xyz, np.asarray(town["classification"]).copy()
    xy, n, s = xyz[:, :2] - [7.7e5, 6.27e6], len(town), size / 60.0
    rng = np.random.default_rng(seed + 1000)
    attrs = {"classification": cls}
    if extras:
        ground = np.flatnonzero(cls == 2)
        cls[rng.choice(ground, len(ground) // 25, replace=False)] = 1
        cls[(cls == 6) & (xy[:, 0] > 35 * s) & (xy[:, 0] < 39 * s) & (xy[:, 1] < 22 * s)] = 64
        virtual, withheld, synthetic = np.split(rng.permutation(n)[: 3 * (n // 100)], 3)
        rn = np.ones(n, np.uint8)
        rn[virtual], cls[virtual], cls[withheld], cls[synthetic] = 0, 66, 7, 18
        wh, sy = np.zeros(n, np.uint8), np.zeros(n, np.uint8)
        wh[withheld], sy[synthetic] = 1, 1
        attrs.update(return_number=rn, withheld=wh, synthetic=sy)
        if noise:
            g = np.flatnonzero(cls == 2)
            cls[rng.choice(g, int(noise * len(g)), replace=False)] = 5
    return lidarfx.PointCloud(xyz, attrs)


def _cm(ref: np.ndarray, pred: np.ndarray, k: int) -> np.ndarray:
    """Rows = reference, columns = predicted; reference < 0 left out (not confusion_matrix's code)."""
    cm = np.zeros((k, k), np.int64)
    lab = ref >= 0
    np.add.at(cm, (ref[lab], pred[lab]), 1)
    return cm


@pytest.fixture(scope="module")
def trained():
    """A model trained on a scene with ignored codes and unusable points, with the sample it was
    fitted on: the CloudSamples given to the features and the labels given to the classifier."""
    cloud = _scene(1, hedges=False)
    seen, fitted = [], []
    transform, fit = LidarFeatures.transform, TrainConfig.fit_matrix
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(LidarFeatures, "transform", lambda self, X: (seen.append(X), transform(self, X))[1])
        mp.setattr(TrainConfig, "fit_matrix",
                   lambda self, X, y, progress=None: (fitted.append(np.array(y)), fit(self, X, y, progress))[1])
        model = train(cloud, classes=CLASSES, max_per_class=MAX_PER_CLASS, min_building_area=10, **FAST)
    return cloud, model, seen, fitted


@pytest.fixture(scope="module")
def tests_clouds():
    """Two test scenes on the same ground (their 20 m blocks have the same ids), with hedges,
    ignored codes, unusable points and reference noise."""
    out = []
    for seed, name in ((2, "a"), (3, "b")):
        c = _scene(seed, noise=0.05)
        c.meta = {"name": name}
        out.append(c)
    return out


@pytest.fixture(scope="module")
def predictions(trained, tests_clouds):
    """``(codes, confidence, probabilities, rule stats)`` of the model on each test scene."""
    model = trained[1]
    out = {}
    for c in tests_clouds:
        st: dict = {}
        codes, conf, proba = model.predict(c, return_confidence=True, return_proba=True, stats=st,
                                           check_density=False)
        out[c.meta["name"]] = (codes, conf, proba, st)
    return out


# --------------------------------------------------------------------------- training (M7)
def test_training_draws_no_point_of_an_ignored_code(trained):
    cloud, model, seen, fitted = trained
    cmap = model.classes
    ref = np.asarray(cloud["classification"])
    use = usable_mask(cloud)
    assert ((ref == 1) & use).sum() > 1000 and ((ref == 64) & use).sum() > 500  # ignored, but usable points
    assert (~use).sum() > 1000 and set(np.unique(ref[~use])) == {66, 7, 18}
    counts = model.meta["training"]["counts"]
    want = {name: int((use & np.isin(ref, group)).sum()) for name, group in zip(cmap.names, cmap.groups)}
    assert counts["available"] == want
    assert counts["used"] == {name: min(v, MAX_PER_CLASS) for name, v in want.items()}
    # the points whose features were computed, and the labels the classifier was fitted with
    assert len(seen) == 1 and len(fitted) == 1
    labels = np.concatenate([cmap.index_of(np.asarray(s.cloud["classification"])[s.index]) for s in seen[0]])
    assert (labels >= 0).all()
    np.testing.assert_array_equal(fitted[0], labels)
    assert np.bincount(labels, minlength=len(cmap)).tolist() == list(counts["used"].values())


# --------------------------------------------------------------------------- evaluate_model (M4, M6, M15)
def test_evaluate_model_confusion_and_intervals_per_file_and_pooled(trained, tests_clouds, predictions):
    model = trained[1]
    cmap, k, n_boot = model.classes, len(model.classes), 200
    rep = evaluate_model(model, tests_clouds, bootstrap=n_boot, ci_block_size=BLOCK)
    total = np.zeros((k, k), np.int64)
    refs, preds, xys, files = [], [], [], []
    for i, c in enumerate(tests_clouds):
        use = usable_mask(c)
        ref = cmap.index_of(np.asarray(c["classification"]))[use]
        codes = predictions[c.meta["name"]][0][use]
        assert (codes >= 0).all()
        pred = cmap.index_of(codes)
        cm = _cm(ref, pred, k)
        assert (ref < 0).sum() > 2000  # classes 1 and 64: predicted, never counted
        g, v = cmap.names.index("ground"), cmap.names.index("vegetation")
        assert cm[v, g] > 1000 and cm[v, g] > 3 * cm[g, v]  # reference vegetation called ground: not symmetric
        m = rep["files"][c.meta["name"]]
        assert m["confusion"] == cm.tolist()
        assert m["points"] == int((ref >= 0).sum())
        assert m["ignored_points"] == int((ref < 0).sum()) and m["unusable_points"] == int((~use).sum())
        assert m["oa"] == pytest.approx(np.trace(cm) / cm.sum())
        blocks = block_ids(c.xyz[use, :2], BLOCK)
        assert m["ci"] == block_bootstrap(ref, pred, blocks, k, n_boot=n_boot, block_size=BLOCK)
        total += cm
        refs.append(ref)
        preds.append(pred)
        xys.append(c.xyz[use, :2])
        files.append(np.full(len(ref), i))
    assert rep["metrics"]["confusion"] == total.tolist()
    assert rep["metrics"]["kappa"] == pytest.approx(metrics(total)["kappa"])
    # pooled intervals: a block of one file is not the block with the same id in another file
    xy, g = np.vstack(xys), np.concatenate(files)
    assert len(np.unique(block_ids(xy, BLOCK))) < len(np.unique(block_ids(xy, BLOCK, groups=g)))  # same ground
    want = block_bootstrap(np.concatenate(refs), np.concatenate(preds), block_ids(xy, BLOCK, groups=g), k,
                           n_boot=n_boot, block_size=BLOCK, strata=g)  # blocks resampled within each file
    assert rep["metrics"]["ci"] == want
    assert want["blocks"] == sum(rep["files"][c.meta["name"]]["ci"]["blocks"] for c in tests_clouds)


# --------------------------------------------------------------------------- block bootstrap (M2)
def test_block_bootstrap_interval_collapses_to_the_point_values_when_every_block_is_alike():
    """Blocks whose confusion matrices are multiples of one matrix: every resample has the same
    OA, kappa and mean F1, those of the matrix itself, so each interval is a single value."""
    base = np.array([[30, 6, 2], [4, 20, 5], [1, 3, 9]])
    ref, pred, blocks = [], [], []
    for b, mult in enumerate([1, 2, 3, 1, 2, 1, 1, 3]):
        r, p = np.indices(base.shape).reshape(2, -1)
        cnt = (base * mult).ravel()
        ref.append(np.repeat(r, cnt))
        pred.append(np.repeat(p, cnt))
        blocks.append(np.full(cnt.sum(), 10 * b + 7))
    ref, pred, blocks = np.concatenate(ref), np.concatenate(pred), np.concatenate(blocks)
    m = metrics(base)
    assert 0.3 < m["kappa"] < m["oa"] < 0.9
    for seed in (0, 5):
        ci = block_bootstrap(ref, pred, blocks, 3, n_boot=300, seed=seed)
        assert ci["blocks"] == 8
        for key in ("oa", "kappa", "mean_f1"):
            assert ci[key] == pytest.approx([m[key], m[key]], rel=1e-12), key


# --------------------------------------------------------------------------- evaluate's buffer (M11)
def test_evaluate_passes_its_buffer_to_the_block_folds():
    cloud = _scene(11, size=40.0, density=10.0)
    size, buf, cv = 10.0, 3.0, 3
    rep = evaluate(cloud, classes=CLASSES, cv=cv, block_size=size, buffer=buf, random_cv=False, bootstrap=0,
                   features="eigen,plane", radii=[1.0, 2.0], classifier="rf", n_estimators=5, max_per_class=300,
                   terrain_augment=0)
    sec = rep["sections"]["cv_blocks"]
    assert sec["buffer"] == buf and sec["block_size"] == size
    use = usable_mask(cloud)
    ref = ClassMap.parse(CLASSES).index_of(np.asarray(cloud["classification"]))[use]
    lab = ref >= 0
    xy = cloud.xyz[use][lab, :2]
    folds, _ = block_folds(xy, cv, size, 0)
    near = block_buffer_mask(xy, folds, size, buf)
    want = [int((near[f] & (folds != f)).sum()) for f in range(cv)]
    assert [pf["fold"] for pf in sec["folds"]] == list(range(cv))
    assert [pf["buffer_excluded"] for pf in sec["folds"]] == want
    assert all(w > 0 for w in want)
    assert sum(pf["test_points"] for pf in sec["folds"]) == int(lab.sum()) == sec["metrics"]["points"]


# --------------------------------------------------------------------------- classify (M13)
def test_classify_keeps_the_class_of_points_it_does_not_predict(trained, tests_clouds, predictions):
    model = trained[1]
    c = tests_clouds[1]
    codes, conf, _, _ = predictions["b"]
    use = usable_mask(c)
    old = np.asarray(c["classification"])
    assert set(np.unique(old[~use])) == {66, 7, 18}  # codes the model never gives, and not 1
    out = model.classify(c, confidence=True)
    cls = np.asarray(out["classification"])
    np.testing.assert_array_equal(cls[~use], old[~use])
    np.testing.assert_array_equal(cls[use], codes[use])
    np.testing.assert_array_equal(np.asarray(out["confidence"]), conf)
    assert np.isnan(conf[~use]).all() and not np.isnan(conf[use]).any()
    assert out.meta["classify"]["predicted_points"] == int(use.sum())
    np.testing.assert_array_equal(np.asarray(c["classification"]), old)  # the input is not changed
    # without a classification, the points not predicted are "unclassified" (1)
    bare = lidarfx.PointCloud(c.xyz, {n: np.asarray(c[n]) for n in ("return_number", "withheld", "synthetic")})
    cls = np.asarray(model.classify(bare)["classification"])
    assert (cls[~use] == 1).all()
    np.testing.assert_array_equal(cls[use], codes[use])


# --------------------------------------------------------------------------- the building rule (M10, M12)
def test_building_rule_threshold_is_the_area_strictly_below():
    """Three flat clusters of 2.5 m × (3.875, 4.0, 4.125) m (hull areas 9.6875, 10, 10.3125 m²,
    exact in binary) well inside a 30 × 30 m ground: with a 10 m² minimum only the first is
    relabelled; the threshold moves with ``min_area``."""
    ax = np.arange(0.125, 30, 0.25)
    gx, gy = np.meshgrid(ax, ax)
    ground = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    parts, part = [ground], [np.zeros(len(ground), int)]
    for i, (x0, length) in enumerate(((4.0, 3.875), (13.0, 4.0), (22.0, 4.125))):
        bx, by = np.meshgrid(np.arange(0, 2.5 + 1e-9, 0.125), np.arange(0, length + 1e-9, 0.125))
        parts.append(np.c_[bx.ravel() + x0, by.ravel() + 12.0, np.full(bx.size, 6.0)])
        part.append(np.full(bx.size, i + 1))
    xyz = np.vstack(parts) + [7.7e5, 6.27e6, 40.0]
    part = np.concatenate(part)
    lab = np.where(part > 0, 2, 0)
    alt = np.ones(len(lab), np.int64)
    from lidarfx.geometry import group_hull_areas

    comp = part[part > 0] - 1
    assert group_hull_areas(xyz[part > 0, :2], comp).tolist() == [9.6875, 10.0, 10.3125]
    st: dict = {}
    out = drop_small_objects(lab, alt, xyz, 2, 10.0, stats=st)
    assert (out[part == 1] == 1).all() and (out[part == 2] == 2).all() and (out[part == 3] == 2).all()
    assert (out[part == 0] == 0).all()
    assert st["components"] == 3 and st["kept_at_edge"] == 0 and st["relabelled_components"] == 1
    assert st["relabelled_points"] == int((part == 1).sum())
    for area, small in ((9.6875, []), (9.7, [1]), (10.3, [1, 2]), (10.32, [1, 2, 3])):
        out = drop_small_objects(lab, alt, xyz, 2, area)
        assert sorted(set(part[(out == 1) & (part > 0)])) == small, area


def test_confidence_of_a_relabelled_point_is_its_new_class_probability(trained, predictions):
    model = trained[1]
    b = model.classes.names.index("building")
    assert b == 0
    n_changed = 0
    for codes, conf, proba, st in predictions.values():
        use = codes >= 0
        top = model.classes.code_of(proba[use].argmax(axis=1))  # the classifier's answer, before the rule
        other = proba[use].copy()
        other[:, b] = -1.0
        changed = codes[use] != top
        assert (top[changed] == 6).all()
        assert changed.sum() == st["relabelled_points"] + st["see_through_points"]
        np.testing.assert_array_equal(codes[use][changed], model.classes.code_of(other[changed].argmax(axis=1)))
        np.testing.assert_array_equal(conf[use][changed], other[changed].max(axis=1))
        np.testing.assert_array_equal(conf[use][~changed], proba[use][~changed].max(axis=1))
        assert (conf[use][changed] <= proba[use][changed, b]).all()
        n_changed += int(changed.sum())
    assert n_changed > 300  # the hedges


# --------------------------------------------------------------------------- model files (M8)
def test_load_model_refuses_a_classifier_that_does_not_fit_the_model(tmp_path):
    import skops.io as sio
    from sklearn.ensemble import RandomForestClassifier

    cloud = _scene(21, size=40.0, density=10.0, extras=False)
    model = train(cloud, classes=CLASSES, features="eigen,plane", radii=[1.0], classifier="rf", n_estimators=5,
                  max_per_class=300, terrain_augment=0)
    n = len(model.feature_names)
    path = model.save(tmp_path / "good.skops")
    np.testing.assert_array_equal(load_model(path).predict(cloud), model.predict(cloud))
    obj = sio.load(path, trusted=sio.get_untrusted_types(file=path))
    rng = np.random.default_rng(0)
    for name, cols, classes, message in (("fewer", n - 3, 3, f"expects {n - 3} features but the model lists {n}"),
                                         ("more", n + 1, 3, f"expects {n + 1} features"),
                                         ("classes", n, 2, "knows 2 classes, the class map 3")):
        X = rng.normal(size=(60, cols))
        obj["classifier"] = RandomForestClassifier(n_estimators=2, random_state=0).fit(X, np.arange(60) % classes)
        bad = tmp_path / f"{name}.skops"
        sio.dump(obj, bad)
        with pytest.raises(LidarfxError, match=message):
            load_model(bad)
    # a stored feature list that is not the one its parameters make
    obj = sio.load(path, trusted=sio.get_untrusted_types(file=path))
    obj["meta"]["features"] = obj["meta"]["features"][:-1]
    sio.dump(obj, tmp_path / "list.skops")
    with pytest.raises(LidarfxError, match="feature list does not match"):
        load_model(tmp_path / "list.skops")


# --------------------------------------------------------------------------- CLI --ignore (M14)
@pytest.fixture(scope="module")
def ignore_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("ignore")
    p = d / "scene.laz"
    lidarfx.write(_scene(31, size=40.0, density=10.0), p)
    return d, p


CLI_FAST = ["--features", "eigen", "-r", "1", "--classifier", "rf", "--n-estimators", "5", "--max-per-class", "300",
            "--terrain-augment", "0", "-q"]


def _usable_counts(path) -> dict[int, int]:
    c = lidarfx.read(path)
    codes, n = np.unique(np.asarray(c["classification"])[usable_mask(c)], return_counts=True)
    return dict(zip(codes.tolist(), n.tolist()))


def test_cli_ignore_without_classes_adds_to_the_default_ignore(ignore_file, capsys):
    d, p = ignore_file
    found = _usable_counts(p)
    assert set(found) == {1, 2, 5, 6, 64}  # without --ignore, 64 would be a class of its own
    m = d / "no_classes.skops"
    assert main(["classify", "train", str(p), "--model", str(m), "--ignore", "64", *CLI_FAST]) == 0
    capsys.readouterr()
    assert main(["classify", "info", str(m), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [c["codes"] for c in info["classes"]] == [[2], [5], [6]]
    assert load_model(m).meta["training"]["counts"]["available"] == {"ground": found[2], "high vegetation": found[5],
                                                                      "building": found[6]}
    # evaluate takes it too
    assert main(["classify", "evaluate", str(p), "--ignore", "64", "--cv", "2", "--no-random-folds",
                 "--spatial-blocks", "20", "--bootstrap", "0", *CLI_FAST, "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["classes"]["groups"] == [[2], [5], [6]]
    assert rep["sections"]["cv_blocks"]["metrics"]["points"] == found[2] + found[5] + found[6]


def test_cli_ignore_with_classes_removes_codes_from_the_groups(ignore_file, capsys):
    d, p = ignore_file
    found = _usable_counts(p)
    m = d / "classes.skops"
    assert main(["classify", "train", str(p), "--model", str(m), "--classes", "ground=2,vegetation=5,building=6+64",
                 "--ignore", "64", *CLI_FAST]) == 0
    capsys.readouterr()
    assert main(["classify", "info", str(m), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [(c["name"], c["codes"]) for c in info["classes"]] == [("ground", [2]), ("vegetation", [5]),
                                                                  ("building", [6])]
    assert load_model(m).meta["training"]["counts"]["available"]["building"] == found[6]


@pytest.mark.parametrize("value, message", [
    ("x", "--ignore takes comma-separated class codes, got 'x'"),
    ("64,x", "--ignore takes comma-separated class codes, got '64,x'"),
    ("6.5", "--ignore takes comma-separated class codes, got '6.5'"),
    ("64,999", "--ignore: class codes must be 0..255, got 999"),
    ("-5", "--ignore: class codes must be 0..255, got -5"),
])
def test_cli_bad_ignore_is_a_one_line_error(ignore_file, capsys, value, message):
    d, p = ignore_file
    assert main(["classify", "train", str(p), "--model", str(d / "bad.skops"), f"--ignore={value}", *CLI_FAST]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [f"lidarfx: error: {message}"]
    assert not (d / "bad.skops").exists()


# --------------------------------------------------------------------------- CLI options reach the model
@pytest.mark.parametrize("args, want", [
    (["--features", "eigen,plane,height_above_ground", "-r", "1", "-r", "1.5", "-n", "cylinder", "--bins", "7",
      "--ground", "class", "--hag-cap", "3", "--max-disc-points", "60", "--terrain-augment", "0",
      "--classifier", "rf", "--n-estimators", "5", "--max-per-class", "300", "--no-balance", "--seed", "7",
      "--jobs", "1", "--min-building-area", "4", "--max-multi-return-share", "0.8"],
     {"features": ["eigen", "plane", "height_above_ground"], "radii": [1.0, 1.5], "neighbourhood": "cylinder", "k": None,
      "hist_bins": 7, "ground": "class", "hag_cap": 3.0, "max_disc_points": 60.0, "terrain_augment": 0,
      "classifier": "rf", "n_estimators": 5, "max_per_class": 300, "balance": False, "seed": 7, "n_jobs": 1,
      "min_building_area": 4.0, "max_multi_return_share": 0.8}),
    (["--features", "eigen", "-n", "knn", "-k", "8", "--scanner", "1,2,30", "--hag-cap", "0", "--max-disc-points",
      "0", "--max-per-class", "0", "--terrain-augment", "2", "--classifier", "nb"],
     {"features": ["eigen"], "radii": [], "neighbourhood": "knn", "k": 8, "scanner": [1.0, 2.0, 30.0], "hag_cap": None,
      "max_disc_points": None, "max_per_class": None, "terrain_augment": 2, "classifier": "nb", "balance": True,
      "min_building_area": 0.0}),
])
def test_cli_train_options_reach_the_model(ignore_file, capsys, args, want):
    """Every training option of the CLI lands in the model's stored configuration."""
    d, p = ignore_file
    m = d / "options.skops"
    assert main(["classify", "train", str(p), "--model", str(m), "--classes", "2,5,6", "-q", "--force", *args]) == 0
    capsys.readouterr()
    assert main(["classify", "info", str(m), "--json"]) == 0
    cfg = json.loads(capsys.readouterr().out)["config"]
    got = {key: cfg[key] for key in want}
    if isinstance(got.get("scanner"), (list, tuple)):
        got["scanner"] = [float(v) for v in got["scanner"]]
    assert got == want


def test_cli_evaluate_modes_write_their_sections(tmp_path, capsys):
    """--leave-one-out, --test (two files: a confusion PNG each) and --backward-elimination through the CLI."""
    files = []
    for seed in (41, 42, 43, 44):
        files.append(tmp_path / f"s{seed}.laz")
        lidarfx.write(_scene(seed, size=40.0, density=10.0, extras=False), files[-1])
    out = tmp_path / "eval"
    rc = main(["classify", "evaluate", str(files[0]), str(files[1]), "--classes", "2,5,6", "--leave-one-out",
               "--buffer", "0", "--test", str(files[2]), str(files[3]), "--backward-elimination", "--out", str(out),
               "--bootstrap", "0", *CLI_FAST[:-1], "--json", "-q"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    rep = json.loads((out / "report.json").read_text())
    assert set(rep["sections"]) == {"leave_one_file_out", "test"}  # --test and --leave-one-out: no CV
    assert [Path(pf["file"]).name for pf in rep["sections"]["leave_one_file_out"]["folds"]] == ["s41.laz", "s42.laz"]
    assert sorted(Path(f).name for f in rep["sections"]["test"]["files"]) == ["s43.laz", "s44.laz"]
    pngs = sorted(f.name for f in out.glob("*.png"))
    for name in ("confusion_leave_one_file_out.png", "confusion_test.png", "confusion_test_s43.png",
                 "confusion_test_s44.png", "errors_s43.png", "errors_s44.png", "backward_elimination.png"):
        assert name in pngs, (name, pngs)
    steps = rep["backward_elimination"]["steps"]
    n0 = len(rep["features"])
    assert steps[0]["n_features"] == n0 and steps[-1]["n_features"] == 1
    assert all(a["n_features"] > b["n_features"] for a, b in zip(steps, steps[1:]))
    assert summary["sections"]["test"]["metrics"] == rep["sections"]["test"]["metrics"]  # --json: the report


def test_default_radii_depend_on_the_neighbourhood():
    from lidarfx.classify.pipeline import DEFAULT_RADII

    assert TrainConfig().radii == TrainConfig(neighbourhood="cylinder").radii == list(DEFAULT_RADII)
    assert TrainConfig(neighbourhood="knn", k=8).radii == []  # kNN: no radius unless a cap is given
    assert TrainConfig(neighbourhood="knn", k=8, radii=[4.0]).radii == [4.0]
    with pytest.raises(LidarfxError, match="at most one radius"):
        TrainConfig(neighbourhood="knn", k=8, radii=[1.0, 2.0])


# --------------------------------------------------------------------------- smaller contracts
def test_terrain_shear_moves_z_by_a_function_of_xy_only():
    """The augmentation copy: every point moves by f(x, y) (walls stay vertical), slopes stay
    below the two sines' bound, and the height above the (class-2) ground barely changes."""
    from lidarfx.classify.pipeline import hag, terrain_shear

    town = _town(5, size=60.0, density=20.0)
    xyz = np.vstack([town.xyz, town.xyz[:500] + [0, 0, 7.5]])  # a second point above 500 of them: a "wall"
    cls = np.r_[np.asarray(town["classification"]), np.full(500, 6, np.uint8)]
    cloud = lidarfx.PointCloud(xyz, {"classification": cls})
    for seed in (0, 1, 2):
        sh = terrain_shear(cloud, seed)
        dz = sh.xyz[:, 2] - xyz[:, 2]
        assert (sh.xyz[:, :2] == xyz[:, :2]).all()
        np.testing.assert_allclose(dz[-500:], dz[:500], atol=1e-9)  # same (x, y), same shift
        assert 0.5 < np.ptp(dz) <= 40.0  # two sines of 4–10 m
        order = np.argsort(xyz[:, 0])
        step = np.hypot(*np.diff(xyz[order, :2], axis=0).T)
        far = step > 0.05
        # the steepest slope of A·sin + B·sin with A, B ≤ 10 m and wavelengths ≥ 60 m: atan(2π·10/60·√2)
        grad = np.abs(np.diff(dz[order]))[far] / step[far]
        assert grad.max() <= 2 * np.pi * 10 / 60 * np.sqrt(2) * 1.001
        # the true height above the terrain is unchanged: measured against the class-2 ground, exactly
        # on the ground and within a few cm on the trees; under the 12 m houses the TIN spans the gap
        # linearly where the shift curves, so roofs move by decimetres (SMRF, the default ground, is
        # recomputed on the copy and errs there as it would on real slopes)
        d = np.abs(hag(sh, "class") - hag(cloud, "class"))
        assert d[cls == 2].max() < 1e-4 and np.percentile(d[cls == 5], 99) < 0.05
        assert 0.1 < np.percentile(d[cls == 6], 99) < 1.0


def test_input_errors_are_lidarfx_errors():
    from lidarfx.classify import confusion_matrix, random_folds

    with pytest.raises(LidarfxError, match="differ in length"):
        confusion_matrix(np.array([0, 1]), np.array([0]), 2)
    with pytest.raises(LidarfxError, match="out of range"):
        confusion_matrix(np.array([0, 2]), np.array([0, 1]), 2)
    with pytest.raises(LidarfxError, match="square"):
        metrics(np.ones((2, 3)))
    with pytest.raises(LidarfxError, match="not both"):
        evaluate([_scene(1, size=20.0, extras=False)], classes="2,5,6", config=TrainConfig(), classifier="rf")
    with pytest.raises(LidarfxError, match="not both"):
        train([_scene(1, size=20.0, extras=False)], classes="2,5,6", config=TrainConfig(), classifier="rf")
    with pytest.raises(LidarfxError, match="cannot make"):
        random_folds(2, 3)


def test_random_folds_fall_back_to_plain_folds_for_a_tiny_class():
    from lidarfx.classify import random_folds

    y = np.r_[np.zeros(60, int), np.ones(60, int), [2]]  # class 2 has one point: no stratification
    f = random_folds(len(y), 3, seed=0, y=y)
    assert sorted(np.bincount(f).tolist()) == [40, 40, 41]
    y2 = np.r_[np.zeros(60, int), np.ones(30, int)]
    f2 = random_folds(len(y2), 3, seed=0, y=y2)  # stratified: every fold holds a third of each class
    assert [np.bincount(f2[y2 == c]).tolist() for c in (0, 1)] == [[20, 20, 20], [10, 10, 10]]


def test_ignoring_a_code_renames_only_the_default_names():
    m = ClassMap.parse("2,5+64,6,veg=3+4+7:4").without([64, 7])
    assert m.names == ("ground", "high vegetation", "building", "veg")  # 'high vegetation/class 64' no more
    assert m.groups == ((2,), (5,), (6,), (3, 4)) and m.codes == (2, 5, 6, 4)
    assert ClassMap.parse("2,3+4+5:3,6").without([3]).codes == (2, 5, 6)  # the output code left: the highest
    # numpy arrays as ignore lists (truth value of an array is ambiguous)
    from lidarfx.classify.model import read_sources, resolve_classes

    srcs = read_sources([_scene(1, size=20.0)])
    assert resolve_classes(srcs, None, np.array([64, 5])).spec() == "ground=2,building=6"
    assert resolve_classes(srcs, "2,5+64,6", np.array([64])).spec() == "ground=2,high vegetation=5,building=6"


def test_absurd_radius_and_height_cap_do_not_overflow():
    """A radius of 1e308 m raised OverflowError (π r² of the neighbour thinning); a cap of 1e308 m
    warned about a float32 overflow. The radius now means 'no thinning', the cap 'no cap'."""
    import warnings

    from lidarfx.classify.pipeline import _cap32

    assert _cap32(None) == np.inf and _cap32(1e308) == np.inf and _cap32(5.0) == np.float32(5.0)
    cloud = _scene(3, size=30.0, density=8.0, extras=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        huge = LidarFeatures(features="planarity,height_above_ground", radii=[1e308], hag_cap=1e308,
                             max_disc_points=125.0).fit_transform(cloud)
        plain = LidarFeatures(features="planarity,height_above_ground", radii=[1e308], hag_cap=None,
                              max_disc_points=None).fit_transform(cloud)
    assert huge.shape == (len(cloud), 2) and np.array_equal(huge, plain, equal_nan=True)
    # every point is in every neighbourhood: one planarity for the whole cloud
    assert np.ptp(huge[:, 0]) < 1e-5 and np.isfinite(huge[:, 0]).all()
    assert huge[:, 1].max() > 5.0  # the roofs and crowns keep their heights: no cap


@pytest.mark.parametrize("seed", [-1, 2**32, 1.5, "x"])
def test_bad_seed_is_a_lidarfx_error(seed):
    """numpy's ValueError ('expected non-negative integer') was a traceback from `--seed -1`."""
    with pytest.raises(LidarfxError, match="seed must be an integer"):
        TrainConfig(seed=seed)
    with pytest.raises(LidarfxError, match="seed must be an integer"):
        evaluate([_scene(1, size=20.0, density=4.0, extras=False)], cv_seed=seed, config=TrainConfig(**FAST))
    assert TrainConfig(seed=2**32 - 1).seed == 2**32 - 1


@pytest.mark.parametrize("bins", [1, 1001, 10**8, 2.5])
def test_bad_histogram_bins_are_refused_before_training(bins):
    """`classify train --bins 100000000` allocated 10^8 bins per thread and ran for ages."""
    with pytest.raises(LidarfxError, match="hist_bins must be an integer from 2 to 1000"):
        TrainConfig(hist_bins=bins)
    assert TrainConfig(hist_bins=1000).hist_bins == 1000


@pytest.mark.parametrize("opts, message", [
    ({"n_estimators": 10**9}, "from 1 to 100000"),  # ran for hours
    ({"terrain_augment": 10**9}, "terrain_augment must be a number of copies from 0 to 100"),  # 5.6 GB, then a traceback
    ({"n_jobs": 10**23}, "n_jobs must be a number of threads from 1 to 1024"),  # ctypes OverflowError traceback
    ({"n_jobs": 0}, "n_jobs must be a number of threads"),
    ({"n_jobs": -1}, "n_jobs must be a number of threads"),
    ({"radii": [1e-300]}, "radii must be at least 1e-09"),  # ZeroDivisionError in the thinning
    ({"scanner": [float("nan"), 0, 0]}, "scanner must be three finite numbers"),
    ({"max_disc_points": 1e-300}, "max_disc_points must be at least 1 point per disc"),  # thinned the cloud away
])
def test_training_options_out_of_range_are_refused(opts, message):
    with pytest.raises(LidarfxError, match=message):
        TrainConfig(**opts)


def test_thinning_keeps_at_least_one_disc_of_points():
    """A disc far wider than the cloud (-r 1e9) asked for a density that kept no point, and training
    said "the point cloud is empty"; the thinning now keeps about max_disc_points points, and
    leaves ordinary thinning alone (the same mask)."""
    from lidarfx.classify.pipeline import point_density, thinning_mask

    xyz = np.random.default_rng(3).uniform(0, 50, (20_000, 3))
    tiny = 125.0 / (np.pi * 1e18)
    assert thinning_mask(xyz, tiny).sum() == 0  # what it did
    kept = thinning_mask(xyz, tiny, min_keep=125).sum()
    assert 80 < kept < 170
    half = point_density(xyz) / 2
    np.testing.assert_array_equal(thinning_mask(xyz, half), thinning_mask(xyz, half, min_keep=125))
    assert thinning_mask(xyz, tiny, min_keep=50_000) is None  # would keep everything: no thinning


@pytest.mark.parametrize("opts, message", [
    ({"bootstrap": 10**9}, "from 0 \\(no intervals\\) to 100000"),  # an 82 GiB allocation
    ({"block_size": 1e-300}, "block size must be a number of metres from 0.01 on"),  # said "only 1 block"
])
def test_evaluation_options_out_of_range_are_refused_before_the_work(opts, message):
    cloud = _scene(1, size=20.0, density=4.0, extras=False)
    with pytest.raises(LidarfxError, match=message):
        evaluate([cloud], cv=3, config=TrainConfig(**FAST), **opts)


def test_a_buffer_wider_than_the_data():
    """Blocks beyond the data's span do not exist: a buffer of 1e308 m marks the same points as one
    just over the span (it raised OverflowError, and 1e5 m looped for ages); CV then says which
    option to change."""
    rng = np.random.default_rng(4)
    xy = rng.uniform(0, 50, (2000, 2)) + [7.7e5, 6.27e6]
    folds, _ = block_folds(xy, 3, 10.0, 0)
    ref = block_buffer_mask(xy, folds, 10.0, 75.0)  # > the 50 m span's diagonal: every other-fold point
    assert np.array_equal(ref, folds[None, :] != np.arange(3)[:, None])
    for b in (1e5, 1e308):
        assert np.array_equal(block_buffer_mask(xy, folds, 10.0, b), ref)
    cloud = _scene(11, size=40.0, density=6.0, extras=False)
    with pytest.raises(LidarfxError, match=r"fold 0: its training part holds fewer than two classes \(.* use a smaller --buffer"):
        evaluate(cloud, classes=CLASSES, cv=3, block_size=10.0, buffer=1e308, random_cv=False, bootstrap=0,
                 config=TrainConfig(**FAST))


def test_cli_reads_headerless_text_with_columns(tmp_path, capsys):
    """ISPRS-style text without a header: `--columns` names its columns for train, predict,
    evaluate (also with --model and --test), ground-eval and dtm (those read only LAS-like input
    before: the 4th column was 'col3', so no classification)."""
    cloud = _scene(21, size=30.0, density=8.0, extras=False)
    xyz, cls = cloud.xyz, np.asarray(cloud["classification"])
    path = tmp_path / "scene.txt"
    np.savetxt(path, np.column_stack([xyz, cls]), fmt="%.3f %.3f %.3f %d")
    spec = ["--columns", "x,y,z,classification"]
    fast = ["-f", "eigen,plane,height_above_ground", "-r", "1", "-r", "2", "--classifier", "rf",
            "--n-estimators", "10", "--terrain-augment", "0", "--classes", CLASSES, "-q"]
    model = tmp_path / "m.skops"
    assert main(["classify", "train", str(path), "--model", str(model), *fast]) == 2
    assert "has no classification" in capsys.readouterr().err
    assert main(["classify", "train", str(path), "--model", str(model), *fast, *spec]) == 0
    files = load_model(model).meta["training"]["files"]
    assert [f["name"] for f in files] == [str(path)] and files[0]["points"] == len(cloud)
    out = tmp_path / "p.laz"
    assert main(["classify", "predict", str(path), str(out), "--model", str(model), "-q", *spec]) == 0
    pred = np.asarray(lidarfx.read(out)["classification"])
    assert len(pred) == len(cloud) and (pred == cls).mean() > 0.9
    capsys.readouterr()
    assert main(["classify", "evaluate", str(path), "--model", str(model), "--json", "-q", "--bootstrap", "0",
                 *spec]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["sections"]["test"]["metrics"]["points"] == len(cloud)
    assert main(["classify", "evaluate", str(path), "--test", str(path), "--json", "-q", "--bootstrap", "0",
                 *fast, *spec]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["sections"]["test"]["metrics"]["points"] == len(cloud)
    assert main(["ground-eval", str(path), "--json", "-q", *spec]) == 0
    assert json.loads(capsys.readouterr().out)["files"][0]["n_points"] == len(cloud)
    assert main(["dtm", str(path), str(tmp_path / "d.asc"), "-q", *spec]) == 0  # class 2 from the 4th column
