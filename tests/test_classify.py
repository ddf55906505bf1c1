"""Supervised classification (docs/classification.md): metrics, folds, class maps, models, CLI, IGN acceptance."""
from __future__ import annotations

import json
import math
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx.classify import (
    ClassMap,
    CloudSample,
    LidarFeatures,
    TrainConfig,
    block_folds,
    confusion_matrix,
    evaluate,
    load_model,
    make_pipeline,
    metrics,
    random_folds,
    train,
    usable_mask,
)
from lidarfx.classify.importance import backward_elimination, impurity_importance, permutation_importance
from lidarfx.cli import main
from lidarfx.errors import LidarfxError, LidarfxWarning

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
IGN_TRAIN = [REAL / f"test_data_{t}_627755_LA93_IGN69.laz" for t in ("77050", "77055", "77060")]
IGN_TEST = [REAL / "crop_1.laz", REAL / "pont.laz"]
FACADE6 = "ground=2,vegetation=5,wall=6,roof=64,window=65,clutter=66"  # Lang's six classes; noise 7 ignored
SMALL = dict(features="eigen,height,plane", radii=[0.3, 0.5], max_per_class=2000)


@pytest.fixture(scope="module")
def facades():
    return lidarfx.synth.facade(seed=1, density=150.0), lidarfx.synth.facade(seed=2, density=150.0)


@pytest.fixture(scope="module")
def rf_model(facades):
    return train(facades[0], classes=FACADE6, classifier="rf", n_estimators=30, **SMALL)


# --------------------------------------------------------------------------- metrics
def test_metrics_on_a_hand_computed_matrix():
    cm = [[50, 10], [5, 35]]  # rows = reference, columns = predicted
    m = metrics(cm, ["a", "b"])
    assert m["points"] == 100 and m["layout"] == "rows = reference, columns = predicted"
    assert m["oa"] == pytest.approx(0.85)
    pe = (60 * 55 + 40 * 45) / 100**2  # 0.51
    assert m["kappa"] == pytest.approx((0.85 - pe) / (1 - pe))  # 0.693877...
    a, b = m["classes"]
    assert (a["support"], a["predicted"], b["support"], b["predicted"]) == (60, 55, 40, 45)
    assert a["pa"] == pytest.approx(50 / 60) and a["ua"] == pytest.approx(50 / 55)
    assert a["f1"] == pytest.approx(2 * (50 / 60) * (50 / 55) / (50 / 60 + 50 / 55)) and a["f1"] == pytest.approx(100 / 115)
    assert a["iou"] == pytest.approx(50 / 65)
    assert b["pa"] == pytest.approx(35 / 40) and b["ua"] == pytest.approx(35 / 45)
    assert b["f1"] == pytest.approx(70 / 85) and b["iou"] == pytest.approx(35 / 50)
    assert m["mean_f1"] == pytest.approx((100 / 115 + 70 / 85) / 2)
    assert m["mean_iou"] == pytest.approx((50 / 65 + 35 / 50) / 2)


def test_a_class_without_reference_points_is_left_out_of_the_means_and_says_so():
    from lidarfx.classify.evaluate import format_metrics

    m = metrics([[50, 10, 0], [5, 35, 0], [0, 0, 0]], ["a", "b", "c"])  # c: never in the reference
    assert m["mean_f1"] == pytest.approx((100 / 115 + 70 / 85) / 2)
    rows: dict[str, str] = {}
    for line in format_metrics(m).splitlines():  # the class table comes before the confusion matrix
        if line.startswith("  "):
            rows.setdefault(line.split()[0], line)
    assert "not in the means" in rows["c"] and "not in the means" not in rows["a"] + rows["b"]


def test_block_bootstrap_intervals():
    from lidarfx.classify import block_bootstrap, block_ids

    rng = np.random.default_rng(0)
    blocks = np.repeat(np.arange(100), 100)  # 100 blocks of 100 points
    ref = rng.integers(0, 2, blocks.size)
    assert block_bootstrap(ref, ref, blocks, 2)["oa"] == [1.0, 1.0]  # perfect: no spread
    # every point of half the blocks right, of the other half wrong: OA 0.5; the resampled
    # share of right blocks has sd sqrt(0.25 / 100) = 0.05, so the 95 % interval is 0.5 ± 0.098,
    # where resampling single points (10 000 of them) would give ± 0.0098
    pred = np.where(blocks % 2 == 0, ref, 1 - ref)
    ci = block_bootstrap(ref, pred, blocks, 2, n_boot=4000, seed=1)
    assert ci["blocks"] == 100 and ci["level"] == 0.95
    assert ci["oa"][0] == pytest.approx(0.402, abs=0.015) and ci["oa"][1] == pytest.approx(0.598, abs=0.015)
    assert ci["mean_f1"][0] < 0.5 < ci["mean_f1"][1]
    assert ci == block_bootstrap(ref, pred, blocks, 2, n_boot=4000, seed=1)  # seeded
    unlabelled = np.where(blocks < 99, -1, ref)  # labelled points in one block only: no interval
    assert block_bootstrap(unlabelled, pred, blocks, 2) is None
    # block ids: the grid is aligned to multiples of the size, groups keep files apart
    xy = np.array([[0.5, 0.5], [19.9, 0.1], [20.1, 0.1], [0.5, 0.5]])
    b = block_ids(xy, 20.0, groups=np.array([0, 0, 0, 1]))
    assert b[0] == b[1] and len({b[0], b[2], b[3]}) == 3


def test_metrics_absent_class_and_layout():
    # class 2 never occurs in the reference but is predicted once: it does not enter the means
    cm = np.array([[8, 1, 1], [0, 10, 0], [0, 0, 0]])
    m = metrics(cm)
    c2 = m["classes"][2]
    assert c2["support"] == 0 and math.isnan(c2["pa"]) and c2["ua"] == 0.0 and c2["f1"] == 0.0
    f1 = [2 * 8 / (10 + 8), 2 * 10 / (10 + 11)]
    assert m["mean_f1"] == pytest.approx(np.mean(f1))
    assert m["oa"] == pytest.approx(18 / 20)
    # rows = reference, columns = predicted
    ref = np.array([0, 0, 1, -1])
    pred = np.array([0, 1, 1, 0])
    np.testing.assert_array_equal(confusion_matrix(ref, pred, 2), [[1, 1], [0, 1]])
    perfect = metrics([[5, 0], [0, 5]])
    assert perfect["oa"] == 1.0 and perfect["kappa"] == pytest.approx(1.0)


def test_metrics_match_sklearn():
    from sklearn.metrics import cohen_kappa_score, f1_score, jaccard_score

    rng = np.random.default_rng(3)
    y = rng.integers(0, 4, 500)
    p = np.where(rng.random(500) < 0.7, y, rng.integers(0, 4, 500))
    m = metrics(confusion_matrix(y, p, 4))
    assert m["kappa"] == pytest.approx(cohen_kappa_score(y, p))
    np.testing.assert_allclose([c["f1"] for c in m["classes"]], f1_score(y, p, average=None))
    np.testing.assert_allclose([c["iou"] for c in m["classes"]], jaccard_score(y, p, average=None))


# --------------------------------------------------------------------------- class maps
def test_class_map_merge_ignore_and_roundtrip():
    cm = ClassMap.parse("2,3+4+5,6")
    assert cm.groups == ((2,), (3, 4, 5), (6,)) and cm.codes == (2, 5, 6)  # a merged class: its highest code
    assert cm.names == ("ground", "vegetation", "building")
    np.testing.assert_array_equal(cm.index_of(np.array([1, 2, 3, 4, 5, 6, 64], np.uint8)), [-1, 0, 1, 1, 1, 2, -1])
    np.testing.assert_array_equal(cm.code_of([0, 1, 2]), [2, 5, 6])
    named = ClassMap.parse("ground=2,veg=3+4+5:3,building=6")
    assert named.codes == (2, 3, 6) and named.names == ("ground", "veg", "building")
    assert ClassMap.parse(named.spec()) == named
    assert ClassMap.parse([2, [3, 4, 5], 6]) == cm
    assert cm.without([4, 6]).groups == ((2,), (3, 5))
    for bad, msg in [("2,2", "twice"), ("2,x", "bad class item"), ("2", "at least two"), ("ground=3+4:6,2", "not one of")]:
        with pytest.raises(LidarfxError, match=msg):
            ClassMap.parse(bad)


def test_training_ignores_unlisted_classes_and_merges(facades):
    a, b = facades
    model = train(a, classes="2,5+66,6", classifier="rf", n_estimators=20, **SMALL)
    counts = model.meta["training"]["counts"]["used"]
    assert set(counts) == {"ground", "high vegetation/class 66", "building"}
    pred = model.predict(b)
    assert set(np.unique(pred)) <= {2, 66, 6}  # the merged class gets its highest code
    ref = ClassMap.parse("2,5+66,6").index_of(b["classification"])
    ok = ref >= 0
    acc = (model.classes.index_of(pred)[ok] == ref[ok]).mean()
    assert acc > 0.95


def test_boosting_fit_is_the_same_on_any_number_of_threads(monkeypatch):
    import os

    import lidarfx.classify.model as model_module
    from lidarfx.classify.model import TrainConfig, idle_cores

    cores = len(os.sched_getaffinity(0))
    assert 1 <= idle_cores() <= cores
    monkeypatch.setenv("OMP_NUM_THREADS", "1")  # the user's limit holds
    assert idle_cores() == 1
    monkeypatch.delenv("OMP_NUM_THREADS")
    rng = np.random.default_rng(3)
    X = rng.normal(size=(3000, 12))
    y = (X[:, 0] + X[:, 1] * X[:, 2] > 0).astype(int) + (X[:, 3] > 1)
    one = TrainConfig(n_jobs=1, n_estimators=40).fit_matrix(X, y).predict_proba(X)
    two = TrainConfig(n_jobs=2, n_estimators=40).fit_matrix(X, y).predict_proba(X)
    assert np.array_equal(one, two)
    # the default asks how many cores are idle and fits on that many threads
    from sklearn.ensemble import HistGradientBoostingClassifier
    from threadpoolctl import threadpool_info

    seen = []
    monkeypatch.setattr(model_module, "idle_cores", lambda: 1)  # as if the other cores were busy
    real_fit = HistGradientBoostingClassifier.fit

    def spy(self, *a, **k):
        seen.append([i["num_threads"] for i in threadpool_info() if i["user_api"] == "openmp"])
        return real_fit(self, *a, **k)

    monkeypatch.setattr(HistGradientBoostingClassifier, "fit", spy)
    auto = TrainConfig(n_estimators=40).fit_matrix(X, y).predict_proba(X)
    assert np.array_equal(one, auto)
    assert seen and seen[0] and all(n == 1 for n in seen[0])


# --------------------------------------------------------------------------- folds
def test_block_folds_keep_blocks_whole_random_folds_do_not():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 100, (20000, 2))
    folds, blocks = block_folds(xy, 3, 20.0, seed=1)
    assert blocks.max() + 1 == 25 and set(np.unique(folds)) == {0, 1, 2}
    for b in range(25):
        assert len(np.unique(folds[blocks == b])) == 1  # no block split across folds
    sizes = np.bincount(folds)
    assert sizes.min() > 0.25 * len(xy)  # balanced by points
    rfold = random_folds(len(xy), 3, seed=1)
    split = sum(len(np.unique(rfold[blocks == b])) > 1 for b in range(25))
    assert split == 25  # random folds put every block's points in several folds
    assert not np.array_equal(folds, rfold)
    # a file id keeps blocks of different files apart
    f2, b2 = block_folds(np.vstack([xy, xy]), 3, 20.0, groups=np.repeat([0, 1], len(xy)))
    assert b2.max() + 1 == 50
    with pytest.raises(LidarfxError, match="spatial block"):
        block_folds(xy, 3, 1000.0)
    with pytest.raises(LidarfxError, match="block size"):
        block_folds(xy, 3, -1.0)


@pytest.mark.parametrize("buffer", [0.7, 3.0, 12.5])  # below, at and above the block size (reach 1 and 2)
def test_block_buffer_mask_is_the_distance_to_other_folds_blocks(buffer):
    from lidarfx.classify.evaluate import block_buffer_mask

    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 60, (3000, 2))
    groups = rng.integers(0, 2, len(xy))
    folds, blocks = block_folds(xy, 3, 10.0, seed=0, groups=groups)
    near = block_buffer_mask(xy, folds, 10.0, buffer, groups)
    # brute force: the distance of every point to every block square of another fold in its own file
    bx, by = np.floor(xy / 10.0).T
    want = np.zeros_like(near)
    for b in np.unique(blocks):
        m = blocks == b
        x0, y0, f, grp = bx[m][0] * 10.0, by[m][0] * 10.0, folds[m][0], groups[m][0]
        d = np.hypot(np.maximum(0, np.maximum(x0 - xy[:, 0], xy[:, 0] - x0 - 10.0)),
                     np.maximum(0, np.maximum(y0 - xy[:, 1], xy[:, 1] - y0 - 10.0)))
        want[f] |= (d < buffer) & (folds != f) & (groups == grp)
    np.testing.assert_array_equal(near, want)
    assert near.any() and not near[folds, np.arange(len(xy))].any()  # never the own fold
    assert not block_buffer_mask(xy, folds, 10.0, 0.0, groups).any()


def test_file_buffer_mask_is_the_distance_to_the_held_out_files_points():
    from lidarfx.classify import file_buffer_mask

    rng = np.random.default_rng(4)
    xy = np.vstack([rng.uniform(0, 10, (300, 2)), rng.uniform(0, 10, (300, 2)) + [10.0, 0.0],
                    rng.uniform(0, 10, (300, 2)) + [40.0, 0.0]])  # two adjacent tiles and a far one
    files = np.repeat([0, 1, 2], 300)
    near = file_buffer_mask(xy, files, 1.5)
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))  # all pairwise distances
    for f in range(3):
        want = (d[:, files == f] < 1.5).any(axis=1) & (files != f)
        np.testing.assert_array_equal(near[f], want)
    assert near[0].any() and near[1].any() and not near[2].any() and not near[:, files == 2].any()
    assert not file_buffer_mask(xy, files, 0.0).any()


def test_cross_validate_leaves_the_buffer_out_of_training():
    from lidarfx.classify.evaluate import block_buffer_mask, cross_validate

    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 80, (4000, 2))
    y = (xy[:, 0] > 40).astype(np.int64) + (xy[:, 1] > 40)  # three classes by place
    X = np.column_stack([np.arange(len(xy)), xy, rng.normal(size=len(xy))]).astype(np.float32)
    folds, _ = block_folds(xy, 3, 10.0, seed=0)
    near = block_buffer_mask(xy, folds, 10.0, 2.0)
    cfg = TrainConfig(features="planarity", radii=[1.0], classifier="nb", max_per_class=None,
                      terrain_augment=0)
    seen = []
    fit = cfg.fit_matrix
    cfg.fit_matrix = lambda Xf, yf, *a, **k: (seen.append(Xf[:, 0].astype(np.int64)), fit(Xf, yf))[1]
    cm, per_fold, _ = cross_validate(X, y, folds, cfg, 3, exclude=near)
    assert cm.sum() == len(y)  # every point is tested once
    for f, rows, pf in zip(range(3), seen, per_fold):
        assert not near[f, rows].any() and not (folds[rows] == f).any()
        want = int((near[f] & (folds != f)).sum())
        assert pf["buffer_excluded"] == want > 0
        assert pf["train_points"] == int((folds != f).sum()) - want


def test_random_folds_are_stratified():
    y = np.repeat([0, 1, 2], [300, 60, 30])
    f = random_folds(len(y), 3, seed=0, y=y)
    for k in range(3):
        assert np.bincount(y[f == k]).tolist() == [100, 20, 10]


# --------------------------------------------------------------------------- classifiers on synthetic scenes
def test_facade_rf_and_nb_reach_stated_accuracy(facades, rf_model):
    a, b = facades
    ref = rf_model.classes.index_of(b["classification"])
    ok = ref >= 0
    acc_rf = (rf_model.classes.index_of(rf_model.predict(b))[ok] == ref[ok]).mean()
    assert acc_rf > 0.95  # measured 0.98
    nb = train(a, classes=FACADE6, classifier="nb", **SMALL)
    acc_nb = (nb.classes.index_of(nb.predict(b))[ok] == ref[ok]).mean()
    assert acc_nb > 0.85  # measured 0.93
    assert acc_rf > acc_nb


def test_sklearn_pipeline_and_tools(facades):
    from sklearn.base import clone
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.model_selection import cross_val_score

    a, _ = facades
    cmap = ClassMap.parse(FACADE6)
    y_all = cmap.index_of(a["classification"])
    idx = np.flatnonzero(y_all >= 0)[::5]
    pipe = make_pipeline("eigen,height", [0.3, 0.5], "rf", n_estimators=20)
    pipe.fit(CloudSample(a, idx), y_all[idx])
    names = pipe.named_steps["features"].get_feature_names_out()
    assert "planarity_r0.30" in names and "dz_below_r0.50" in names and len(names) == 36
    assert clone(pipe).get_params()["features__radii"] == [0.3, 0.5]
    # the transformer's matrix works with scikit-learn's own tools
    X = LidarFeatures("eigen,height", [0.3, 0.5]).fit().transform(CloudSample(a, idx))
    assert X.shape == (len(idx), 36) and X.dtype == np.float32
    scores = cross_val_score(RandomForestClassifier(20, random_state=0), np.nan_to_num(X), y_all[idx], cv=3)
    assert scores.mean() > 0.9
    pred = pipe.predict(CloudSample(a, idx[:100]))
    assert pred.shape == (100,)
    # single radius: names still carry the scale
    assert LidarFeatures("planarity", [0.5]).get_feature_names_out().tolist() == ["planarity_r0.50"]


def test_sample_features_equal_full_cloud_features(facades):
    a, _ = facades
    idx = np.arange(0, len(a), 97)
    tr = LidarFeatures("eigen,histogram", [0.3, 0.5]).fit()
    np.testing.assert_array_equal(tr.transform(CloudSample(a, idx)), tr.transform(a)[idx])


def test_usable_mask_drops_virtual_points():
    c = lidarfx.PointCloud(np.random.default_rng(0).random((5, 3)),
                           {"return_number": np.array([1, 0, 2, 1, 0], np.uint8)})
    np.testing.assert_array_equal(usable_mask(c), [True, False, True, True, False])
    c2 = lidarfx.PointCloud(np.zeros((3, 3)), {"return_number": np.zeros(3, np.uint8)})
    assert usable_mask(c2).all()  # no return information at all: every point counts


def test_height_above_ground_is_capped():
    rng = np.random.default_rng(0)
    g = np.column_stack([rng.uniform(0, 30, 6000), rng.uniform(0, 30, 6000), rng.normal(0, 0.02, 6000)])
    box = np.column_stack([rng.uniform(10, 14, 2000), rng.uniform(10, 14, 2000), rng.uniform(0.5, 12, 2000)])
    c = lidarfx.PointCloud(np.vstack([g, box]))
    h = LidarFeatures(["height_above_ground"], []).fit().transform(c)[:, 0]
    assert h.max() == pytest.approx(5.0) and np.median(np.abs(h[:6000])) < 0.1
    raw = LidarFeatures(["height_above_ground"], [], hag_cap=None).fit().transform(c)[:, 0]
    assert raw.max() > 11


FOOT_WKT = (
    'PROJCS["NAD83 / test (ftUS)",GEOGCS["NAD83",DATUM["North_American_Datum_1983",'
    'SPHEROID["GRS 1980",6378137,298.257222101]],UNIT["degree",0.0174532925199433]],'
    'PROJECTION["Transverse_Mercator"],UNIT["US survey foot",0.3048006096012192]]'
)


def test_features_are_metres_on_a_feet_cloud(tmp_path, facades):
    """A cloud in US feet (CRS unit) gives the features of the same cloud in metres:
    radii, thinning density, HAG and its cap are metres whatever the coordinate unit."""
    import laspy

    a, _ = facades
    u = 0.3048006096012192
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.zeros(3)
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(FOOT_WKT))
    las = laspy.LasData(header)
    ft = a.xyz / u
    las.x, las.y, las.z = ft[:, 0], ft[:, 1], ft[:, 2]
    las.classification = a["classification"]
    las.write(tmp_path / "feet.las")
    feet = lidarfx.read(tmp_path / "feet.las")
    assert lidarfx.ground.cloud_crs(feet)["unit_to_metre"] == pytest.approx(u)
    metres = lidarfx.PointCloud(feet.xyz * u, {"classification": feet["classification"]})
    # thinned (150 pts/m² > 20 / (π 0.3²) = 71 pts/m²): the density is compared in m² too
    tr = LidarFeatures("eigen,plane,histogram,height_above_ground", [0.3, 0.5], max_disc_points=20).fit()
    names = list(tr.get_feature_names_out())
    idx = np.arange(0, len(feet), 13)
    xf, xm = tr.transform(CloudSample(feet, idx)), tr.transform(CloudSample(metres, idx))
    h = names.index("height_above_ground")
    geo = [i for i in range(len(names)) if i != h]
    np.testing.assert_allclose(xf[:, geo], xm[:, geo], rtol=1e-4, atol=1e-5, equal_nan=True)
    # HAG: the same SMRF ground (its parameters are converted to feet), heights in metres
    assert np.mean(np.abs(xf[:, h] - xm[:, h]) < 0.01) > 0.99
    assert np.nanmax(xf[:, h]) == pytest.approx(5.0)
    # spatial blocks are metres too: 4 m blocks of the feet cloud = those of the metre cloud
    from lidarfx.classify.evaluate import _file_features
    from lidarfx.classify.model import Source, TrainConfig, resolve_classes

    cfg = TrainConfig(features=["linearity"], radii=[0.5])
    srcs = [Source("f", feet, np.ones(len(feet), bool), len(feet)),
            Source("m", metres, np.ones(len(metres), bool), len(metres))]
    cmap = resolve_classes(srcs[:1], FACADE6)
    _, _, xy_f, _ = _file_features(srcs[:1], cmap, cfg, False)
    _, _, xy_m, _ = _file_features(srcs[1:], cmap, cfg, False)
    np.testing.assert_array_equal(block_folds(xy_f, 3, 4.0)[1], block_folds(xy_m, 3, 4.0)[1])
    # precomputed features would be in feet: refused
    with pytest.raises(LidarfxError, match="precomputed"):
        LidarFeatures("linearity", [0.5], precomputed=True).fit().transform(feet)


@pytest.mark.parametrize("n_classes", [2, 3])
def test_fast_boosting_prediction_equals_sklearn(n_classes):
    """The numba tree walker gives scikit-learn's raw scores, probabilities and classes
    exactly — NaN inputs (missing values sent left or right) included."""
    from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
    from sklearn.pipeline import Pipeline

    from lidarfx.classify.fastpredict import FastBoosting, fast_estimator, predict, predict_proba

    rng = np.random.default_rng(n_classes)
    X = rng.normal(size=(3000, 6)).astype(np.float32)
    y = (X[:, 0] + 0.5 * X[:, 1] ** 2 > 0.4).astype(int) + (n_classes == 3) * (X[:, 2] > 1.0)
    X[rng.random(X.shape) < 0.05] = np.nan
    clf = HistGradientBoostingClassifier(max_iter=40, random_state=0).fit(X, y * 2 + 1)  # classes 1, 3(, 5)
    pipe = Pipeline([("impute", "passthrough"), ("classifier", clf)])
    fast = fast_estimator(pipe)
    assert isinstance(fast, FastBoosting)
    Xt = rng.normal(size=(5000, 6)).astype(np.float32)
    Xt[rng.random(Xt.shape) < 0.1] = np.nan
    np.testing.assert_array_equal(fast.raw(Xt), clf._raw_predict(Xt))
    np.testing.assert_array_equal(predict_proba(pipe, Xt), clf.predict_proba(Xt))
    np.testing.assert_array_equal(predict(pipe, Xt), clf.predict(Xt))
    assert set(np.unique(predict(pipe, Xt))) <= {1, 3, 5}
    # permutation importance through the walker: scikit-learn's own numbers
    from sklearn.inspection import permutation_importance as sk_pi

    yt = clf.predict(np.nan_to_num(Xt[:800]))
    ours = permutation_importance(pipe, Xt[:800], yt, n_repeats=2, seed=3)
    ref = sk_pi(pipe, Xt[:800], yt, n_repeats=2, scoring="f1_macro", random_state=3)
    assert {d["name"]: d["mean"] for d in ours} == {str(i): float(v) for i, v in enumerate(ref.importances_mean)}
    assert ours[0]["mean"] > 0.05  # the informative columns matter
    # anything else goes to scikit-learn
    rf = RandomForestClassifier(n_estimators=5, random_state=0).fit(np.nan_to_num(X), y)
    assert fast_estimator(rf) is None
    np.testing.assert_array_equal(predict(rf, np.nan_to_num(Xt)), rf.predict(np.nan_to_num(Xt)))


# --------------------------------------------------------------------------- model files
def test_model_roundtrip_identical_predictions(tmp_path, facades, rf_model):
    _, b = facades
    path = rf_model.save(tmp_path / "m.skops")
    loaded = load_model(path)
    np.testing.assert_array_equal(loaded.predict(b), rf_model.predict(b))
    assert loaded.feature_names == rf_model.feature_names and loaded.radii == [0.3, 0.5]
    assert loaded.meta["lidarfx_version"] == lidarfx.__version__
    assert loaded.classes == rf_model.classes
    out = loaded.classify(b, confidence=True)
    assert out["classification"].dtype == np.uint8 and np.nanmin(out["confidence"]) > 0


@pytest.mark.parametrize("kind", ["hgb", "nb"])
def test_model_roundtrip_other_classifiers(tmp_path, facades, kind):
    a, b = facades
    m = train(a, classes="2,5,6", classifier=kind, n_estimators=30 if kind != "nb" else None, features="eigen",
              radii=[0.5], max_per_class=500)
    loaded = load_model(m.save(tmp_path / f"{kind}.skops"))
    np.testing.assert_array_equal(loaded.predict(b), m.predict(b))
    # boosting predicts through the numba tree walker, with scikit-learn's exact answers
    assert (loaded._fast() is not None) == (kind == "hgb")
    X = loaded.feature_matrix(b)
    codes, conf = loaded.predict(b, return_confidence=True)
    np.testing.assert_array_equal(codes, loaded.classes.code_of(loaded.estimator.predict(X)))
    np.testing.assert_array_equal(conf, loaded.estimator.predict_proba(X).max(axis=1).astype(np.float32))


def test_model_files_with_settings_once_ignored_still_load(tmp_path, facades):
    import skops.io as sio

    a, _ = facades
    m = train(a, classes="2,5,6", classifier="nb", features="eigen", radii=[0.5], max_per_class=300)
    path = m.save(tmp_path / "nb.skops")
    obj = sio.load(path, trusted=sio.get_untrusted_types(file=path))
    obj["meta"]["config"].update(n_estimators=50, k=10)  # what a model written before they were refused may hold
    sio.dump(obj, path)
    old = load_model(path)
    np.testing.assert_array_equal(old.predict(facades[1]), m.predict(facades[1]))
    with pytest.raises(LidarfxError, match="for classifier 'nb'"):
        TrainConfig(**{**m.meta["config"], "n_estimators": 50})


class Evil:
    """Stands for any type a model file must not make lidarfx build."""

    def __init__(self):
        self.payload = "rm -rf /"


def test_model_file_with_unknown_type_is_refused(tmp_path, rf_model):
    import skops.io as sio
    from sklearn.svm import SVC

    good = rf_model.save(tmp_path / "good.skops")
    obj = sio.load(good, trusted=sio.get_untrusted_types(file=good))
    for name, payload in [("evil", Evil()), ("svc", SVC())]:  # SVC is trusted by skops' defaults, not by lidarfx
        obj["classifier"] = payload
        bad = tmp_path / f"{name}.skops"
        sio.dump(obj, bad)
        with pytest.raises(LidarfxError, match="refusing to load"):
            load_model(bad)
    (tmp_path / "junk.skops").write_bytes(b"not a zip")
    with pytest.raises(LidarfxError, match="not a skops model"):
        load_model(tmp_path / "junk.skops")
    with pytest.raises(LidarfxError, match="not found"):
        load_model(tmp_path / "none.skops")


def test_edited_feature_list_is_refused(tmp_path, rf_model):
    path = rf_model.save(tmp_path / "m.skops")
    edited = tmp_path / "edited.skops"
    with zipfile.ZipFile(path) as zin, zipfile.ZipFile(edited, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "schema.json":
                data = data.replace(b'planarity_r0.30', b'planarity_r0.40')
            zout.writestr(item, data)
    with pytest.raises(LidarfxError, match="feature list does not match"):
        load_model(edited)


def test_model_refuses_cloud_missing_a_feature(tmp_path, capsys):
    rng = np.random.default_rng(0)
    n = 3000
    xyz = np.column_stack([rng.uniform(0, 20, n), rng.uniform(0, 20, n), rng.uniform(0, 1, n)])
    cls = np.where(xyz[:, 2] > 0.5, 5, 2).astype(np.uint8)
    nr = np.where(cls == 5, 2, 1).astype(np.uint8)
    cloud = lidarfx.PointCloud(xyz, {"classification": cls, "return_number": np.ones(n, np.uint8), "number_of_returns": nr})
    model = train(cloud, classes="2,5", classifier="rf", n_estimators=10,
                  features="planarity,number_of_returns", radii=[1.0])
    bare = lidarfx.PointCloud(xyz)
    with pytest.raises(LidarfxError, match="number_of_returns"):
        model.predict(bare)
    with pytest.raises(LidarfxError, match="empty: no points to classify"):  # not "no number_of_returns"
        model.predict(cloud.subset(np.zeros(n, bool)))
    empty = tmp_path / "empty.laz"
    lidarfx.write(cloud.subset(np.zeros(n, bool)), empty)
    model.save(tmp_path / "m.skops")
    assert main(["classify", "predict", str(empty), str(tmp_path / "o.laz"), "--model", str(tmp_path / "m.skops"),
                 "-q"]) == 2
    assert not (tmp_path / "o.laz").exists()
    capsys.readouterr()
    assert main(["classify", "train", str(empty), "--model", str(tmp_path / "e.skops"), "-q"]) == 2
    assert main(["classify", "evaluate", str(empty), "--model", str(tmp_path / "m.skops"), "-q"]) == 2
    assert capsys.readouterr().err.count("empty.laz: no usable points") == 2
    assert not (tmp_path / "e.skops").exists()
    # precomputed features at the wrong radius
    model.features.precomputed = True
    wrong = lidarfx.compute_features(cloud, "planarity", radii=[0.5, 2.0])
    with pytest.raises(LidarfxError, match=r"planarity_r1\.00.*radii 1 m"):
        model.predict(wrong)
    right = lidarfx.compute_features(cloud, "planarity", radii=[1.0, 2.0])
    model.features.precomputed = False
    ref = model.predict(cloud)
    model.features.precomputed = True
    np.testing.assert_array_equal(model.predict(right), ref)
    # the refusal names a command that writes every feature the model reads (the helper's hint
    # said only "--features ..."); run as printed, its output predicts like the model itself
    multi = train(cloud, classes="2,5", classifier="rf", n_estimators=10,
                  features="planarity,plane_std,dh_peaks,number_of_returns", radii=[1.0, 2.0])
    src = tmp_path / "src.laz"
    lidarfx.write(cloud, src)
    multi.features.precomputed = True
    with pytest.raises(LidarfxError) as err:
        multi.predict(lidarfx.read(src))
    cmd = str(err.value).split("compute them with: ")[1].split(" (or predict")[0]
    assert cmd == "lidarfx features IN OUT -r 1 -r 2 --features eigen,plane,histogram"
    fx = tmp_path / "fx.laz"
    assert main(["features", str(src), str(fx), *cmd.split()[4:], "-q"]) == 0
    pre = multi.predict(lidarfx.read(fx))
    multi.features.precomputed = False
    np.testing.assert_array_equal(pre, multi.predict(lidarfx.read(src)))
    # one radius: lidarfx features writes no suffix, and the hint says so
    model.features.precomputed = True
    with pytest.raises(LidarfxError, match=r"-r 1 --features eigen and add the suffix _r1\.00 to their names"):
        model.predict(wrong)


# --------------------------------------------------------------------------- evaluation
def test_evaluate_random_vs_blocks_and_report(tmp_path, facades):
    from lidarfx.classify import write_report

    a, b = facades
    # the two scenes are scans of the same house: a buffer around one would leave no training in the other
    with pytest.raises(LidarfxError, match="the files overlap"):
        evaluate([a, b], cv=None, leave_one_out=True, classes=FACADE6, **SMALL)
    rep = evaluate([a, b], test=[b], cv=3, block_size=4.0, leave_one_out=True, classes=FACADE6,
                   classifier="rf", n_estimators=20, importance=True, buffer=0, **SMALL)
    sec = rep["sections"]
    assert set(sec) == {"cv_random", "cv_blocks", "leave_one_file_out", "test"}
    r, bl = sec["cv_random"]["metrics"], sec["cv_blocks"]["metrics"]
    assert r["points"] == bl["points"] == sec["leave_one_file_out"]["metrics"]["points"]
    assert r["oa"] > bl["oa"] > 0.85  # random folds leak neighbours: optimistic
    assert sec["test"]["metrics"]["oa"] > 0.9
    assert rep["importance"]["impurity"][0]["importance"] >= rep["importance"]["impurity"][-1]["importance"]
    files = write_report(rep, tmp_path / "rep")
    names = {p.name for p in files}
    assert {"report.txt", "report.json", "confusion_cv_random.png", "confusion_cv_blocks.png", "importance.png"} <= names
    assert "backward_elimination.png" not in names  # not asked for
    assert (tmp_path / "rep" / "importance.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    js = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert js["layout"] == "rows = reference, columns = predicted"
    assert js["sections"]["cv_blocks"]["metrics"]["confusion"] == bl["confusion"]
    assert (tmp_path / "rep" / "confusion_cv_blocks.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    txt = (tmp_path / "rep" / "report.txt").read_text()
    assert "rows = reference, columns = predicted" in txt and "spatial blocks of 4 m" in txt
    assert sec["cv_blocks"]["buffer"] == 0 and "buffer_excluded" not in sec["cv_blocks"]["folds"][0]


def test_evaluate_buffers_blocks_and_neighbouring_files(facades):
    from scipy.spatial import cKDTree

    from lidarfx.classify import format_report

    a, _ = facades
    west, east = a.subset(a.x < 6.0), a.subset(a.x >= 6.0)  # two adjacent "tiles"
    rep = evaluate([west, east], cv=3, block_size=4.0, random_cv=False, leave_one_out=True, classes=FACADE6,
                   classifier="nb", **SMALL)
    bl, lo = rep["sections"]["cv_blocks"], rep["sections"]["leave_one_file_out"]
    # the default buffer is twice the largest radius (0.5 m)
    assert bl["buffer"] == lo["buffer"] == 1.0 and "buffer 1 m" in bl["title"] and "buffer 1 m" in lo["title"]
    assert all(pf["buffer_excluded"] > 0 for pf in bl["folds"])
    # leave one file out drops the other tile's strip within 1 m of the held-out tile
    cmap = ClassMap.parse(FACADE6)
    labelled = [np.flatnonzero(cmap.index_of(c["classification"]) >= 0) for c in (west, east)]
    for pf, (i_h, i_o), (held, other) in zip(lo["folds"], ((0, 1), (1, 0)), ((west, east), (east, west))):
        d, _ = cKDTree(held.xyz[labelled[i_h], :2]).query(other.xyz[labelled[i_o], :2])
        assert pf["buffer_excluded"] == int((d < 1.0).sum()) > 0
    txt = format_report(rep)
    assert "training points within 1 m of the held-out file are left out" in txt


def test_evaluate_checks_the_folds_before_the_features(facades, monkeypatch):
    import sys

    E = sys.modules["lidarfx.classify.evaluate"]  # the package's `evaluate` is the function

    def no_features(*a, **k):
        raise AssertionError("features computed before the fold check")

    monkeypatch.setattr(E, "file_features", no_features)
    with pytest.raises(LidarfxError, match="spatial block"):
        evaluate([facades[0]], classes=FACADE6, cv=5, block_size=1000.0, **SMALL)  # 4 blocks (x, y straddle 0)


def test_importance_and_backward_elimination(facades):
    a, _ = facades
    cmap = ClassMap.parse("2,5,6,64")
    y = cmap.index_of(a["classification"])
    idx = np.flatnonzero(y >= 0)[::4]
    cfg = TrainConfig(features="planarity,verticality,z_range,sphericity", radii=[0.5], classifier="rf",
                      n_estimators=20)
    X = cfg.transformer().transform(CloudSample(a, idx))
    rng = np.random.default_rng(0)
    X = np.hstack([X, rng.normal(size=(len(idx), 1)).astype(np.float32)])  # a pure-noise feature
    names = cfg.feature_names() + ["noise"]
    est = TrainConfig(**{**cfg.to_dict()}).fit_matrix(X[:, :4], y[idx])
    imp = impurity_importance(est, names[:4])
    assert len(imp) == 4 and imp[0]["importance"] >= imp[-1]["importance"]
    perm = permutation_importance(est, X[:, :4], y[idx], names[:4], n_repeats=2)
    assert perm[0]["mean"] > 0.01
    folds, _ = block_folds(a.xyz[idx, :2], 3, 4.0)
    be = backward_elimination(X, y[idx], names, folds, step=0.2, n_estimators=20)
    ns = [s["n_features"] for s in be["steps"]]
    assert ns == sorted(ns, reverse=True) and ns[-1] == 1
    assert "noise" in be["steps"][0]["removed"]  # the noise column goes first
    assert be["best"]["mean_f1"] >= max(s["mean_f1"] for s in be["steps"]) - be["tolerance"]


@pytest.mark.parametrize("degrees", [5.0, 25.0, 40.0])
def test_terrain_slope_of_tilted_ground(degrees):
    from lidarfx.classify.evaluate import terrain_slope

    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 80, (20_000, 2))
    z = np.tan(np.radians(degrees)) * xy[:, 0] + rng.normal(0, 0.02, len(xy))
    s = terrain_slope(lidarfx.PointCloud(np.c_[xy, z]))
    inner = ((xy > 5) & (xy < 75)).all(axis=1)
    assert abs(np.median(s[inner]) - degrees) < 0.3
    assert np.all(np.abs(np.percentile(s[inner], [5, 95]) - degrees) < 1.5)
    assert terrain_slope(lidarfx.PointCloud(np.zeros((0, 3)))).shape == (0,)


def test_by_slope_needs_test_files(facades):
    with pytest.raises(LidarfxError, match="by_slope breaks down the results on test files"):
        evaluate([facades[0]], classes=FACADE6, cv=3, by_slope=True, **SMALL)


def test_slope_confusions_bins():
    from lidarfx.classify.evaluate import SLOPE_BINS, slope_confusions

    y = np.array([0, 0, 1, 1, 0, -1, 0, 1])
    pred = np.array([0, 1, 1, 1, 0, 0, 0, 0])
    slope = np.array([0.0, 9.99, 10.0, 29.0, 45.0, 50.0, 90.0, np.nan], dtype=np.float32)
    cms = slope_confusions(y, pred, slope, 2)
    assert cms.shape == (len(SLOPE_BINS) - 1, 2, 2)
    assert cms[0].tolist() == [[1, 1], [0, 0]]  # 0 and 9.99
    assert cms[1].tolist() == [[0, 0], [0, 1]]  # 10 opens the second class
    assert cms[2].tolist() == [[0, 0], [0, 1]]
    assert cms[4].tolist() == [[2, 0], [0, 0]]  # 45 and 90 (the last class includes 90); unlabelled and NaN left out
    assert cms.sum() == 6


def test_importance_and_elimination_pictures(tmp_path):
    import matplotlib.image as mpimg

    from lidarfx.classify import plot_elimination, plot_importance, write_report

    imp = {"impurity": [{"name": f"f{i}", "importance": 1.0 / (i + 1)} for i in range(30)],
           "impurity_model": "random forest"}
    p = plot_importance(imp, tmp_path / "imp1.png", top=5)  # impurity only: one panel
    w1 = mpimg.imread(p).shape[1]
    imp["permutation"] = [{"name": f"f{i}", "mean": 0.1 - 0.01 * i, "std": 0.005} for i in range(8)]
    w2 = mpimg.imread(plot_importance(imp, tmp_path / "imp2.png", top=5)).shape[1]
    assert w2 > 1.8 * w1  # two panels
    be = {"steps": [{"n_features": n, "oa": 0.9 + 0.001 * n, "mean_f1": 0.88 + 0.001 * n, "features": [],
                     "removed": []} for n in (10, 9, 8, 7, 6, 5, 4, 3, 2, 1)], "tolerance": 0.005}
    be["best"] = be["steps"][5]
    assert plot_elimination(be, tmp_path / "be.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the report writer draws both when the report has them, and nothing is left half-written
    rep = {"sections": {}, "importance": imp, "backward_elimination": be, "features": ["f0"], "train_files": [],
           "config": {"classifier": "rf", "radii": [1.0], "max_per_class": 100}}
    names = sorted(p.name for p in write_report(rep, tmp_path / "out"))
    assert names == ["backward_elimination.png", "importance.png", "report.json", "report.txt"]
    assert sorted(f.name for f in (tmp_path / "out").iterdir()) == names


# --------------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def facade_files(tmp_path_factory, facades):
    d = tmp_path_factory.mktemp("clf")
    a, b = facades
    pa, pb = d / "a.laz", d / "b.laz"
    lidarfx.write(a, pa)
    lidarfx.write(b, pb)
    return d, pa, pb


CLI_MODEL = ["--classes", FACADE6, "--features", "eigen,height,plane", "-r", "0.3", "-r", "0.5",
             "--classifier", "rf", "--n-estimators", "20", "--max-per-class", "2000", "-q"]


def test_cli_train_predict_evaluate(facade_files, capsys):
    d, pa, pb = facade_files
    model = d / "m.skops"
    assert main(["classify", "train", str(pa), "--model", str(model), *CLI_MODEL, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["features"] == 52 and summary["radii"] == [0.3, 0.5]  # (14 eigen + 4 height + 8 plane) x 2
    assert summary["min_building_area"] == 0.0  # own features (a TLS facade): no small-building rule
    out = d / "b_pred.laz"
    assert main(["classify", "predict", str(pb), str(out), "--model", str(model), "--confidence", "-q",
                 "--picture", str(d / "b_classes.png"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["picture"] == str(d / "b_classes.png")
    assert (d / "b_classes.png").stat().st_size > 1000
    pred = lidarfx.read(out)
    ref = lidarfx.read(pb)["classification"]
    ok = ref != 7
    assert (pred["classification"][ok] == ref[ok]).mean() > 0.95
    assert pred["confidence"].dtype == np.float32
    assert main(["classify", "predict", str(pb), str(d / "b_prob.laz"), "--model", str(model), "--probabilities",
                 "-q", "--json"]) == 0
    names = {f"probability_{n}": n for n in ("ground", "vegetation", "wall", "roof", "window", "clutter")}
    js = json.loads(capsys.readouterr().out)
    assert js["probabilities"] == names and js["upgraded_point_format"] is None  # a LAS 1.4 input
    prob = lidarfx.read(d / "b_prob.laz")
    assert all(prob[n].dtype == np.float32 for n in names) and "confidence" not in prob
    np.testing.assert_allclose(sum(prob[n] for n in names), 1.0, atol=1e-5)
    np.testing.assert_array_equal(prob["classification"], pred["classification"])
    # a legacy point format stores classes 0-31 only: codes 64-66 make predict write LAS 1.4 format 6, and say so
    legacy = lidarfx.read(pb)
    legacy["classification"] = np.ones(len(legacy), np.uint8)
    lidarfx.write(legacy, d / "b_pf1.las", point_format=1)
    assert main(["classify", "predict", str(d / "b_pf1.las"), str(d / "b_pf1_pred.laz"), "--model", str(model),
                 "--json"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["upgraded_point_format"] == 6
    assert "writing LAS 1.4 point format 6" in cap.err
    up = lidarfx.read(d / "b_pf1_pred.laz")
    assert up.header.point_format.id == 6 and up["classification"].max() > 31
    np.testing.assert_array_equal(up["classification"], pred["classification"])
    capsys.readouterr()
    assert main(["classify", "evaluate", str(pb), "--model", str(model), "--out", str(d / "ev"), "--json", "-q",
                 "--by-slope"]) == 0
    rep = json.loads(capsys.readouterr().out)
    rows = rep["sections"]["test"]["files"][str(pb)]["by_slope"]
    assert [r["slope_deg"] for r in rows] == [[0, 10], [10, 20], [20, 30], [30, 45], [45, 90]]
    assert sum(r["points"] for r in rows) == rep["sections"]["test"]["metrics"]["points"]  # every point has a slope
    assert rep["sections"]["test"]["metrics"]["by_slope"] == rows  # one file: pooled = the file
    from lidarfx.classify import format_report

    assert "by terrain slope" in format_report(rep)
    ci = rep["sections"]["test"]["metrics"]["ci"]  # the default 1000 block resamples, 20 m blocks
    assert ci["resamples"] == 1000 and ci["block_size"] == 20.0 and ci["blocks"] >= 2
    assert ci["oa"][0] <= rep["sections"]["test"]["metrics"]["oa"] <= ci["oa"][1]
    assert "95% interval (bootstrap of" in format_report(rep)
    assert rep["sections"]["test"]["metrics"]["oa"] > 0.95
    assert (d / "ev" / "confusion_test.png").is_file()
    fb = rep["sections"]["test"]["files"][str(pb)]
    assert fb["error_map"] == str(d / "ev" / "errors_b.png") and (d / "ev" / "errors_b.png").is_file()
    cm = np.array(fb["confusion"])
    off = cm - np.diag(np.diag(cm))
    counts = list(fb["error_pairs"].values())
    assert counts == sorted(counts, reverse=True) and counts[0] == off.max()  # the largest off-diagonal cell first
    assert sum(counts) == off.sum() if (off > 0).sum() <= 8 else sum(counts) < off.sum()  # at most 8 pairs named
    assert main(["classify", "evaluate", str(pa), "--cv", "2", "--spatial-blocks", "5", *CLI_MODEL, "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    for key in ("cv_random", "cv_blocks"):  # every section has its block-bootstrap interval (5 m blocks)
        m = rep["sections"][key]["metrics"]
        assert m["ci"]["block_size"] == 5.0 and m["ci"]["oa"][0] <= m["oa"] <= m["ci"]["oa"][1]
    assert main(["classify", "evaluate", str(pa), "--cv", "2", "--spatial-blocks", "5", *CLI_MODEL,
                 "--bootstrap", "0"]) == 0
    txt = capsys.readouterr().out
    assert "random folds" in txt and "spatial blocks of 5 m" in txt and "OA" in txt and "interval" not in txt


@pytest.mark.parametrize(
    "args,message",
    [
        (["train", "{a}", "--model", "{d}/x.skops", "--features", "planarty"], "unknown feature 'planarty'"),
        (["train", "{a}", "--model", "{d}/x.skops", "--classes", "2,2"], "twice"),
        (["train", "{a}", "--model", "{d}/x.pkl", "--classes", "2,6"], "should end in .skops"),
        (["predict", "{a}", "{d}/o.laz", "--model", "{d}/none.skops"], "not found"),
        (["predict", "{a}", "{d}/o.laz", "--model", "{d}/none.skops", "--picture", "{d}/map.jpg"], "PNG files"),
        (["predict", "{a}", "{d}/o.laz", "--model", "{d}/none.skops", "--picture", "{d}/no/map.png"],
         "folder does not exist"),
        (["evaluate", "{a}", "--cv", "1"], "at least 2 folds"),
        (["evaluate", "{a}", "--by-slope"], "--by-slope breaks down the results on test files"),
        # options the configuration would ignore are refused
        (["train", "{a}", "--model", "{d}/x.skops", "--classifier", "nb", "--n-estimators", "50"],
         "got 50 for classifier 'nb'"),
        (["train", "{a}", "--model", "{d}/x.skops", "--features", "eigen", "-r", "0.5", "-k", "10"],
         "is for the 'knn' neighbourhood"),
        # a trained model brings its own classes, features and settings: training options are refused, not ignored
        (["evaluate", "{a}", "--model", "{d}/none.skops", "--classes", "2,6", "--importance"],
         "it does not take --classes, --importance"),
        (["evaluate", "{a}", "--model", "{d}/none.skops", "--cv", "3", "-r", "2"], "it does not take --cv, --radius"),
        (["train", "{a}", "--model", "{d}/x.skops", "--classes", "2,99", "--features", "eigen", "-r", "0.5"],
         "no training points of 'class 99' (the usable points hold the classes [2, 5, 6, 7, 64, 65, 66]"),
        (["train", "{a}", "--model", "{d}/x.skops", "--density-augment", "0.5,2"], "between 0 and 1"),
        (["evaluate", "{a}", "--classes", "2,6", "--features", "eigen", "-r", "0.5", "--spatial-blocks", "5000",
          "--cv", "5", "--no-random-folds"], "spatial block"),  # the scene straddles x = 0, y = 0: 4 blocks
    ],
)
def test_cli_errors_exit_2(facade_files, capsys, args, message):
    d, pa, _ = facade_files
    argv = ["classify"] + [s.format(a=pa, d=d) for s in args] + ["-q"]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_cli_refuses_tampered_model(facade_files, tmp_path, capsys):
    import skops.io as sio

    d, pa, pb = facade_files
    model = tmp_path / "m.skops"
    assert main(["classify", "train", str(pa), "--model", str(model), *CLI_MODEL]) == 0
    obj = sio.load(model, trusted=sio.get_untrusted_types(file=model))
    obj["impute"] = Evil()
    sio.dump(obj, model)
    assert main(["classify", "predict", str(pb), str(tmp_path / "o.laz"), "--model", str(model), "-q"]) == 2
    assert "refusing to load" in capsys.readouterr().err


def test_density_warning_api(facades, rf_model):
    import warnings

    from lidarfx.classify.model import DENSITY_WARN_RATIO, ClassifierModel, cloud_density
    from lidarfx.classify.pipeline import point_density
    from lidarfx.errors import LidarfxWarning

    a, b = facades
    files = rf_model.meta["training"]["files"]
    assert files[0]["density"] == pytest.approx(point_density(a.xyz), rel=1e-3)
    assert rf_model.training_density == pytest.approx(files[0]["density"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the second scene has the training density: no warning
        info = rf_model.density_check(b)
    assert 0.8 < info["ratio"] < 1.25 and info["density"] == pytest.approx(cloud_density(b), abs=0.01)
    sparse = b.subset(np.random.default_rng(0).random(len(b)) < 0.3)  # 30 % of the points
    with pytest.warns(LidarfxWarning, match=r"points/m² is \d+% of the sparsest training file"):
        codes = rf_model.predict(sparse)
    assert len(codes) == len(sparse)
    info = rf_model.density_check(sparse, warn=False)
    assert info["ratio"] < DENSITY_WARN_RATIO and info["ratio"] == pytest.approx(0.3, abs=0.05)
    old = ClassifierModel(rf_model.pipeline, rf_model.classes, {**rf_model.meta, "training": {"files": []}})
    assert old.density_check(sparse) is None  # models without a recorded density: no check


def test_cli_density_warning_names_the_file_as_typed(facades, rf_model, tmp_path, monkeypatch, capsys):
    sparse = facades[1].subset(np.random.default_rng(0).random(len(facades[1])) < 0.3)
    lidarfx.write(sparse, tmp_path / "sparse.laz")
    rf_model.save(tmp_path / "m.skops")
    monkeypatch.chdir(tmp_path)
    assert main(["classify", "predict", "sparse.laz", "out.laz", "--model", "m.skops", "-q"]) == 0
    err = capsys.readouterr().err
    assert "warning: sparse.laz: " in err and str(tmp_path) not in err


def test_pulse_thinning_keeps_whole_pulses():
    from lidarfx.classify.pipeline import pulse_thinning_mask

    rng = np.random.default_rng(3)
    n_pulses = 20_000
    returns = rng.integers(1, 4, n_pulses)  # 1-3 returns per pulse
    t = np.repeat(np.arange(n_pulses) * 1e-5 + 1e5, returns)
    c = lidarfx.PointCloud(rng.random((len(t), 3)), {"gps_time": t})
    m = pulse_thinning_mask(c, 0.25, seed=1)
    kept_per_pulse = np.bincount(np.repeat(np.arange(n_pulses), returns), weights=m)
    assert set(np.unique(kept_per_pulse / returns)) == {0.0, 1.0}  # all returns of a pulse or none
    assert (kept_per_pulse > 0).mean() == pytest.approx(0.25, abs=0.01)
    assert np.array_equal(m, pulse_thinning_mask(c, 0.25, seed=1))  # seeded
    bare = lidarfx.PointCloud(c.xyz)  # no GPS time: points
    assert pulse_thinning_mask(bare, 0.5, seed=0).mean() == pytest.approx(0.5, abs=0.02)
    zero = lidarfx.PointCloud(c.xyz, {"gps_time": np.zeros(len(c))})  # times that are not pulse stamps
    assert pulse_thinning_mask(zero, 0.5, seed=0).mean() == pytest.approx(0.5, abs=0.02)
    # pulses that share a (truncated) GPS time are still thinned one by one (pulse_ids: file order)
    rn = np.concatenate([np.arange(1, k + 1) for k in returns])
    shared = lidarfx.PointCloud(c.xyz, {"gps_time": np.repeat(np.arange(n_pulses) // 2 * 1e-5 + 1e5, returns),
                                        "return_number": rn.astype(np.uint8),
                                        "number_of_returns": np.repeat(returns, returns).astype(np.uint8)})
    m = pulse_thinning_mask(shared, 0.5, seed=2)
    kept = np.bincount(np.repeat(np.arange(n_pulses), returns), weights=m) / returns
    assert set(np.unique(kept)) == {0.0, 1.0}
    assert (kept[0::2] != kept[1::2]).mean() == pytest.approx(0.5, abs=0.03)  # time-sharing pairs split


def _pulse_cloud(t, rn, nr, z):
    n = len(z)
    xyz = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.asarray(z, dtype=float)])
    return lidarfx.PointCloud(xyz, {"gps_time": np.asarray(t, dtype=float),
                                    "return_number": np.asarray(rn, np.uint8),
                                    "number_of_returns": np.asarray(nr, np.uint8)})


def test_pulse_ids_split_pulses_that_share_a_gps_time():
    from lidarfx.classify.pipeline import pulse_heights, pulse_ids

    # two 3-return pulses stored with one (truncated) GPS time, then a single return, then a
    # 2-return pulse written out of order (its time and return count make it one pulse)
    c = _pulse_cloud(t=[5, 5, 5, 5, 5, 5, 6, 7, 7], rn=[1, 2, 3, 1, 2, 3, 1, 2, 1],
                     nr=[3, 3, 3, 3, 3, 3, 1, 2, 2], z=[20, 12, 0, 30, 25, 1, 4, 0.5, 9])
    pid = pulse_ids(c)
    assert len(set(pid[:3])) == 1 and len(set(pid[3:6])) == 1 and pid[0] != pid[3]
    assert pid[7] == pid[8] and len(set(pid)) == 4
    above, below = pulse_heights(c)
    np.testing.assert_allclose(above, [0, 8, 20, 0, 5, 29, 0, 8.5, 0])
    np.testing.assert_allclose(below, [20, 12, 0, 29, 24, 0, 0, 0, 8.5])
    # without GPS times there are no pulses: NaN, and a model that needs them refuses the cloud
    bare = lidarfx.PointCloud(c.xyz, {k: c[k] for k in ("return_number", "number_of_returns")})
    assert pulse_ids(bare) is None and np.isnan(pulse_heights(bare)[0]).all()
    with pytest.raises(LidarfxError, match="gps_time"):
        LidarFeatures(["pulse_above"], []).fit().transform(bare)


def test_pulse_features_are_clipped_metres():
    c = _pulse_cloud(t=[1, 1, 2, 2], rn=[1, 2, 1, 2], nr=[2, 2, 2, 2], z=[30, 2, 3, 1])
    X = LidarFeatures(["pulse_above", "pulse_below"], []).fit().transform(c)
    np.testing.assert_allclose(X, [[0, 5], [5, 0], [0, 2], [2, 0]])  # 28 m clipped to the 5 m cap
    X = LidarFeatures(["pulse_above"], [], hag_cap=None).fit().transform(c)
    np.testing.assert_allclose(X[:, 0], [0, 28, 0, 2])
    # a file sorted by z (not in acquisition order) breaks the pulses: a warning, not silence
    rng = np.random.default_rng(0)
    t = np.repeat(np.arange(200.0), 2)
    z = rng.uniform(0, 20, 400)
    sorted_c = _pulse_cloud(t, np.tile([1, 2], 200), np.full(400, 2), z)
    sorted_c = sorted_c.subset(np.argsort(z))
    sorted_c["gps_time"] = np.round(sorted_c["gps_time"] / 4)  # truncated times: no group key
    with pytest.warns(LidarfxWarning, match="complete pulses"):
        LidarFeatures(["pulse_above"], []).fit().transform(sorted_c)


def test_pulse_ids_on_the_ign_tile_with_truncated_gps_times():
    from lidarfx.classify.pipeline import pulse_ids

    path = IGN_TRAIN[0]
    if not path.exists():
        pytest.skip(f"IGN training tile not found (shared real-data folder): {path}")
    c = lidarfx.read(path)
    pid = pulse_ids(c)
    nr = np.asarray(c["number_of_returns"])
    complete = np.bincount(pid)[pid] == nr
    assert len(np.unique(np.asarray(c["gps_time"]))) < 0.35 * len(c)  # GPS time alone is no key here
    assert complete.mean() > 0.985  # measured 0.991; the time key gives 0.399


def test_density_augment_train_and_cv(facades):
    from lidarfx.classify.evaluate import _file_features, _thinned_features
    from lidarfx.classify.model import read_sources, resolve_classes, thinned_sources

    a = facades[0]
    with pytest.raises(LidarfxError, match="between 0 and 1"):
        TrainConfig(density_augment=[1.5])
    m = train(a, classes=FACADE6, classifier="rf", n_estimators=10, density_augment=[0.5, 0.25], **SMALL)
    counts = m.meta["training"]["counts"]
    assert len(counts["density_augment"]) == 2
    for copy in counts["density_augment"]:  # at most half of 2000 per class, fewer where a class is small
        assert all(0 < v <= 1000 for v in copy.values()) and max(copy.values()) == 1000
    assert m.meta["config"]["density_augment"] == [0.5, 0.25]
    # CV rows of a thinned copy point at the same points of the full feature matrix
    cfg = TrainConfig(classifier="rf", n_estimators=10, density_augment=[0.3], **SMALL)
    srcs = read_sources([a])
    cmap = resolve_classes(srcs, FACADE6)
    X, y, xy, g = _file_features(srcs, cmap, cfg, False)
    (copies,) = thinned_sources(srcs, cfg)
    Xa, rows = _thinned_features(srcs, copies, cmap, cfg, False)
    assert len(Xa) == len(rows) and 0.25 < len(rows) / len(y) < 0.35
    keep = copies[0][1]
    lab = cmap.index_of(srcs[0].cloud["classification"])
    assert np.array_equal(xy[rows], srcs[0].cloud.xyz[keep][lab[keep] >= 0, :2])
    rep = evaluate([a], classes=FACADE6, cv=2, block_size=None, config=cfg)
    plain = evaluate([a], classes=FACADE6, cv=2, block_size=None,
                     config=TrainConfig(classifier="rf", n_estimators=10, **SMALL))
    assert rep["sections"]["cv_random"]["metrics"]["oa"] > 0.9
    added = [f["train_points"] - g["train_points"] for f, g in zip(rep["sections"]["cv_random"]["folds"],
                                                                   plain["sections"]["cv_random"]["folds"])]
    assert all(1000 < n <= 6 * 1000 for n in added)  # each fold adds a sample of the thinned copy


def test_mostly_unusable_points_warn(facades, rf_model):
    from lidarfx.errors import LidarfxWarning

    b = facades[1].copy()
    flag = np.zeros(len(b), np.uint8)
    flag[: int(0.6 * len(b))] = 1
    b["synthetic"] = flag
    with pytest.warns(LidarfxWarning, match=r"of [\d,]+ points are not used \(flags: synthetic [\d,]+"):
        out = rf_model.classify(b)
    assert out.meta["classify"]["predicted_points"] == len(b) - int(flag.sum())


def test_prediction_in_chunks_equals_one_pass(facades, rf_model, monkeypatch):
    import lidarfx.classify.model as model_module

    b = facades[1]
    codes, conf = rf_model.predict(b, return_confidence=True)
    proba, usable = rf_model.predict_proba(b)
    X = rf_model.feature_matrix(b.subset(usable) if not usable.all() else b)
    monkeypatch.setattr(model_module, "PREDICT_CHUNK", 997)  # many chunks, the last one short
    assert len(b) > 5 * 997
    assert [r.stop - r.start for r, _ in rf_model.feature_chunks(b)][-1] == len(b) % 997
    codes2, conf2 = rf_model.predict(b, return_confidence=True)
    proba2, _ = rf_model.predict_proba(b)
    assert np.array_equal(codes, codes2) and np.array_equal(conf, conf2, equal_nan=True)
    assert np.array_equal(proba, proba2)
    assert np.array_equal(rf_model.feature_matrix(b.subset(usable) if not usable.all() else b), X, equal_nan=True)
    assert np.array_equal(codes, rf_model.predict(b))  # the no-confidence path gives the same classes


def test_per_class_probabilities(facades, rf_model):
    b = facades[1].copy()
    flag = np.zeros(len(b), np.uint8)
    flag[:50] = 1  # withheld: not predicted
    b["withheld"] = flag
    codes, conf, proba = rf_model.predict(b, return_confidence=True, return_proba=True)
    p2, usable = rf_model.predict_proba(b)
    assert proba.dtype == np.float32 and proba.shape == (len(b), len(rf_model.classes))
    assert np.isnan(proba[:50]).all() and not np.isnan(proba[50:]).any()
    np.testing.assert_array_equal(proba[usable], p2.astype(np.float32))
    np.testing.assert_allclose(proba[usable].sum(axis=1), 1.0, atol=1e-5)
    assert np.array_equal(conf[usable], proba[usable].max(axis=1))  # no building rule on this model
    assert np.array_equal(codes[usable], rf_model.classes.code_of(proba[usable].argmax(axis=1)))
    codes_only, proba_only = rf_model.predict(b, return_proba=True)
    assert np.array_equal(codes_only, codes) and np.array_equal(proba_only, proba, equal_nan=True)
    out = rf_model.classify(b, probabilities=True)
    names = rf_model.probability_names()
    assert names == ["probability_" + n for n in rf_model.classes.names]
    for j, name in enumerate(names):
        assert np.array_equal(out[name], proba[:, j], equal_nan=True)
    assert "confidence" not in out


def test_probability_names_fall_back_to_codes():
    from lidarfx.classify.model import ClassifierModel

    m = ClassifierModel.__new__(ClassifierModel)
    m.classes = ClassMap.parse("Low Veg=3,low-veg=4,ground=2")  # the same after cleaning: codes
    assert m.probability_names() == ["probability_3", "probability_4", "probability_2"]
    m.classes = ClassMap.parse("Low Veg=3,ground=2")
    assert m.probability_names() == ["probability_low_veg", "probability_ground"]
    m.classes = ClassMap.parse(f"{'x' * 21}=3,ground=2")  # 33 characters: too long for LAS
    assert m.probability_names() == ["probability_3", "probability_2"]


def test_transform_of_several_clouds_equals_one_cloud_at_a_time(facades):
    # the neighbour index is kept for the current cloud only: a list switches clouds and back
    a, b = facades
    tr = LidarFeatures(features="eigen,height_above_ground", radii=[0.3, 0.5]).fit()
    ia, ib, ia2 = np.arange(0, 3000, 3), np.arange(5, 4000, 4), np.arange(7000, 9000, 2)
    X = tr.transform([CloudSample(a, ia), CloudSample(b, ib), CloudSample(a, ia2)])
    one = [tr.transform(CloudSample(c, i)) for c, i in ((a, ia), (b, ib), (a, ia2))]
    assert X.flags["C_CONTIGUOUS"] and np.array_equal(X, np.vstack(one), equal_nan=True)


def test_evaluate_model_without_model_classes(facades, rf_model):
    from lidarfx.classify import evaluate_model
    from lidarfx.errors import LidarfxWarning

    b = facades[1]
    other = b.copy()
    other["classification"] = np.zeros(len(b), np.uint8)
    other.meta = {**other.meta, "name": "unlabelled"}
    with pytest.raises(LidarfxError, match=r"no points of the model's classes .*its classes: \[0\]"):
        evaluate_model(rf_model, [other])
    with pytest.warns(LidarfxWarning, match="not counted"):
        sec = evaluate_model(rf_model, [other, b])
    assert len(sec["files"]) == 1 and sec["metrics"]["oa"] > 0.9


def test_predict_with_the_files_ground_class(facade_files, tmp_path, capsys):
    d, pa, pb = facade_files
    model = tmp_path / "m.skops"
    assert main(["classify", "train", str(pa), "--model", str(model), "--classes", FACADE6, "--features",
                 "eigen,height_above_ground", "-r", "0.5", "--classifier", "rf", "--n-estimators", "10",
                 "--max-per-class", "1000", "-q"]) == 0
    m = load_model(model)
    b = lidarfx.read(pb)
    m.features.ground = "class"  # what predict --ground class does
    hag = m.feature_matrix(b)[:, m.feature_names.index("height_above_ground")]
    assert np.all(hag[np.asarray(b["classification"]) == 2] == 0)  # class-2 points are the ground surface
    capsys.readouterr()
    assert main(["classify", "predict", str(pb), str(tmp_path / "o.laz"), "--model", str(model),
                 "--ground", "class", "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["ground"] == "class"
    nog = b.copy()
    nog["classification"] = np.where(nog["classification"] == 2, 1, nog["classification"]).astype(np.uint8)
    lidarfx.write(nog, tmp_path / "noground.laz")
    assert main(["classify", "predict", str(tmp_path / "noground.laz"), str(tmp_path / "o2.laz"), "--model",
                 str(model), "--ground", "class", "-q"]) == 2
    assert "no ground found" in capsys.readouterr().err and not (tmp_path / "o2.laz").exists()


def test_density_warning_cli(facade_files, tmp_path, capsys):
    d, pa, pb = facade_files
    model = tmp_path / "m.skops"
    assert main(["classify", "train", str(pa), "--model", str(model), *CLI_MODEL]) == 0
    b = lidarfx.read(pb)
    sparse = tmp_path / "sparse.laz"
    lidarfx.write(b.subset(np.random.default_rng(0).random(len(b)) < 0.3), sparse)
    capsys.readouterr()
    assert main(["classify", "predict", str(sparse), str(tmp_path / "o.laz"), "--model", str(model),
                 "--json", "-q"]) == 0
    cap = capsys.readouterr()
    warn = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(warn) == 1 and warn[0].startswith("lidarfx: warning: ") and "sparsest training file" in warn[0]
    summary = json.loads(cap.out)
    assert summary["density"]["ratio"] < 0.5
    assert main(["classify", "predict", str(pb), str(tmp_path / "o2.laz"), "--model", str(model), "-q"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_cli_model_info(facade_files, tmp_path, capsys):
    d, pa, _ = facade_files
    model = tmp_path / "m.skops"
    assert main(["classify", "train", str(pa), "--model", str(model), *CLI_MODEL]) == 0
    capsys.readouterr()
    assert main(["classify", "info", str(model), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["classifier"] == "rf" and info["trees"] == 20
    assert [c["name"] for c in info["classes"]] == ["ground", "vegetation", "wall", "roof", "window", "clutter"]
    assert info["classes"][0]["codes"] == [2] and len(info["features"]) == 52 and info["radii"] == [0.3, 0.5]
    assert info["training_density"] == pytest.approx(info["training_files"][0]["density"])
    assert info["training_density"] > 50  # the dense synthetic facade
    assert sum(info["training_counts"].values()) > 6000
    assert main(["info", str(model)]) == 0  # the general info command shows models too
    out = " ".join(capsys.readouterr().out.split())  # rich wraps long lines
    assert "classifier (rf)" in out and "training density" in out and "wall codes 6" in out
    assert main(["classify", "info", str(tmp_path / "none.skops")]) == 2


def test_cli_help_has_examples(capsys):
    with pytest.raises(SystemExit):
        main(["classify", "--help"])
    out = capsys.readouterr().out
    assert "examples:" in out and "lidarfx classify train" in out and "rows = reference" in out


# --------------------------------------------------------------------------- IGN acceptance
needs_ign = pytest.mark.skipif(
    not all(p.is_file() for p in IGN_TRAIN + IGN_TEST),
    reason=f"IGN LiDAR HD files not found in {REAL} (test_data_*_627755_*.laz, crop_1.laz, pont.laz)",
)


@pytest.fixture(scope="module")
def ign_result():
    from lidarfx.classify import evaluate_model

    t0 = time.perf_counter()
    model = train([str(p) for p in IGN_TRAIN], classes="ground=2,vegetation=3+4+5,building=6")
    sec = evaluate_model(model, [str(p) for p in IGN_TEST])
    return sec, time.perf_counter() - t0


@pytest.mark.slow
@needs_ign
def test_ign_default_pipeline_regression(ign_result):
    """Train on the three IGN tiles, test on crop_1 + pont (classes 2 / 3+4+5 / 6, others ignored).

    Measured (docs/classification.md §7, 2026-11-22): OA 0.955, mean F1 0.944, ≈ 30 s; the usual
    pipeline (jakteristics 1/2/3 m + z + balanced RF) gets OA 0.43 on this split.
    """
    sec, _ = ign_result
    m = sec["metrics"]
    assert m["oa"] >= 0.95 and m["mean_f1"] >= 0.93, m
    assert sec["files"][str(IGN_TEST[0])]["oa"] >= 0.97
    # its time against the usual pipeline's is measured by benchmarks/bench_classify.py, not here


@pytest.mark.slow
@needs_ign
@pytest.mark.xfail(reason="issue 5 target OA >= 0.965 / mean F1 >= 0.95 not reached on crop_1 + pont "
                          "(0.955 / 0.944): sloped, vegetated ground in pont (docs/classification.md)", strict=False)
def test_ign_acceptance_target(ign_result):
    m = ign_result[0]["metrics"]
    assert m["oa"] >= 0.965 and m["mean_f1"] >= 0.95, m


def test_default_list_with_inputs_left_out(facades, tmp_path, capsys):
    from lidarfx.classify.pipeline import feature_list

    full = feature_list(None, [1, 2, 3])[0]
    assert feature_list("default", [1, 2, 3])[0] == full
    left = feature_list("default,-return_ratio,-number_of_returns,-histogram", [1, 2, 3])[0]
    assert left == [n for n in full if n not in ("return_ratio", "number_of_returns") and not n.startswith("dh_")]
    assert len(left) == 81 - 2 - 3 * 7
    assert feature_list("eigen,z,-z", [1])[0] == feature_list("eigen", [1])[0]
    assert feature_list("eigen,-eigen,z", [1])[0] == ["z"]  # inputs remain: not "all were left out"
    # the registry's group "ground" is the input height_above_ground, once
    assert feature_list("default,-ground", [1, 2, 3])[0] == [n for n in full if n != "height_above_ground"]
    both = feature_list("default,ground", [1, 2, 3])[0]
    assert sorted(both) == sorted(full) and both.count("height_above_ground") == 1
    for spec, message in (("eigen,-z", "cannot leave out 'z'"), ("z,-z", "all were left out"),
                          ("-z,z", "requested before it"), ("default,--z", "one '-' leaves"),
                          ("default,-planarty", "unknown feature 'planarty'")):
        with pytest.raises(LidarfxError, match=message):
            feature_list(spec, [1])
    # a file that has the return fields but 0 in every point (AHN4 exports): the default list leaves
    # the return inputs out by itself (before: refused with a hint) ...
    a = facades[0]
    zero = np.zeros(len(a), np.uint8)
    path = tmp_path / "noreturns.laz"
    lidarfx.write(lidarfx.PointCloud(a.xyz, {**a.attrs, "return_number": zero, "number_of_returns": zero}), path)
    model = tmp_path / "m.skops"
    args = ["classify", "train", str(path), "--model", str(model), "--classes", FACADE6, "-r", "0.5",
            "--max-per-class", "1000", "-q"]
    assert main(args[:-1] + ["--json"]) == 0
    assert json.loads(capsys.readouterr().out)["features"] == 27
    # ... as the list given explicitly does: the default list's other inputs and the ALS building rule
    assert main(args + ["--features", "default,-return_ratio,-number_of_returns", "--json", "--force"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["features"] == 27 and summary["min_building_area"] == 10.0  # 26 at 0.5 m + HAG
    # predicting: the building rule runs, its see-through test says it cannot
    assert main(["classify", "predict", str(path), str(tmp_path / "o.laz"), "--model", str(model)]) == 0
    assert "see-through test not run: the file records no return numbers" in capsys.readouterr().err
    # a model with a list of its own gets its own list back in the hint, without the lacking input
    from lidarfx.classify.pipeline import LidarFeatures

    with pytest.raises(LidarfxError, match=r"without number_of_returns, e\.g\. --features eigen,plane$"):
        LidarFeatures(features="eigen,number_of_returns,plane", radii=[0.5]).check_cloud(lidarfx.read(path))
