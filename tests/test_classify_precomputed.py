"""``classify predict --precomputed`` against a plain predict (issue 31 B; docs/classification.md §4).

A plain predict thins the neighbour cloud of a cloud denser than the model's limit
(``max_disc_points`` per disc of the smallest radius: 39.8 points/m² for the default model)
and leaves virtual / withheld / synthetic points out of every neighbourhood; ``lidarfx
features`` does neither.  Below the limit, on a cloud of usable points only, the features
read back from the file are the model's own to the bit (float32 both ways) and so are the
classes; on a denser cloud (crop_1.laz, 81 points/m²) they are not, and the prediction says so.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx.classify import train
from lidarfx.cli import main
from lidarfx.errors import LidarfxWarning

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
CROP = REAL / "crop_1.laz"


def scene(n: int, seed: int = 0) -> lidarfx.PointCloud:
    """``n`` points over 20 m × 20 m: ground (z < 0.5) and vegetation with two returns."""
    rng = np.random.default_rng(seed)
    xyz = np.column_stack([rng.uniform(0, 20, n), rng.uniform(0, 20, n), rng.uniform(0, 1, n)])
    cls = np.where(xyz[:, 2] > 0.5, 5, 2).astype(np.uint8)
    nr = np.where(cls == 5, 2, 1).astype(np.uint8)
    return lidarfx.PointCloud(xyz, {"classification": cls, "return_number": np.ones(n, np.uint8),
                                    "number_of_returns": nr})


def precomputed(model, cloud):
    """The model's features as --precomputed reads them from a file written by ``lidarfx features``."""
    fx = lidarfx.compute_features(cloud, "planarity,linearity", radii=[1.0, 2.0])
    model.features.precomputed = True
    try:
        return model.feature_matrix(fx), fx
    finally:
        model.features.precomputed = False


def no_lidarfx_warning(fn, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("error", LidarfxWarning)
        return fn(*a, **k)


@pytest.fixture(scope="module")
def model():
    return train(scene(6000), classes="2,5", classifier="rf", n_estimators=10,
                 features="planarity,linearity,number_of_returns", radii=[1.0, 2.0])


def test_precomputed_features_are_the_models_below_the_thinning_limit(model):
    sparse = scene(6000, seed=1)  # 15 points/m²: never thinned
    X_pre, fx = no_lidarfx_warning(precomputed, model, sparse)
    np.testing.assert_array_equal(X_pre, model.feature_matrix(sparse))
    model.features.precomputed = True
    try:
        pre = no_lidarfx_warning(model.predict, fx)
    finally:
        model.features.precomputed = False
    np.testing.assert_array_equal(pre, model.predict(sparse))


def test_precomputed_features_of_a_dense_cloud_differ_and_it_says_so(model):
    dense = scene(24000, seed=2)  # 60 points/m²: a plain predict thins the neighbours to 39.8
    with pytest.warns(LidarfxWarning, match=r"60(\.\d)? points/m² is denser than the 39\.8 .*lidarfx features"):
        X_pre, fx = precomputed(model, dense)
    X = model.feature_matrix(dense)
    assert not np.array_equal(X[:, :4], X_pre[:, :4])  # the neighbourhood features: another neighbour cloud
    np.testing.assert_array_equal(X[:, 4], X_pre[:, 4])  # number_of_returns: read from the cloud both ways
    # the thinning is the only difference: a model that never thins reads its own features back
    model.features.max_disc_points = None
    try:
        X_all = model.feature_matrix(dense)
        X_pre_all, _ = no_lidarfx_warning(precomputed, model, dense)
    finally:
        model.features.max_disc_points = 125.0
    np.testing.assert_array_equal(X_pre_all, X_all)


def test_precomputed_warns_about_points_a_plain_predict_leaves_out(model):
    cloud = scene(6000, seed=3)
    rn = np.asarray(cloud["return_number"]).copy()
    rn[:50] = 0  # IGN virtual points: return number 0, never neighbours in a plain predict
    cloud["return_number"] = rn
    fx = lidarfx.compute_features(cloud, "planarity,linearity", radii=[1.0, 2.0])
    model.features.precomputed = True
    try:
        with pytest.warns(LidarfxWarning, match=r"50 virtual, withheld or synthetic points"):
            model.check(fx, "virtual.laz")
    finally:
        model.features.precomputed = False


@pytest.mark.skipif(not CROP.is_file(), reason=f"real LiDAR file not found (shared real-data folder): {CROP}")
def test_precomputed_on_crop_1_differs_only_by_the_thinning(tmp_path):
    """crop_1.laz (IGN, 81 points/m² of usable points, no virtual points) in a 25 m window:
    the features file written by the command the model names (as .las: LAZ would cost more to
    read than the features cost to compute) gives other classes to a small share of the points
    (the default model on the whole file: 1 409 of 210 582 points, 0.67 %), with a warning; with
    the thinning off the model reads its own features back and the classes are the same."""
    crop = lidarfx.read(CROP)
    x0, y0 = crop.xyz[:, 0].min(), crop.xyz[:, 1].min()
    win = crop.subset((crop.xyz[:, 0] < x0 + 25) & (crop.xyz[:, 1] < y0 + 25))
    src = tmp_path / "win.las"
    lidarfx.write(win, src)
    win = lidarfx.read(src)
    model = train(win, classes="ground=2,vegetation=3+4+5", classifier="rf", n_estimators=20,
                  features="eigen,plane,number_of_returns", radii=[1.0, 2.0], max_per_class=2000)
    cmd = model.features.features_command()
    fx_path = tmp_path / "win_fx.las"
    assert main(["features", str(src), str(fx_path), *cmd.split()[4:], "-q"]) == 0
    fx = lidarfx.read(fx_path)
    plain = model.predict(win)
    model.features.precomputed = True
    with pytest.warns(LidarfxWarning, match="is denser than the 39.8 points/m²"):
        pre = model.predict(fx)
    share = float((pre != plain).mean())
    assert 0 < share < 0.03, share
    model.features.precomputed = False
    model.features.max_disc_points = None
    plain_all = model.predict(win)
    model.features.precomputed = True
    np.testing.assert_array_equal(no_lidarfx_warning(model.predict, fx), plain_all)
