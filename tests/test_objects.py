"""The object-size rule after classification: components, hull areas, data edge, relabelling."""
from __future__ import annotations


import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, cKDTree

import lidarfx
from lidarfx.classify import ClassMap, TrainConfig, load_model, train
from lidarfx.classify.evaluate import HeldOutRule, _labelled, cross_validate
from lidarfx.classify.model import read_sources, resolve_classes
from lidarfx.classify.objects import building_class, drop_small_objects, edge_mask, link_for
from lidarfx.cli import main
from lidarfx.errors import LidarfxError
from lidarfx.geometry import group_hull_areas
from lidarfx.segment.components import linked_components


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    pairs = np.unique(np.c_[a, b], axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


def test_linked_components_equal_single_linkage():
    rng = np.random.default_rng(3)
    centres = rng.random((40, 3)) * [60, 60, 10]
    xyz = np.vstack([c + rng.normal(0, 0.6, (int(rng.integers(1, 60)), 3)) for c in centres]) + [5e5, 6e6, 100]
    for d in (0.5, 1.0, 2.0):
        ours = linked_components(xyz, d)
        pairs = cKDTree(xyz).query_pairs(d, output_type="ndarray")
        g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(xyz),) * 2)
        ref = connected_components(g, directed=False)[1]
        assert _same_partition(ours, ref), d
        first = np.array([np.flatnonzero(ours == c)[0] for c in range(ours.max() + 1)])
        assert (np.diff(first) > 0).all()  # numbered in the order of their first point


def test_linked_components_link_is_inclusive_and_checked():
    xyz = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.5, 0, 0], [2.5, 0, 1.0]])
    assert linked_components(xyz, 1.0).tolist() == [0, 0, 1, 1]
    assert linked_components(xyz, 1.5).tolist() == [0, 0, 0, 0]
    assert linked_components(np.zeros((0, 3)), 1.0).shape == (0,)
    with pytest.raises(LidarfxError):
        linked_components(xyz, 0.0)


def test_group_hull_areas():
    rng = np.random.default_rng(0)
    xy = rng.random((2000, 2)) * [40, 7] + [7.7e5, 6.3e6]
    g = rng.integers(0, 25, len(xy))
    ref = [ConvexHull(xy[g == i] - xy[g == i][0]).volume for i in range(25)]
    assert np.allclose(group_hull_areas(xy, g), ref, rtol=1e-9)
    square = np.array([[0, 0], [2, 0], [2, 3], [0, 3], [1, 1], [1, 2], [0, 1.5]], float)  # inner + edge points
    line = np.c_[np.arange(5.0), np.arange(5.0)]
    pts = np.vstack([square, line, [[9, 9], [9, 10]]])
    groups = np.r_[np.zeros(7), np.ones(5), [2, 2]].astype(int)
    assert group_hull_areas(pts, groups).tolist() == [6.0, 0.0, 0.0]


def test_edge_mask_marks_the_border_and_holes():
    ax = np.arange(0.125, 30, 0.25)
    xy = np.array(np.meshgrid(ax, ax)).reshape(2, -1).T
    e = edge_mask(xy)
    inner = np.minimum(xy.min(axis=1), 30 - xy.max(axis=1))
    assert e[inner < 2].all() and not e[inner >= 3].any()
    hole = (np.abs(xy - 15) < 2).all(axis=1)  # a 4 m hole in the middle
    e2 = edge_mask(xy[~hole])
    d = np.abs(xy[~hole] - 15).max(axis=1)  # Chebyshev distance to the centre
    assert e2[(d >= 2) & (d < 4)].all() and not e2[(d >= 5) & (inner[~hole] >= 3)].any()


def _scene():
    """30 × 30 m of ground (class 0) at 16 pts/m², a 10 × 10 m roof and two 1.5 m blobs
    (classes 2 = building predicted, alternative 1): one in the middle, one at the edge."""
    ax = np.arange(0.125, 30, 0.25)
    gx, gy = np.meshgrid(ax, ax)
    ground = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    r = np.arange(0.125, 10, 0.25)
    rx, ry = np.meshgrid(r, r)
    roof = np.c_[rx.ravel() + 4, ry.ravel() + 4, np.full(rx.size, 5.0)]
    b = np.arange(0.125, 1.5, 0.25)
    bx, by = np.meshgrid(b, b)
    blob = np.c_[bx.ravel(), by.ravel(), np.full(bx.size, 8.0)]
    xyz = np.vstack([ground, roof, blob + [20, 20, 0], blob + [0.2, 14, 0]])
    lab = np.r_[np.zeros(len(ground)), np.full(len(roof) + 2 * len(blob), 2)].astype(np.int64)
    part = np.r_[np.zeros(len(ground)), np.ones(len(roof)), np.full(len(blob), 2), np.full(len(blob), 3)]
    return xyz, lab, part


def test_drop_small_objects_relabels_small_inner_clusters_only():
    xyz, lab, part = _scene()
    alt = np.ones(len(lab), np.int64)
    st: dict = {}
    out = drop_small_objects(lab, alt, xyz, 2, 10.0, stats=st)
    assert (out[part == 2] == 1).all()  # the inner blob: 1.5 × 1.5 m < 10 m²
    assert (out[part == 1] == 2).all()  # the roof: 100 m²
    assert (out[part == 3] == 2).all()  # the blob at the edge: size unknown, kept
    assert (out[part == 0] == 0).all()
    assert st == {"components": 3, "kept_at_edge": 1, "relabelled_components": 1,
                  "relabelled_points": int((part == 2).sum()), "see_through_components": 0,
                  "see_through_points": 0, "see_through_untested": 0}
    assert (drop_small_objects(lab, alt, xyz, 2, 0.0) == lab).all()
    assert (drop_small_objects(lab, alt, xyz, 2, 200.0)[part == 1] == 1).all()  # a larger threshold takes the roof
    with pytest.raises(LidarfxError):
        drop_small_objects(lab, alt, xyz, 2, -1.0)


def test_see_through_test_takes_large_clusters_the_laser_passes():
    """A judged cluster (footprint >= the minimum area) with more than the given share of its
    points from multi-return pulses takes its next class; a small one at the edge is not judged."""
    xyz, lab, part = _scene()
    alt = np.ones(len(lab), np.int64)
    nr = np.ones(len(lab), np.int64)
    roof = np.flatnonzero(part == 1)
    nr[roof[: len(roof) // 2]] = 2  # exactly half of the roof from multi-return pulses: not more than 0.5
    nr[part == 3] = 3  # the edge blob: all multi-return, but too small to be judged
    st: dict = {}
    out = drop_small_objects(lab, alt, xyz, 2, 10.0, returns=nr, max_multi_return_share=0.5, stats=st)
    assert (out[part == 1] == 2).all() and (out[part == 3] == 2).all() and (out[part == 2] == 1).all()
    assert st["see_through_components"] == 0
    nr[roof[len(roof) // 2]] = 2  # one point more: the roof is a see-through cluster now
    out = drop_small_objects(lab, alt, xyz, 2, 10.0, returns=nr, max_multi_return_share=0.5, stats=st)
    assert (out[part == 1] == 1).all() and (out[part == 3] == 2).all()
    assert st["see_through_components"] == 1 and st["see_through_points"] == len(roof)
    assert st["relabelled_components"] == 1 and st["relabelled_points"] == (part == 2).sum()  # the small rule
    # no return numbers (none, or 0 everywhere as in AHN4 exports), a share of 1, or the rule switched off: no test
    for kw, untested in (({"returns": None}, 1), ({"returns": np.zeros_like(nr)}, 1),
                         ({"max_multi_return_share": 1.0}, 0)):
        args = {"returns": nr, "max_multi_return_share": 0.5, **kw}
        assert (drop_small_objects(lab, alt, xyz, 2, 10.0, stats=st, **args)[part == 1] == 2).all()
        assert st["see_through_untested"] == untested and st["see_through_components"] == 0
    from lidarfx.classify.evaluate import _small_buildings_line

    line = _small_buildings_line({**st, "see_through_untested": 1, "min_building_area": 10.0,
                                  "max_multi_return_share": 0.5})
    assert line.endswith("not run where the data record no return numbers")
    assert "not run" not in _small_buildings_line({**st, "min_building_area": 10.0, "max_multi_return_share": 0.5})
    assert (drop_small_objects(lab, alt, xyz, 2, 0.0, returns=nr, max_multi_return_share=0.5) == lab).all()
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(LidarfxError, match="multi-return share"):
            drop_small_objects(lab, alt, xyz, 2, 10.0, returns=nr, max_multi_return_share=bad)


def test_link_grows_only_for_sparse_clouds():
    assert link_for(30.0) == link_for(4.0) == 1.0 and link_for(None) == 1.0
    assert link_for(1.0) == pytest.approx(2.0)


def test_the_rule_is_part_of_the_als_default_only():
    assert TrainConfig().min_building_area == 10.0  # the default feature list (ALS)
    assert TrainConfig(features="eigen,plane").min_building_area == 0.0  # own features, e.g. TLS facades
    # the default list with inputs left out (a survey without return numbers) is still the ALS default
    assert TrainConfig(features="default,-return_ratio,-number_of_returns").min_building_area == 10.0
    assert TrainConfig(features="eigen", min_building_area=25).min_building_area == 25.0
    assert TrainConfig(min_building_area=0).min_building_area == 0.0
    with pytest.raises(LidarfxError):
        TrainConfig(min_building_area=float("nan"))
    assert TrainConfig().max_multi_return_share == 0.5
    assert TrainConfig(max_multi_return_share=1).max_multi_return_share == 1.0
    with pytest.raises(LidarfxError, match="multi-return share"):
        TrainConfig(max_multi_return_share=0)


def test_building_class_is_the_class_holding_code_6():
    assert building_class(ClassMap.parse("ground=2,vegetation=3+4+5,building=6")) == 2
    assert building_class(ClassMap.parse("2,6+64,5")) == 1
    assert building_class(ClassMap.parse("2,3+4+5")) is None


# --------------------------------------------------------------------------- in a model
def _town(seed: int, hedges: bool = True, size: float = 60.0, density: float = 20.0) -> lidarfx.PointCloud:
    """Ground, three 12 × 12 m flat houses and single trees (round crowns) at 20 pts/m²;
    with ``hedges`` also six clipped hedges (vegetation, 2 × 2 m flat tops 3 m high) that
    look like small roofs to a model trained without them.  ``size``: the scene's side in m
    (60; positions and house sides scale with it, crowns and hedges keep their size)."""
    rng = np.random.default_rng(seed)
    s = size / 60.0
    n = int(density * size * size)
    xy = rng.random((n, 2)) * size
    z = np.zeros(n)
    cls = np.full(n, 2, np.uint8)
    for hx, hy in ((8 * s, 8 * s), (35 * s, 10 * s), (15 * s, 38 * s)):
        inside = (xy[:, 0] > hx) & (xy[:, 0] < hx + 12 * s) & (xy[:, 1] > hy) & (xy[:, 1] < hy + 12 * s)
        z[inside], cls[inside] = 6.0, 6
    for tx, ty in (rng.random((12, 2)) * [20, 20] + [38, 36]) * s:
        d = np.hypot(xy[:, 0] - tx, xy[:, 1] - ty)
        crown = (d < 2.5) & (cls == 2) & (rng.random(n) < 0.7)
        z[crown] = 4 + 3 * np.sqrt(np.clip(1 - (d[crown] / 2.5) ** 2, 0, 1)) + rng.normal(0, 0.3, crown.sum())
        cls[crown] = 5
    if hedges:
        for hx, hy in ((32, 30), (5, 28), (50, 5), (25, 25), (28, 52), (52, 24)):
            top = (np.abs(xy[:, 0] - hx * s) < 1) & (np.abs(xy[:, 1] - hy * s) < 1) & (cls == 2)
            z[top], cls[top] = 3.0, 5
    xyz = np.c_[xy + [7.7e5, 6.27e6], z + rng.normal(0, 0.03, n) + 50]
    return lidarfx.PointCloud(xyz, {"classification": cls})


@pytest.fixture(scope="module")
def town_model():
    return train(_town(1, hedges=False), classes="ground=2,vegetation=5,building=6",
                 features="eigen,plane,height_above_ground", radii=[1.0, 2.0],
                 max_per_class=3000, terrain_augment=0, classifier="rf", n_estimators=20, min_building_area=10)


def test_model_stores_and_applies_the_rule(town_model, tmp_path):
    cloud = _town(2)
    assert town_model.min_building_area == 10.0
    st: dict = {}
    rule = town_model.predict(cloud, stats=st)
    plain = town_model.predict(cloud, min_building_area=0)
    changed = rule != plain
    assert st["relabelled_points"] == changed.sum() > 0
    assert (plain[changed] == 6).all() and (rule[changed] != 6).all()
    ref = np.asarray(cloud["classification"])
    hedge = (ref == 5) & (plain == 6)  # the hedges look like small roofs ...
    assert hedge.sum() > 300 and not (rule[hedge] == 6).any()  # ... and are all taken out of the building class
    assert ((rule == 6) & (ref == 6)).sum() == ((plain == 6) & (ref == 6)).sum()  # no house loses a point
    # the confidence of a relabelled point is its new class's probability (below the building's)
    codes, conf = town_model.predict(cloud, return_confidence=True)
    assert (codes == rule).all() and np.isfinite(conf).all()
    # the per-class probabilities are the classifier's, before the rule: building is still the top class there
    _, proba = town_model.predict(cloud, return_proba=True)
    top = town_model.classes.code_of(proba.argmax(axis=1))
    assert (top == plain).all() and (top[changed] == 6).all()
    b = town_model.classes.codes.index(6)
    others = proba.copy()
    others[:, b] = -1.0  # the best class but building: the one a relabelled point gets, and its probability
    assert (rule[changed] == town_model.classes.code_of(others[changed].argmax(axis=1))).all()
    np.testing.assert_array_equal(conf[changed], others[changed].max(axis=1))
    np.testing.assert_array_equal(conf[~changed], proba[~changed].max(axis=1))
    assert (conf[changed] <= proba[changed, b]).all()
    town_model.set_min_building_area(0)
    try:
        path = town_model.save(tmp_path / "m.skops")
        assert load_model(path).min_building_area == 0.0
        assert (load_model(path).predict(cloud) == plain).all()
    finally:
        town_model.set_min_building_area(10.0)
    old = load_model(path)
    del old.meta["config"]["min_building_area"]  # a model written before the rule existed
    assert old.min_building_area == 0.0
    # the see-through test: every point from a two-return pulse makes every judged cluster (the
    # 144 m² houses) see-through; the model's share (default 0.5) applies, 1 switches it off
    assert town_model.max_multi_return_share == 0.5
    cloud["number_of_returns"] = np.full(len(cloud), 2, np.uint8)
    st = {}
    through = town_model.predict(cloud, stats=st)
    assert st["see_through_components"] >= 3 and not (through == 6).any()
    assert (town_model.predict(cloud, max_multi_return_share=1.0) == rule).all()
    town_model.set_max_multi_return_share(1.0)
    try:
        assert (load_model(town_model.save(tmp_path / "m1.skops")).predict(cloud) == rule).all()
    finally:
        town_model.set_max_multi_return_share(0.5)
    del old.meta["config"]["max_multi_return_share"]  # a model written before the test existed
    assert old.max_multi_return_share == 1.0
    with pytest.raises(LidarfxError):
        town_model.set_max_multi_return_share(0)


def test_cross_validation_applies_the_rule_per_held_out_part(town_model):
    """HeldOutRule predicts the held-out labelled points together with the context points of
    the same part and file; with area 0 it is the plain prediction."""
    clouds = [_town(3), _town(4)]
    for c in clouds:  # unlabelled context points: class 1 ignored by the class map
        cls = np.asarray(c["classification"]).copy()
        cls[::50] = 1
        c["classification"] = cls
    srcs = read_sources(clouds)
    cmap = resolve_classes(srcs, "ground=2,vegetation=5,building=6")
    cfg = TrainConfig(features="eigen,plane", radii=[1.0, 2.0], max_per_class=2000, terrain_augment=0,
                      classifier="rf", n_estimators=10, min_building_area=10)
    lab = _labelled(srcs, cmap)
    from lidarfx.classify.evaluate import _file_features

    X = _file_features(srcs, cmap, cfg, False, lab)[0]
    y, g = lab[1], lab[3]
    rule = HeldOutRule(srcs, cmap, cfg, lab, X, 2)
    assert len(rule.X_c) == sum(len(np.asarray(c["classification"])[::50]) for c in clouds)
    from lidarfx.classify import block_folds

    fb, _ = block_folds(lab[2], 3, 20.0, 0, g)
    rule.set_folds("blocks", fb, block_size=20.0)  # a context point joins the fold of its block
    def key(xy, gg):
        return [tuple(r) for r in np.c_[gg, np.floor(xy[:, :2] / 20.0)].astype(int)]

    fold_of = dict(zip(key(rule.xyz, g), fb))
    assert rule.folds_c.tolist() == [fold_of.get(k, -1) for k in key(rule.xyz_c, rule.g_c)]
    rule.set_folds("files", g)
    pred_rule, pred_plain = np.full(len(y), -1), np.full(len(y), -1)
    cm_rule, _, fitted = cross_validate(X, y, g, cfg, 3, post=rule, out_pred=pred_rule)
    assert rule.stats["components"] > 0 and rule.stats["relabelled_points"] > 0
    cfg0 = TrainConfig(**{**cfg.to_dict(), "min_building_area": 0.0})
    rule0 = HeldOutRule(srcs, cmap, cfg0, lab, X, 2)
    rule0.set_folds("files", g)
    cm0, _, _ = cross_validate(X, y, g, cfg, 3, post=rule0)
    cm_plain, _, _ = cross_validate(X, y, g, cfg, 3, out_pred=pred_plain)
    assert (cm0 == cm_plain).all()
    assert (cm_rule.sum(axis=1) == cm_plain.sum(axis=1)).all()  # the same reference points
    # every relabelled labelled point left the building column, and nothing else moved
    changed = pred_rule != pred_plain
    assert changed.any() and (pred_plain[changed] == 2).all() and (pred_rule[changed] != 2).all()
    assert cm_plain[:, 2].sum() - cm_rule[:, 2].sum() == changed.sum()
    # the rule's counts also hold the context points relabelled with them
    assert changed.sum() <= rule.stats["relabelled_points"] + rule.stats["see_through_points"]


@pytest.mark.parametrize("spec, target", [("ground=2,vegetation=5,building=6", 2),
                                          ("building=6,ground=2,vegetation=5", 0)])
def test_the_rule_in_a_fold_whose_training_part_lacks_the_building_class(spec, target):
    """A held-out part whose training part has no building points (a small file, fine blocks, a
    buffer): the estimator knows fewer classes than the map.  The rule must read its probability
    columns as the estimator's classes, not as class indices (it raised an IndexError with building
    last in the map, and took the ground column for the building one with building first)."""
    a, b = _town(3), _town(4)
    cls = np.asarray(b["classification"]).copy()
    cls[cls == 6] = 1  # b: no building labels (its houses become unlabelled context points)
    b["classification"] = cls
    srcs = read_sources([a, b])
    cmap = resolve_classes(srcs, spec)
    cfg = TrainConfig(features="eigen,plane,height_above_ground", radii=[1.0, 2.0], max_per_class=2000,
                      terrain_augment=0, classifier="rf", n_estimators=10, min_building_area=10)
    lab = _labelled(srcs, cmap)
    from lidarfx.classify.evaluate import _file_features

    X = _file_features(srcs, cmap, cfg, False, lab)[0]
    y, g = lab[1], lab[3]
    rule = HeldOutRule(srcs, cmap, cfg, lab, X, target)
    rule.set_folds("files", g)
    pred_rule = np.full(len(y), -1)
    pred_plain = np.full(len(y), -1)
    _, folds_rule, _ = cross_validate(X, y, g, cfg, 3, post=rule, out_pred=pred_rule, class_names=cmap.names)
    _, folds_plain, _ = cross_validate(X, y, g, cfg, 3, out_pred=pred_plain)
    # the fold holding out a (trained on b) says it cannot predict building; the other does not
    assert [pf.get("not_trained") for pf in folds_rule] == [["building"], None]
    assert [pf.get("not_trained") for pf in folds_plain] == [[target], None]  # indices without names
    held_a = g == 0  # predicted by a model of b alone: it knows no building, so the rule has nothing to do
    assert set(np.unique(pred_plain[held_a])) <= set(range(3)) - {target}
    assert (pred_rule[held_a] == pred_plain[held_a]).all()
    assert (y[held_a] == target).sum() > 5000  # a's houses are there, and called something else


def test_cli_min_building_area(tmp_path, capsys, town_model):
    import json

    src = tmp_path / "town.laz"
    lidarfx.write(_town(5), src)
    m = tmp_path / "t.skops"
    town_model.save(m)
    out = tmp_path / "o.laz"
    assert main(["classify", "predict", str(src), str(out), "-m", str(m), "--json", "-q"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["min_building_area"] == 10.0 and s["small_buildings"]["components"] >= 1
    assert main(["classify", "predict", str(src), str(out), "-m", str(m), "--force", "--json", "-q",
                 "--min-building-area", "0"]) == 0
    s0 = json.loads(capsys.readouterr().out)
    assert s0["min_building_area"] == 0.0 and s0["small_buildings"] is None
    sb = s["small_buildings"]
    assert sb["relabelled_points"] > 0  # the hedges
    # every point the rule relabels leaves class 6: the written classes differ by exactly that many
    six, six0 = s["classes"].get(6, s["classes"].get("6")), s0["classes"].get(6, s0["classes"].get("6"))
    assert six0 - six == sb["relabelled_points"] + sb["see_through_points"]
    assert sum(s["classes"].values()) == sum(s0["classes"].values()) == s["points"]
    assert main(["classify", "predict", str(src), str(out), "-m", str(m), "--force", "-q", "--min-building-area", "-3"]) == 2
    assert "minimum building area" in capsys.readouterr().err
    assert s["max_multi_return_share"] == 0.5 and s["small_buildings"]["see_through_components"] == 0  # no returns
    assert main(["classify", "predict", str(src), str(out), "-m", str(m), "--force", "--json", "-q",
                 "--max-multi-return-share", "1"]) == 0
    assert json.loads(capsys.readouterr().out)["max_multi_return_share"] == 1.0
    assert main(["classify", "predict", str(src), str(out), "-m", str(m), "--force", "-q", "--max-multi-return-share", "2"]) == 2
    assert "multi-return share" in capsys.readouterr().err


def test_evaluate_reports_the_rule():
    from lidarfx.classify import evaluate, format_report

    rep = evaluate([_town(6), _town(7)], classes="ground=2,vegetation=5,building=6", cv=None, leave_one_out=True,
                   buffer=0, features="eigen,plane,height_above_ground", radii=[1.0, 2.0], max_per_class=2000,
                   terrain_augment=0, classifier="rf", n_estimators=10, min_building_area=10)
    sb = rep["sections"]["leave_one_file_out"]["small_buildings"]
    assert sb["min_building_area"] == 10.0 and sb["components"] >= 6  # three houses per file at least
    assert sb["max_multi_return_share"] == 0.5 and sb["see_through_components"] == 0  # no return numbers
    assert f"{sb['relabelled_components']:,} of {sb['components']:,} predicted-building clusters" in format_report(rep)
    rep0 = evaluate([_town(6), _town(7)], classes="ground=2,vegetation=5,building=6", cv=None, leave_one_out=True,
                    buffer=0, features="eigen,plane,height_above_ground", radii=[1.0, 2.0], max_per_class=2000,
                    terrain_augment=0, classifier="rf", n_estimators=10)  # own features: no rule by default
    assert "small_buildings" not in rep0["sections"]["leave_one_file_out"]
    assert "small-building rule" not in format_report(rep0)
    # cross-validation passes the held-out points' return numbers to the see-through test
    towns = [_town(6), _town(7)]
    for t in towns:
        t["return_number"] = np.full(len(t), 2, np.uint8)  # last returns of two-return pulses
        t["number_of_returns"] = np.full(len(t), 2, np.uint8)
    rep2 = evaluate(towns, classes="ground=2,vegetation=5,building=6", cv=None, leave_one_out=True,
                    buffer=0, features="eigen,plane,height_above_ground", radii=[1.0, 2.0], max_per_class=2000,
                    terrain_augment=0, classifier="rf", n_estimators=10, min_building_area=10)
    sb2 = rep2["sections"]["leave_one_file_out"]["small_buildings"]
    assert sb2["see_through_components"] >= 6  # every house: all its points from two-return pulses
    assert rep2["sections"]["leave_one_file_out"]["metrics"]["classes"][2]["ua"] is None or \
        rep2["sections"]["leave_one_file_out"]["metrics"]["classes"][2]["pa"] < 0.05
    assert "see-through test (> 0.5 of the points from multi-return pulses)" in format_report(rep2)
