"""Feature engine: analytic values, a brute-force reference, peers and invariances."""
from __future__ import annotations

import math

import numpy as np
import pytest

import lidarfx
from lidarfx import PointCloud, synth
from lidarfx.errors import LidarfxError
from lidarfx.features import compute_features, feature_arrays
from lidarfx.features import slots as S

from reference_features import features as ref_features

EIGEN_RATIOS = ["linearity", "planarity", "sphericity", "anisotropy", "surface_variation", "verticality"]


def tilted_plane(slope, aspect, n=40_000, size=20.0, noise=0.0, seed=0):
    """Random points on a plane with the given slope and aspect (degrees)."""
    rng = np.random.default_rng(seed)
    s, a = math.radians(slope), math.radians(aspect)
    nrm = np.array([math.sin(s) * math.sin(a), math.sin(s) * math.cos(a), math.cos(s)])
    xy = rng.uniform(0, size, (n, 2))
    z = -(nrm[0] * xy[:, 0] + nrm[1] * xy[:, 1]) / nrm[2] + rng.normal(0, noise, n) if noise else -(
        nrm[0] * xy[:, 0] + nrm[1] * xy[:, 1]
    ) / nrm[2]
    return np.c_[xy, z], nrm


def interior(xyz, margin, size=20.0):
    return (xyz[:, 0] > margin) & (xyz[:, 0] < size - margin) & (xyz[:, 1] > margin) & (xyz[:, 1] < size - margin)


def scene(n=6000, seed=3):
    """A small cloud with structure: a ground plane, a wall, a roof edge, a blob of 'vegetation'."""
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(0, 10, n), rng.uniform(0, 10, n), rng.normal(0, 0.02, n)]
    w = np.c_[rng.uniform(0, 10, n // 2), np.full(n // 2, 5.0) + rng.normal(0, 0.01, n // 2), rng.uniform(0, 3, n // 2)]
    v = rng.normal([7, 7, 1.5], 0.5, (n // 3, 3))
    return np.vstack([g, w, v])


# --------------------------------------------------------------------------- analytic


@pytest.mark.parametrize("kind", ["line", "plane", "plane_border", "edge", "volume"])
def test_closed_form_eigenvalues(kind):
    density = {"line": 20000.0, "volume": 60000.0}.get(kind, 20000.0)
    cloud = getattr(synth, kind)(1.0, density=density, sampling="grid", seed=0)
    f = feature_arrays(cloud.xyz, "eigen", radius=1.0, query_xyz=np.zeros((1, 3)))
    got = np.array([f["eigenvalue1"][0], f["eigenvalue2"][0], f["eigenvalue3"][0]])
    want = np.array(synth.analytic_eigenvalues(kind))
    np.testing.assert_allclose(got, want, rtol=0.01, atol=0.01 * want.max())


def test_closed_form_eigenvalues_random_rotation():
    """The eigenvalues do not depend on the orientation of the structure."""
    cloud = synth.edge(1.0, density=20000.0, sampling="grid", rotation="random", seed=4)
    f = feature_arrays(cloud.xyz, "eigen", radius=1.0, query_xyz=np.zeros((1, 3)))
    got = [f[f"eigenvalue{i}"][0] for i in (1, 2, 3)]
    np.testing.assert_allclose(got, synth.analytic_eigenvalues("edge"), rtol=0.01, atol=0.0025)


def test_plane_planarity_and_line_linearity():
    p = synth.plane(1.0, density=5000.0, sampling="grid")
    fp = feature_arrays(p.xyz, "eigen", radius=1.0, query_xyz=np.zeros((1, 3)))
    assert fp["planarity"][0] > 0.99 and fp["sphericity"][0] < 1e-6 and fp["linearity"][0] < 0.01
    ln = synth.line(1.0, density=2000.0, sampling="grid")
    fl = feature_arrays(ln.xyz, "eigen", radius=1.0, query_xyz=np.zeros((1, 3)))
    assert fl["linearity"][0] > 0.999 and fl["planarity"][0] < 1e-3
    vol = synth.volume(1.0, density=20000.0, sampling="grid")
    fv = feature_arrays(vol.xyz, "eigen", radius=1.0, query_xyz=np.zeros((1, 3)))
    assert fv["sphericity"][0] > 0.98
    assert fv["omnivariance"][0] == pytest.approx(1 / 3, rel=0.01)  # (1/3·1/3·1/3)^(1/3)
    assert fv["eigenentropy"][0] == pytest.approx(math.log(3), rel=0.01)


@pytest.mark.parametrize("slope,aspect", [(10, 0), (30, 120), (45, 225), (60, 90), (80, 300)])
def test_slope_and_aspect_of_tilted_planes(slope, aspect):
    xyz, nrm = tilted_plane(slope, aspect)
    cloud = PointCloud(xyz)
    out = compute_features(cloud, ["slope", "aspect", "normal_x", "normal_y", "normal_z"], radius=0.5)
    sel = interior(xyz, 1.0)
    assert np.nanmax(np.abs(out["slope"][sel] - slope)) < 0.1
    d_aspect = (out["aspect"][sel] - aspect + 180) % 360 - 180
    assert np.nanmax(np.abs(d_aspect)) < 0.1
    n = np.c_[out["normal_x"], out["normal_y"], out["normal_z"]][sel]
    assert np.nanmin(n @ nrm) > math.cos(math.radians(0.1))
    assert np.isfinite(out["slope"][sel]).mean() > 0.95


def test_aspect_stays_below_360_in_float32():
    """A north-facing plane: atan2 just below 0 gives 359.99999…, which float32 would round to 360."""
    xyz, _ = tilted_plane(30, 0)
    out = compute_features(PointCloud(xyz), ["aspect", "msac_aspect"], radius=0.5)
    for name in ("aspect", "msac_aspect"):
        a = out[name][np.isfinite(out[name])]
        assert a.dtype == np.float32 and a.min() >= 0.0 and a.max() < 360.0, name
        assert ((a < 0.1) | (a > 359.9)).mean() > 0.99  # all of them north


def test_slope_with_noise():
    xyz, _ = tilted_plane(35, 200, noise=0.01)
    out = compute_features(PointCloud(xyz), ["slope", "aspect"], radius=1.0)
    sel = interior(xyz, 1.5)
    assert abs(np.median(out["slope"][sel]) - 35) < 0.1
    assert abs(np.median(out["aspect"][sel]) - 200) < 0.1


def test_echo_ratio_on_planes():
    flat, _ = tilted_plane(0, 0)
    out = compute_features(PointCloud(flat), "density", radius=0.5)
    sel = interior(flat, 0.6)
    assert np.all(out["echo_ratio"][sel] == 100)
    assert np.all(out["echo_ratio_slope"][sel] == 100)
    for slope in (20, 45, 70):
        xyz, _ = tilted_plane(slope, 60)
        out = compute_features(PointCloud(xyz), "density", radius=0.5)
        sel = interior(xyz, 2.0)
        # the plain echo ratio sees a tilted plane as cos(slope) ...
        assert np.median(out["echo_ratio"][sel]) == pytest.approx(100 * math.cos(math.radians(slope)), rel=0.03)
        # ... the slope-adaptive one says 100 % on any plane
        assert np.all(out["echo_ratio_slope"][sel] == 100)
    # and clearly less in a volume (vegetation)
    vol = synth.volume(1.0, density=3000.0)
    fv = compute_features(vol, "density", radius=0.5)
    assert np.nanmedian(fv["echo_ratio_slope"]) < 60


def test_density_counts():
    flat, _ = tilted_plane(0, 0, n=40_000, size=20.0)
    out = compute_features(PointCloud(flat), "density", radius=1.0)
    sel = interior(flat, 1.1)
    assert np.median(out["density_2d"][sel]) == pytest.approx(100.0, rel=0.03)  # 40000 / 400 m²
    assert np.median(out["density_3d"][sel]) == pytest.approx(100.0 * 3 / 4, rel=0.03)  # π r² n / (4/3 π r³)


def test_quadric_curvature_of_paraboloid_and_sphere():
    g = np.arange(-1.0, 1.0001, 0.02)
    x, y = np.meshgrid(g, g)
    x, y = x.ravel(), y.ravel()
    par = np.c_[x, y, 0.5 * x**2 + 0.1 * y**2]
    f = feature_arrays(par, "curvature", radius=0.3, query_xyz=np.zeros((1, 3)))
    assert f["k1"][0] == pytest.approx(1.0, abs=2e-3)
    assert f["k2"][0] == pytest.approx(0.2, abs=2e-3)
    assert f["gauss_curvature"][0] == pytest.approx(0.2, abs=2e-3)
    assert f["mean_curvature"][0] == pytest.approx(0.6, abs=2e-3)
    R = 5.0
    zs = np.sqrt(np.clip(R * R - x**2 - y**2, 0, None))
    sph = np.c_[x, y, zs]
    fs = feature_arrays(sph, "curvature", radius=0.5, query_xyz=np.array([[0.0, 0.0, R]]))
    # a dome curves away from its upward normal: negative curvature 1/R
    assert fs["k1"][0] == pytest.approx(-1 / R, abs=1e-3)
    assert fs["k2"][0] == pytest.approx(-1 / R, abs=1e-3)


def test_quadric_inlier_ratio_on_curved_surface_and_volume():
    """A paraboloid lies on its quadric (ratio 1) where a plane keeps only part of it;
    a random volume stays far from any surface; 5 neighbours give NaN."""
    g = np.arange(-1.5, 1.5001, 0.03)
    x, y = np.meshgrid(g, g)
    x, y = x.ravel(), y.ravel()
    par = np.c_[x, y, 0.5 * x**2 + 0.2 * y**2]
    f = feature_arrays(par, ["plane_inlier_ratio", "quadric_inlier_ratio"], radius=1.0, query_xyz=np.zeros((1, 3)))
    assert f["quadric_inlier_ratio"][0] == pytest.approx(1.0)
    assert f["plane_inlier_ratio"][0] < 0.8
    rng = np.random.default_rng(0)
    vol = rng.uniform(-1, 1, (20000, 3))
    fv = feature_arrays(vol, "quadric", radius=1.0, query_xyz=np.zeros((1, 3)))
    # the slab |h| <= d_max = 0.1 of a unit ball holds 3/4 (0.2 - 0.002/3) = 0.1495 of it
    assert fv["quadric_inlier_ratio"][0] == pytest.approx(0.1495, abs=0.015)
    few = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0.01], [0.05, 0.02, 0.0]], float)
    assert np.isnan(feature_arrays(few, "quadric", radius=0.5, query_xyz=np.zeros((1, 3)))["quadric_inlier_ratio"][0])


def test_not_computable_is_nan():
    xyz = np.array([[0, 0, 0], [0.1, 0, 0], [5, 5, 5], [5.1, 5, 5], [5, 5.1, 5], [5, 5, 5.1], [5.05, 5.05, 5.0]], float)
    f = feature_arrays(xyz, ["eigen", "curvature", "n_neighbours"], radius=0.3)
    assert np.isnan(f["planarity"][0]) and f["n_neighbours"][0] == 2  # 2 neighbours: no covariance
    assert not np.isnan(f["planarity"][2])
    assert np.isnan(f["k1"][2])  # 5 neighbours < 6: no quadric
    flat, _ = tilted_plane(0, 0, n=5000)
    out = compute_features(PointCloud(flat), ["aspect", "slope"], radius=0.5)
    assert np.all(np.isnan(out["aspect"])) and np.nanmax(out["slope"]) < 1e-4


# ---------------------------------------------------------------- brute-force reference


@pytest.mark.parametrize("kind,height", [("sphere", None), ("cylinder", None), ("sphere", 0.2), ("cylinder", 0.3)])
def test_every_feature_matches_bruteforce_reference(kind, height):
    xyz = scene()
    r = 0.6
    rng = np.random.default_rng(1)
    qi = rng.choice(len(xyz), 60, replace=False)
    out = compute_features(PointCloud(xyz), "all", radius=r, neighbourhood=kind, query=qi, height=height)
    skip = {"return_ratio"} | {S.NAMES[s] for s in S.GROUPS["msac"]} | {S.NAMES[s] for s in S.GROUPS["eigenvectors"]}
    checked = 0
    for row, i in enumerate(qi):
        ref = ref_features(xyz, xyz[i], r, kind=kind, height=np.inf if height is None else height)
        for name in out.meta["features"]:
            if name in skip:
                continue
            got = float(out[name][row])
            want = float(ref.get(name, np.nan))
            if name.startswith("normal_") or name == "aspect":
                continue  # compared below, up to orientation of near-vertical normals
            tol = 2e-3 if name in ("k1", "k2", "mean_curvature", "gauss_curvature", "dh_skewness") else 2e-5
            scale = max(1.0, abs(want))
            assert (np.isnan(got) and np.isnan(want)) or abs(got - want) <= tol * scale, (name, i, got, want)
            checked += 1
        if ref["n_neighbours"] >= 3:
            n_got = np.array([out["normal_x"][row], out["normal_y"][row], out["normal_z"][row]])
            n_ref = np.array([ref["normal_x"], ref["normal_y"], ref["normal_z"]])
            assert abs(n_got @ n_ref) > 1 - 1e-5
            if abs(n_ref[2]) > 1e-3 and ref["slope"] > 1:
                da = (out["aspect"][row] - ref["aspect"] + 180) % 360 - 180
                assert abs(da) < 1e-2
    assert checked > 60 * 40


def test_distribution_features_on_plane_border():
    """Centroid offset of a half disc: 4/(3π); z asymmetry 0 on a plane; occupancy."""
    cloud = synth.plane_border(1.0, density=20000.0, sampling="grid")
    f = feature_arrays(cloud.xyz, "distribution", radius=1.0, query_xyz=np.zeros((1, 3)))
    assert f["centroid_offset"][0] == pytest.approx(4 / (3 * math.pi), rel=0.01)
    assert f["z_asymmetry"][0] == 0.0
    assert f["octant_occupancy"][0] == 2  # z == 0 counts as 'not above', y >= 0 half, x both signs


def test_histogram_features_two_levels():
    """Points on two levels 2 m apart: two peaks, at the two ends of the scaled range."""
    rng = np.random.default_rng(0)
    lo = np.c_[rng.uniform(0, 4, 3000), rng.uniform(0, 4, 3000), np.zeros(3000)]
    hi = np.c_[rng.uniform(0, 4, 1000), rng.uniform(0, 4, 1000), np.full(1000, 2.0)]
    xyz = np.vstack([lo, hi])
    f = feature_arrays(xyz, "histogram", radius=0.5, query_xyz=np.array([[2.0, 2.0, 0.0]]))
    assert f["dh_peaks"][0] == 2
    # upper level: dh = -2 m -> scaled -1 -> bin 0; own level: dh = 0 -> bin 5
    assert f["dh_peak_distance"][0] == 5
    assert f["dh_max_bin"][0] == pytest.approx(0.1)  # centre of bin 5 (the larger peak)
    assert f["dh_share_above"][0] == pytest.approx(0.25, abs=0.03)
    assert f["dh_share_below"][0] == 0.0


# ----------------------------------------------------------------------- invariances


def test_utm_shift_gives_identical_features():
    xyz = scene()
    a = compute_features(PointCloud(xyz), "all", radius=0.5)
    b = compute_features(PointCloud(xyz + [500000.0, 5000000.0, 0.0]), "all", radius=0.5)
    for name in a.meta["features"]:
        np.testing.assert_allclose(a[name], b[name], rtol=1e-5, atol=1e-5, err_msg=name)


def test_multiscale_equals_separate_runs():
    xyz = scene()
    cloud = PointCloud(xyz)
    groups = ["eigen", "plane", "density", "height", "histogram", "distribution", "curvature", "count"]
    multi = compute_features(cloud, groups, radii=[0.25, 0.5, 1.0])
    for r in (0.25, 0.5, 1.0):
        single = compute_features(cloud, groups, radius=r)
        for name in single.meta["features"]:
            # omnivariance is a cube root: rounding noise of λ3 ≈ 0 (1e-17·λ1) shows as 1e-6
            atol = {"omnivariance": 1e-5, "k1": 1e-4, "k2": 1e-4, "mean_curvature": 1e-4, "gauss_curvature": 1e-4}.get(name, 1e-6)
            np.testing.assert_allclose(multi[f"{name}_r{r:.2f}"], single[name], rtol=1e-5, atol=atol, err_msg=name)


def test_query_subset_equals_full_run():
    xyz = scene()
    cloud = PointCloud(xyz, {"label": np.arange(len(xyz))})
    full = compute_features(cloud, ["eigen", "plane", "msac"], radius=0.5)
    qi = np.arange(0, len(xyz), 7)
    sub = compute_features(cloud, ["eigen", "plane", "msac"], radius=0.5, query=qi)
    assert len(sub) == len(qi) and np.array_equal(sub["label"], qi)
    for name in sub.meta["features"]:
        np.testing.assert_allclose(sub[name], full[name][qi], rtol=1e-6, atol=1e-6, err_msg=name)
    mask = np.zeros(len(xyz), bool)
    mask[qi] = True
    np.testing.assert_array_equal(compute_features(cloud, "planarity", radius=0.5, query=mask)["planarity"], sub["planarity"])


# ----------------------------------------------------------------- neighbourhood kinds


def test_knn_with_more_neighbours_than_points_takes_them_all():
    """k above the cloud's size means every point (the search asks for n; the answer is the same
    as with k = n), and the k-th distances are found block by block (a block smaller than the
    query set gives the same radii)."""
    from lidarfx.features import api

    xyz = scene()[:40]
    a = compute_features(PointCloud(xyz), ["eigen", "n_neighbours"], neighbourhood="knn", k=40)
    b = compute_features(PointCloud(xyz), ["eigen", "n_neighbours"], neighbourhood="knn", k=5000)
    assert np.all(a["n_neighbours"] == 40)
    for name in ("n_neighbours", "planarity", "eigenvalue1"):
        np.testing.assert_array_equal(a[name], b[name])
    old = api._KNN_ENTRIES
    try:
        api._KNN_ENTRIES = 7 * 40  # blocks of 7 queries
        c = compute_features(PointCloud(xyz), ["eigen", "n_neighbours"], neighbourhood="knn", k=40)
    finally:
        api._KNN_ENTRIES = old
    for name in ("n_neighbours", "planarity", "eigenvalue1"):
        np.testing.assert_array_equal(a[name], c[name])


def test_knn_neighbourhood_uses_exactly_k_points():
    from scipy.spatial import cKDTree

    xyz = scene()
    out = compute_features(PointCloud(xyz), ["eigen", "n_neighbours"], neighbourhood="knn", k=12)
    assert np.all(out["n_neighbours"] == 12)
    _, nn = cKDTree(xyz).query(xyz[:50], 12)
    for i in range(50):
        w = np.linalg.eigvalsh(np.cov(xyz[nn[i]].T, bias=True))[::-1]
        assert out["planarity"][i] == pytest.approx((w[1] - w[2]) / w[0], abs=1e-5)
    capped = compute_features(PointCloud(xyz), ["n_neighbours"], neighbourhood="knn", k=500, radius=0.3)
    plain = compute_features(PointCloud(xyz), ["n_neighbours"], radius=0.3)
    np.testing.assert_array_equal(capped["n_neighbours"], np.minimum(plain["n_neighbours"], 500))


def test_scanner_orients_normals():
    rng = np.random.default_rng(0)
    wall = np.c_[np.zeros(4000), rng.uniform(0, 10, 4000), rng.uniform(0, 5, 4000)]
    front = compute_features(PointCloud(wall), "normal_x", radius=0.5, scanner=(5.0, 5.0, 1.5))
    back = compute_features(PointCloud(wall), "normal_x", radius=0.5, scanner=(-5.0, 5.0, 1.5))
    assert np.all(front["normal_x"] > 0.999) and np.all(back["normal_x"] < -0.999)


def test_msac_is_robust_to_outliers():
    rng = np.random.default_rng(2)
    xyz, nrm = tilted_plane(25, 40, n=20000, size=10.0, noise=0.005)
    out_pts = xyz[rng.choice(len(xyz), 8000)] + np.c_[np.zeros((8000, 2)), rng.uniform(0.2, 0.6, 8000)]
    cloud = PointCloud(np.vstack([xyz, out_pts]))
    out = compute_features(cloud, ["msac", "normal_x", "normal_y", "normal_z"], radius=0.5, seed=3)
    sel = np.r_[interior(xyz, 1.0, 10.0), np.zeros(8000, bool)]
    n_msac = np.c_[out["msac_normal_x"], out["msac_normal_y"], out["msac_normal_z"]][sel]
    n_pca = np.c_[out["normal_x"], out["normal_y"], out["normal_z"]][sel]
    ang_msac = np.degrees(np.arccos(np.clip(np.abs(n_msac @ nrm), 0, 1)))
    ang_pca = np.degrees(np.arccos(np.clip(np.abs(n_pca @ nrm), 0, 1)))
    assert np.median(ang_msac) < 0.5 < np.median(ang_pca)
    # the inlier share is the share of neighbours within d_max of the true plane
    from scipy.spatial import cKDTree

    pts = cloud.xyz
    tree = cKDTree(pts)
    for i in np.flatnonzero(sel)[::500]:
        nb = pts[tree.query_ball_point(pts[i], 0.5)]
        true_share = np.mean(np.abs((nb - xyz[0]) @ nrm) <= 0.1)
        assert out["msac_inlier_ratio"][i] == pytest.approx(true_share, abs=0.02)
    assert np.median(out["msac_slope"][sel]) == pytest.approx(25, abs=0.5)
    again = compute_features(cloud, ["msac"], radius=0.5, seed=3)
    np.testing.assert_array_equal(again["msac_slope"], out["msac_slope"])


# ----------------------------------------------------------------------- peers


def test_ratio_features_equal_jakteristics():
    jak = pytest.importorskip("jakteristics")
    xyz = scene(n=4000)
    names = ["linearity", "planarity", "sphericity", "anisotropy", "surface_variation", "verticality"]
    theirs = jak.compute_features(xyz, 0.5, feature_names=names + ["number_of_neighbors"], num_threads=1)
    ours = compute_features(PointCloud(xyz), names + ["n_neighbours"], radius=0.5)
    np.testing.assert_array_equal(ours["n_neighbours"], theirs[:, -1])
    ok = ours["n_neighbours"] >= 3
    for c, name in enumerate(names):
        np.testing.assert_allclose(ours[name][ok], theirs[ok, c], atol=1e-5, err_msg=name)


def test_cloudcompare_convention_matches_jakteristics_raw_eigenvalues():
    jak = pytest.importorskip("jakteristics")
    xyz = scene(n=3000)
    theirs = jak.compute_features(xyz, 0.5, feature_names=["eigenvalue1", "omnivariance", "number_of_neighbors"], num_threads=1)
    ours = compute_features(PointCloud(xyz), ["eigenvalue1", "omnivariance"], radius=0.5, convention="cloudcompare")
    n = theirs[:, 2]
    ok = n >= 3
    # jakteristics divides by n - 1, lidarfx by n: raw eigenvalues differ by that factor
    np.testing.assert_allclose(ours["eigenvalue1"][ok] * n[ok] / (n[ok] - 1), theirs[ok, 0], rtol=1e-4)
    np.testing.assert_allclose(ours["omnivariance"][ok] * n[ok] / (n[ok] - 1), theirs[ok, 1], rtol=1e-3, atol=1e-6)


def test_pdal_convention_matches_pgeof():
    """√λ ratios as pgeof computes them; pgeof adds ε = 1e-3 m to its denominators (include/pca.hpp)."""
    pgeof = pytest.importorskip("pgeof")
    from lidarfx.neighbors import NeighborIndex

    xyz = scene(n=3000)
    off, nn, _ = NeighborIndex(xyz, 0.5).query_radius(xyz, 0.5)
    theirs = pgeof.compute_features(xyz.astype(np.float32), nn.astype(np.uint32), off.astype(np.uint32), k_min=3)
    names = ["linearity", "planarity", "sphericity"]
    ours = compute_features(PointCloud(xyz), names + ["eigenvalue1"], radius=0.5, convention="pdal")
    # pgeof works in float32: √λ3 of a 3-point neighbourhood (λ3 = 0) is noise of ~3e-4 there
    ok = np.diff(off) >= 6
    mu1 = np.sqrt(ours["eigenvalue1"][ok].astype(float))
    for c, name in enumerate(names):
        np.testing.assert_allclose(ours[name][ok] * mu1 / (mu1 + 1e-3), theirs[ok, c], atol=2e-5, err_msg=name)


def test_radii_that_would_share_a_name_are_refused():
    with pytest.raises(LidarfxError, match="same attribute suffix"):
        compute_features(PointCloud(scene(n=300)), "planarity", radii=[0.12, 0.121])


# --------------------------------------------------------------------------- API


def test_feature_names_and_errors():
    cloud = PointCloud(scene(n=500))
    with pytest.raises(LidarfxError, match="unknown feature 'planarty'"):
        compute_features(cloud, "planarty", radius=0.5)
    with pytest.raises(LidarfxError, match="radius"):
        compute_features(cloud, "eigen")
    with pytest.raises(LidarfxError, match="k >= 1"):
        compute_features(cloud, "eigen", neighbourhood="knn")
    with pytest.raises(LidarfxError, match="is for the 'knn' neighbourhood, not 'sphere'"):
        compute_features(cloud, "eigen", radius=0.5, k=10)  # a k that would be ignored is refused
    out = compute_features(cloud, "eigen,slope", radius=0.5)
    assert out.meta["features"] == [S.NAMES[s] for s in S.GROUPS["eigen"]] + ["slope"]
    assert all(out[n].dtype == np.float32 for n in out.meta["features"])
    multi = compute_features(cloud, "planarity", radii=[0.5, 0.25])
    assert multi.meta["features"] == ["planarity_r0.25", "planarity_r0.50"]
    assert lidarfx.compute_features is compute_features


def test_return_ratio():
    cloud = PointCloud(np.zeros((3, 3)), {"return_number": np.array([1, 2, 3]), "number_of_returns": np.array([3, 3, 3])})
    out = compute_features(cloud, "echo")
    np.testing.assert_allclose(out["return_ratio"], [1 / 3, 2 / 3, 1])


def test_height_above_ground_feature():
    """From the class-2 ground when present; from the ground filter otherwise."""
    rng = np.random.default_rng(5)
    g = np.c_[rng.uniform(0, 40, 8000), rng.uniform(0, 40, 8000), np.zeros(8000)]
    g[:, 2] = 0.05 * g[:, 0]  # a gentle slope
    roof = np.c_[rng.uniform(15, 25, 1500), rng.uniform(15, 25, 1500), np.zeros(1500)]
    roof[:, 2] = 0.05 * roof[:, 0] + 6.0
    xyz = np.vstack([g, roof])
    cls = np.r_[np.full(8000, 2), np.full(1500, 6)].astype(np.uint8)
    labelled = compute_features(PointCloud(xyz, {"classification": cls}), "height_above_ground")
    np.testing.assert_allclose(labelled["height_above_ground"][8000:], 6.0, atol=1e-3)
    np.testing.assert_allclose(labelled["height_above_ground"][:8000], 0.0, atol=1e-3)
    unlabelled = compute_features(PointCloud(xyz), ["height_above_ground", "planarity"], radius=1.0, query=np.arange(8000, 9500))
    assert np.median(unlabelled["height_above_ground"]) == pytest.approx(6.0, abs=0.05)
    assert "height_above_ground" not in compute_features(PointCloud(xyz), "all", radius=1.0).meta["features"]


@pytest.mark.parametrize(
    "features,kw",
    [
        ("eigen,plane,density,return_ratio", {"radii": [0.3, 0.6]}),
        ("msac,curvature,histogram", {"radius": 0.5}),
        ("eigen", {"neighbourhood": "knn", "k": 12}),
    ],
)
def test_stream_features_equal_compute_features(features, kw):
    from lidarfx.features import stream_features

    cloud = synth.plane(3.0, density=300.0, noise=0.01, seed=4, origin=(500000.0, 5000000.0, 100.0))
    cloud["return_number"] = np.ones(len(cloud), np.uint8)
    cloud["number_of_returns"] = np.full(len(cloud), 2, np.uint8)
    ref = compute_features(cloud, features, **kw)
    names, fill = stream_features(cloud, features, **kw)
    assert names == ref.meta["features"]
    cuts = [0, 1, 777, 1500, len(cloud)]  # uneven pieces, one of a single point
    pieces = [fill(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
    for name in names:
        got = np.concatenate([p[name] for p in pieces])
        np.testing.assert_array_equal(got, ref[name], err_msg=name)


def test_stream_features_checks_before_work():
    from lidarfx.features import stream_features

    cloud = synth.plane(1.0, density=100.0, seed=1)
    with pytest.raises(LidarfxError, match="k >= 1"):
        stream_features(cloud, "eigen", neighbourhood="knn")
    with pytest.raises(LidarfxError, match="give a radius"):
        stream_features(cloud, "eigen")


@pytest.mark.parametrize("want_v1", [False, True])
def test_eigh3_matches_lapack(want_v1):
    """The closed-form 3×3 solver against LAPACK on random, plane-like, line-like,
    degenerate (rank 1, identity multiple, zero) covariance matrices."""
    from lidarfx.features.eigen import eigh3

    rng = np.random.default_rng(7)
    mats = []
    for scale in ([1, 1, 1], [1, 1, 1e-3], [1, 1e-3, 1e-3], [1, 1e-8, 0], [5, 5, 5]):
        for _ in range(300):
            b = rng.normal(size=(3, 3)) * np.asarray(scale, float)
            r, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            mats.append(r @ (b.T @ b) @ r.T)
    mats += [np.eye(3) * 2.5, np.zeros((3, 3)), np.outer([1, 2, 3], [1, 2, 3])]
    lam, v1, v3 = np.empty(3), np.empty(3), np.empty(3)
    for a in mats:
        eigh3(a[0, 0], a[0, 1], a[0, 2], a[1, 1], a[1, 2], a[2, 2], lam, v1, v3, want_v1)
        w, v = np.linalg.eigh(a)
        # the trigonometric cubic loses digits on near-double roots: errors up to
        # ~1e-8 λ1 (measured 4.5e-9 / 8.9e-9), irrelevant for every ratio feature
        np.testing.assert_allclose(lam, np.clip(w[::-1], 0, None), rtol=1e-9, atol=2e-8 * max(w[-1], 1e-300))
        assert abs(np.linalg.norm(v3) - 1) < 1e-12
        # the normal is an eigenvector of the smallest eigenvalue: |A v3 - λ3 v3| small
        assert np.linalg.norm(a @ v3 - lam[2] * v3) <= 1e-7 * max(w[-1], 1e-300) + 1e-300
        if want_v1:
            assert np.linalg.norm(a @ v1 - lam[0] * v1) <= 1e-7 * max(w[-1], 1e-300) + 1e-300


def test_resolve_leaves_groups_and_features_out():
    from lidarfx.features.registry import resolve

    full = resolve("all").names
    left = resolve("all,-quadric,-slope").names
    assert left == [n for n in full if n not in ("quadric_inlier_ratio", "slope")]  # order kept
    assert resolve(["eigen", "-eigenentropy"]).names == [n for n in resolve("eigen").names if n != "eigenentropy"]
    assert resolve("echo,eigen,-echo").names == resolve("eigen").names  # a per-point group too
    with pytest.raises(LidarfxError, match="cannot leave out 'plane'"):
        resolve("eigen,-plane")
    with pytest.raises(LidarfxError, match="unknown feature 'planarty'"):
        resolve("eigen,-planarty")
    with pytest.raises(LidarfxError, match="all were left out"):
        resolve("eigen,-eigen")
    # left to right: a removal takes out what came before it, a later name adds it back
    assert set(resolve("all,-eigen,linearity").names) == set(full) - set(resolve("eigen").names) | {"linearity"}
    assert resolve("eigen,-eigen,planarity").names == ["planarity"]
    with pytest.raises(LidarfxError, match="requested before it"):
        resolve("-eigen,eigen")
    with pytest.raises(LidarfxError, match="one '-' leaves"):
        resolve("eigen,--slope")
    with pytest.raises(LidarfxError, match="classifier's default list"):
        resolve("default")  # a classifier keyword: the feature engine says where it belongs
