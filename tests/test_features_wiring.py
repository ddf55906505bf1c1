"""How the feature engine's options and boundaries are wired: each test against an independent answer.

tests/test_features.py checks the formulas (closed forms, a brute-force reference on random
clouds, peers).  Random clouds never put a neighbour at exactly the radius and always use the
default options, so these tests cover what they cannot see:

* neighbourhood boundaries are inclusive (‖d‖ ≤ r, |dz| ≤ h) — on integer grids, where
  neighbours lie at exactly r: the sphere, the height-limited cylinder, ``NeighborIndex``,
  the horizontal shells of a multi-scale run, kNN ties (docs/features.md §1);
* closed forms of an isotropic and of a coincident neighbourhood (NaN rules, docs §3.1);
* the kNN radius that enters densities: d_K, or the cap R when fewer than K lie within R;
* the Python options reach the kernels (``d_max``, ``hist_bins``, ``msac_threshold``,
  ``msac_iterations``, the cylinder of MSAC, ``scanner`` on UTM coordinates) and
  ``stream_features`` passes every option on;
* the 80° slope cap of ``echo_ratio_slope`` and ``eigenvector1``'s documented sign rule;
* every ``lidarfx features`` option reaches the computation (``--d-max``, ``--height``,
  ``--convention``, ``--bins``, ``--seed``, ``--scanner``, ``-k``, ``-n cylinder``).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import lidarfx
from lidarfx import PointCloud
from lidarfx.cli import main
from lidarfx.errors import LidarfxError
from lidarfx.features import compute_features, stream_features
from lidarfx.neighbors import NeighborIndex

from reference_features import features as ref_features

UTM = np.array([500000.0, 5000000.0, 100.0])


def int_grid(n=5, dims=3, offset=UTM):
    """Integer grid 0..n-1 per axis (z = 0 for dims=2), shifted to UTM-sized coordinates
    (integers: every coordinate and every local difference is exact in float64)."""
    axes = [np.arange(n, dtype=float)] * dims
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, dims)
    if dims == 2:
        g = np.c_[g, np.zeros(len(g))]
    return g + offset


def index_of(xyz, p):
    return int(np.flatnonzero(np.all(xyz == p, axis=1))[0])


def nearest(xyz, p):
    return int(np.argmin(((xyz - p) ** 2).sum(1)))


def sphere_count(xyz, p, r):
    return int((((xyz - p) ** 2).sum(1) <= r * r).sum())


def cylinder_count(xyz, p, r, h=np.inf):
    d = xyz - p
    return int(((d[:, 0] ** 2 + d[:, 1] ** 2 <= r * r) & (np.abs(d[:, 2]) <= h)).sum())


# ------------------------------------------------------------------ inclusive boundaries


def test_sphere_and_cylinder_include_neighbours_at_exactly_r():
    """Unit grid 5×5×5, r = 1 at the centre: the sphere holds the point and its 6 axis
    neighbours (7); the vertical cylinder holds 5 columns × 5 levels (25), with half-height
    h = 1 5 × 3 (15).  Densities follow: n_cyl/(π r²), n_sph/(4/3 π r³)."""
    xyz = int_grid()
    c = UTM + 2.0
    i = index_of(xyz, c)
    assert (sphere_count(xyz, c, 1.0), cylinder_count(xyz, c, 1.0), cylinder_count(xyz, c, 1.0, 1.0)) == (7, 25, 15)
    cloud = PointCloud(xyz)
    # covariance features alone walk the sphere only (no cylinder): the centre and 6 unit
    # neighbours, centroid at the centre -> eigenvalue_sum = 6/7, eigenvalues 2/7 each
    cov = compute_features(cloud, ["n_neighbours", "eigenvalue_sum", "eigenvalue3"], radius=1.0, query=[i])
    assert cov["n_neighbours"][0] == 7
    assert cov["eigenvalue_sum"][0] == pytest.approx(6 / 7, rel=1e-6)
    assert cov["eigenvalue3"][0] == pytest.approx(2 / 7, rel=1e-6)
    sph = compute_features(cloud, ["n_neighbours", "density"], radius=1.0, query=[i])
    assert sph["n_neighbours"][0] == 7
    assert sph["density_2d"][0] == pytest.approx(25 / math.pi, rel=1e-6)
    assert sph["density_3d"][0] == pytest.approx(7 / (4 / 3 * math.pi), rel=1e-6)
    assert sph["echo_ratio"][0] == pytest.approx(28.0, rel=1e-6)
    assert sph["neighbour_ratio"][0] == pytest.approx(0.28, rel=1e-6)
    cyl = compute_features(cloud, ["n_neighbours", "density"], radius=1.0, neighbourhood="cylinder",
                           height=1.0, query=[i])
    assert cyl["n_neighbours"][0] == 15
    assert cyl["density_2d"][0] == pytest.approx(15 / math.pi, rel=1e-6)
    assert cyl["echo_ratio"][0] == pytest.approx(700 / 15, rel=1e-6)
    unb = compute_features(cloud, "n_neighbours", radius=1.0, neighbourhood="cylinder", query=[i])
    assert unb["n_neighbours"][0] == 25


def test_neighbor_index_includes_points_at_exactly_r():
    xyz = int_grid()
    c = (UTM + 2.0).reshape(1, 3)
    idx = NeighborIndex(xyz, 1.0)
    off, nb, dist = idx.query_radius(c, 1.0)
    want = np.flatnonzero(((xyz - c) ** 2).sum(1) <= 1.0)
    assert sorted(nb.tolist()) == want.tolist() and len(want) == 7
    np.testing.assert_allclose(np.sort(dist), [0, 1, 1, 1, 1, 1, 1])
    assert idx.count(c, 1.0)[0] == 7
    assert idx.count(c, 1.0, cylinder=True)[0] == 25
    off, nb, _ = idx.query_radius(c, 1.0, cylinder=True, height=1.0)
    assert len(nb) == 15 and np.all(np.abs(xyz[nb, 2] - c[0, 2]) <= 1.0)


def test_multiscale_shells_keep_points_at_exactly_each_radius():
    """radii [1, 2] with cylinder features (the buffer is sorted into horizontal shells):
    each scale equals its own single-radius run and the brute-force counts."""
    xyz = int_grid()
    c = UTM + 2.0
    i = index_of(xyz, c)
    cloud = PointCloud(xyz)
    names = ["n_neighbours", "density_2d", "density_3d", "z_range"]
    multi = compute_features(cloud, names, radii=[1.0, 2.0], query=[i])
    for r in (1.0, 2.0):
        want_n = sphere_count(xyz, c, r)
        want_cyl = cylinder_count(xyz, c, r)
        assert multi[f"n_neighbours_r{r:.2f}"][0] == want_n
        assert multi[f"density_2d_r{r:.2f}"][0] == pytest.approx(want_cyl / (math.pi * r * r), rel=1e-6)
        assert multi[f"density_3d_r{r:.2f}"][0] == pytest.approx(want_n / (4 / 3 * math.pi * r**3), rel=1e-6)
        assert multi[f"z_range_r{r:.2f}"][0] == 4.0
        single = compute_features(cloud, names, radius=r, query=[i])
        for n in names:
            assert multi[f"{n}_r{r:.2f}"][0] == single[n][0], (n, r)
    assert (sphere_count(xyz, c, 1.0), sphere_count(xyz, c, 2.0)) == (7, 33)


def test_isotropic_and_coincident_neighbourhoods():
    """The 7-point cross of the unit grid is isotropic: λ1 = λ2 = λ3 = 2/7, so sphericity 1,
    omnivariance 1/3, eigenentropy ln 3, westin_spherical 1, and sffi_x NaN (λ1 = λ3);
    normal (0, 0, 1), plane_std √(2/7), the 2 points at dz = ±1 are no plane inliers (5/7).
    Coinciding points (docs §3.1): eigenvalues 0, ratios NaN, normal (0, 0, 1)."""
    xyz = int_grid()
    i = index_of(xyz, UTM + 2.0)
    f = compute_features(PointCloud(xyz), ["eigen", "westin", "plane"], radius=1.0, query=[i])
    want = dict(eigenvalue1=2 / 7, eigenvalue2=2 / 7, eigenvalue3=2 / 7, linearity=0, planarity=0, sphericity=1,
                anisotropy=0, omnivariance=1 / 3, eigenentropy=math.log(3), surface_variation=1 / 3,
                sffi_y=1, westin_linear=0, westin_planar=0, westin_spherical=1, normal_z=1, slope=0,
                plane_std=math.sqrt(2 / 7), plane_inlier_ratio=5 / 7, plane_distance=0)
    for name, v in want.items():
        assert f[name][0] == pytest.approx(v, abs=1e-6), name
    assert np.isnan(f["sffi_x"][0]) and np.isnan(f["aspect"][0])
    pts = np.vstack([np.repeat([[1.0, 1.0, 1.0]], 5, axis=0), [[5.0, 5.0, 5.0], [6.0, 6.0, 6.0]]]) + UTM
    c = compute_features(PointCloud(pts), ["eigen", "plane", "n_neighbours"], radius=0.5, query=[0])
    assert c["n_neighbours"][0] == 5
    assert [c[f"eigenvalue{k}"][0] for k in (1, 2, 3)] == [0, 0, 0]
    for name in ("linearity", "planarity", "sphericity", "omnivariance", "eigenentropy", "surface_variation"):
        assert np.isnan(c[name][0]), name
    assert (c["normal_x"][0], c["normal_y"][0], c["normal_z"][0]) == (0, 0, 1)


# ------------------------------------------------------------------------------ kNN


def test_knn_ties_at_the_kth_distance_are_all_included():
    """docs/features.md §1: 'on a unit grid, k=2 at an interior point gives 5 neighbours';
    the neighbourhood is the sphere of radius d_K (enlarged by a relative 1e-9)."""
    xyz = int_grid(n=7, dims=2)
    inner = np.all((xyz[:, :2] - UTM[:2] >= 1) & (xyz[:, :2] - UTM[:2] <= 5), axis=1)
    out = compute_features(PointCloud(xyz), ["n_neighbours", "density_2d"], neighbourhood="knn", k=2)
    assert np.all(out["n_neighbours"][inner] == 5)
    np.testing.assert_allclose(out["density_2d"][inner], 5 / math.pi, rtol=1e-6)


def test_knn_ties_at_irrational_distances():
    """3-D unit grid at UTM coordinates: the K-th neighbour at √2 or √3 (d_K² = 2, 3 rounds
    when squared back: √3² = 2.9999999999999996 in float64); every tied point still counts:
    k = 8 -> 1 + 6 + 12 = 19 neighbours, k = 20 -> 19 + 8 corners = 27, k = 7 -> 7."""
    xyz = int_grid()
    i = index_of(xyz, UTM + 2.0)
    cloud = PointCloud(xyz)
    for k, want in ((7, 7), (8, 19), (20, 27)):
        out = compute_features(cloud, ["n_neighbours", "density_3d"], neighbourhood="knn", k=k, query=[i])
        assert out["n_neighbours"][0] == want, k
        r = math.sqrt({7: 1, 19: 2, 27: 3}[want])
        assert out["density_3d"][0] == pytest.approx(want / (4 / 3 * math.pi * r**3), rel=1e-6), k


def test_capped_knn_radius_is_the_cap_when_fewer_than_k():
    """kNN capped by R: when fewer than K points lie within R the neighbourhood is the sphere
    of radius R (docs §1), and R is the radius of the densities; with K points inside R it is d_K."""
    xyz = int_grid(n=7, dims=2)
    c = UTM + np.array([3.0, 3.0, 0.0])
    i = index_of(xyz, c)
    cloud = PointCloud(xyz)
    capped = compute_features(cloud, ["n_neighbours", "density"], neighbourhood="knn", k=50, radius=1.5, query=[i])
    n = sphere_count(xyz, c, 1.5)
    assert n == 9 and capped["n_neighbours"][0] == 9
    assert capped["density_2d"][0] == pytest.approx(9 / (math.pi * 1.5**2), rel=1e-6)
    assert capped["density_3d"][0] == pytest.approx(9 / (4 / 3 * math.pi * 1.5**3), rel=1e-6)
    within = compute_features(cloud, ["n_neighbours", "density_2d"], neighbourhood="knn", k=5, radius=1.5, query=[i])
    assert within["n_neighbours"][0] == 5
    assert within["density_2d"][0] == pytest.approx(5 / math.pi, rel=1e-6)
    with pytest.raises(LidarfxError, match="at most one radius"):
        compute_features(cloud, "n_neighbours", neighbourhood="knn", k=5, radii=[1.0, 2.0])


# ------------------------------------------------------------------- Python options


def rough_plane(seed=0):
    """A 3 m × 3 m grid (0.1 m) whose points alternate ±4 cm (checkerboard), plus a random
    roof 1.2 m above one corner: plane inliers depend on d_max, histograms on the bins."""
    rng = np.random.default_rng(seed)
    g = int_grid(n=31, dims=2, offset=np.zeros(3)) * 0.1
    ij = np.rint(g[:, :2] / 0.1).astype(int)
    g[:, 2] = 0.04 * (-1.0) ** (ij.sum(1))
    roof = np.c_[rng.uniform(0, 1.2, 300), rng.uniform(0, 1.2, 300), 1.2 + rng.normal(0, 0.01, 300)]
    return np.vstack([g, roof]) + UTM


def test_d_max_and_hist_bins_reach_the_kernels():
    """Non-default d_max and hist_bins against the brute-force reference (tests/reference_features.py)."""
    xyz = rough_plane()
    qi = np.array([nearest(xyz, UTM + p) for p in ([1.5, 1.5, -0.04], [0.5, 0.6, -0.04], [2.2, 0.4, 0.04])])
    names = ["plane_inlier_ratio", "quadric_inlier_ratio", "dh_peaks", "dh_peak_distance", "dh_entropy", "dh_max_bin"]
    r = 0.35
    for d_max, bins in ((0.03, 4), (0.10, 7)):
        out = compute_features(PointCloud(xyz), names, radius=r, d_max=d_max, hist_bins=bins, query=qi)
        for row, i in enumerate(qi):
            ref = ref_features(xyz, xyz[i], r, dmax=d_max, bins=bins)
            for name in names:
                assert float(out[name][row]) == pytest.approx(ref[name], abs=1e-5), (name, d_max, bins, i)
    # the options matter here: at the plane's centre 4 cm residuals are inliers only at d_max 0.10
    a = compute_features(PointCloud(xyz), names, radius=r, d_max=0.03, hist_bins=4, query=qi[:2])
    b = compute_features(PointCloud(xyz), names, radius=r, query=qi[:2])
    assert a["plane_inlier_ratio"][0] < 0.2 and b["plane_inlier_ratio"][0] == 1.0
    # under the roof: dh of the roof is -1.2 -> first bin; the query's level in bin B/2 (4 bins: 2)
    assert a["dh_peak_distance"][1] == 2 and b["dh_peak_distance"][1] == 5


def test_msac_threshold_and_cylinder_neighbourhood():
    """Ground (z = 0, 0.1 m grid) under a 6 cm higher layer of a third of the points.
    MSAC with threshold 3 cm keeps the ground only (inlier share = ground share); with
    the default (= d_max 0.10) both layers.  In a vertical cylinder a roof 3 m above joins
    the neighbourhood but not the plane: inlier share = ground share of the cylinder."""
    g = int_grid(n=21, dims=2, offset=np.zeros(3)) * 0.1
    layer = g[::3] + [0.05, 0.05, 0.06]
    roof = g[(g[:, 0] < 1.0)][::2] + [0.03, 0.03, 3.0]
    xyz = np.vstack([g, layer, roof]) + UTM
    q = nearest(xyz, UTM + [0.5, 1.0, 0.0])
    r = 0.45
    p = xyz[q]
    d = xyz - p
    in_sph = (d**2).sum(1) <= r * r
    ground = np.abs(d[:, 2]) < 1e-9
    share = ground[in_sph].mean()
    assert 0.6 < share < 0.85
    cloud = PointCloud(xyz)
    tight = compute_features(cloud, "msac", radius=r, msac_threshold=0.03, seed=1, query=[q])
    assert tight["msac_inlier_ratio"][0] == pytest.approx(share, abs=1e-6)
    assert tight["msac_normal_z"][0] == pytest.approx(1.0, abs=1e-9)
    assert tight["msac_plane_std"][0] == pytest.approx(0.0, abs=1e-6)
    loose = compute_features(cloud, "msac", radius=r, seed=1, query=[q])
    assert loose["msac_inlier_ratio"][0] == 1.0
    in_cyl = d[:, 0] ** 2 + d[:, 1] ** 2 <= r * r
    cshare = ground[in_cyl].mean()
    assert in_cyl.sum() > in_sph.sum()
    cyl = compute_features(cloud, ["msac", "n_neighbours"], radius=r, neighbourhood="cylinder",
                           msac_threshold=0.03, seed=1, query=[q])
    assert cyl["n_neighbours"][0] == in_cyl.sum()
    assert cyl["msac_inlier_ratio"][0] == pytest.approx(cshare, abs=1e-6)


def test_msac_iterations_caps_the_trials():
    """The same two layers: with the default 100 trials MSAC finds the ground plane at every
    point (inlier share = ground share, brute force); msac_iterations=1 tries a single random
    triple, which lies on the ground with probability share³ (mean 0.47 here; measured 0.471)."""
    g = int_grid(n=21, dims=2, offset=np.zeros(3)) * 0.1
    layer = g[::3] + [0.05, 0.05, 0.06]
    xyz = np.vstack([g, layer]) + UTM
    loc = g[:, :2]
    qi = np.flatnonzero(np.all((loc >= 0.45) & (loc <= 1.55), axis=1))
    r = 0.45
    share = np.array([(np.abs(xyz[((xyz - xyz[i]) ** 2).sum(1) <= r * r, 2] - UTM[2]) < 1e-9).mean() for i in qi])
    cloud = PointCloud(xyz)
    full = compute_features(cloud, "msac_inlier_ratio", radius=r, msac_threshold=0.03, query=qi)
    np.testing.assert_allclose(full["msac_inlier_ratio"], share, atol=1e-6)
    one = compute_features(cloud, "msac_inlier_ratio", radius=r, msac_threshold=0.03, msac_iterations=1, query=qi)
    hit = np.abs(one["msac_inlier_ratio"] - share) < 1e-6
    assert len(qi) > 100 and abs(hit.mean() - np.mean(share**3)) < 0.15, hit.mean()


def test_scanner_position_in_utm_coordinates():
    """The scanner is given in the cloud's coordinates: a wall at E 500 000 seen from the
    west (E 499 995) has normals pointing west, from the east pointing east."""
    rng = np.random.default_rng(0)
    wall = np.c_[np.zeros(3000), rng.uniform(0, 10, 3000), rng.uniform(0, 5, 3000)] + UTM
    cloud = PointCloud(wall)
    west = compute_features(cloud, "normal_x", radius=0.5, scanner=UTM + [-5.0, 5.0, 1.5])
    east = compute_features(cloud, "normal_x", radius=0.5, scanner=UTM + [5.0, 5.0, 1.5])
    assert np.all(west["normal_x"] < -0.999) and np.all(east["normal_x"] > 0.999)
    # and a horizontal surface seen from below has downward normals
    flat = np.c_[rng.uniform(0, 5, 2000), rng.uniform(0, 5, 2000), np.zeros(2000)] + UTM
    below = compute_features(PointCloud(flat), "normal_z", radius=0.5, scanner=UTM + [2.5, 2.5, -10.0])
    assert np.all(below["normal_z"] < -0.999)
    # docs §3.3: the aspect is that of the up-facing normal, also with scanner-oriented normals:
    # a plane sloping 30° towards azimuth 120°, scanned from below, keeps aspect 120°
    s, a = math.radians(30), math.radians(120)
    nrm = np.array([math.sin(s) * math.sin(a), math.sin(s) * math.cos(a), math.cos(s)])
    xy = rng.uniform(0, 6, (3000, 2))
    tilted = np.c_[xy, -(xy @ nrm[:2]) / nrm[2]] + UTM
    t = compute_features(PointCloud(tilted), ["aspect", "normal_x", "normal_y", "normal_z"], radius=0.5,
                         scanner=UTM + [3.0, 3.0, -50.0])
    n = np.c_[t["normal_x"], t["normal_y"], t["normal_z"]]
    np.testing.assert_allclose(n, np.broadcast_to(-nrm, n.shape), atol=1e-5)
    np.testing.assert_allclose(t["aspect"], 120.0, atol=1e-3)


def test_echo_ratio_slope_caps_the_slope_at_80_degrees():
    """A 10 m high vertical wall (slope 90°), query at its foot: the slope-adaptive echo ratio
    counts the cylinder points within r / cos(80°) = 5.76 r (docs §3.5: 'steeper than 80° the
    cap bites'), brute force; the plain echo ratio counts those within r."""
    y, z = np.meshgrid(np.arange(0, 4.001, 0.1), np.arange(0, 10.001, 0.1))
    wall = np.c_[np.zeros(y.size), y.ravel(), z.ravel()] + UTM
    i = nearest(wall, UTM + [0.0, 2.0, 0.0])
    r = 0.5
    out = compute_features(PointCloud(wall), ["slope", "echo_ratio", "echo_ratio_slope"], radius=r, query=[i])
    assert out["slope"][0] == pytest.approx(90.0, abs=1e-4)
    d = wall - wall[i]
    cyl = d[:, 0] ** 2 + d[:, 1] ** 2 <= r * r
    dist = np.sqrt((d**2).sum(1))
    want = 100 * np.sum(cyl & (dist <= r / math.cos(math.radians(80)))) / cyl.sum()
    assert 20 < want < 40
    assert out["echo_ratio_slope"][0] == pytest.approx(want, rel=1e-6)
    assert out["echo_ratio"][0] == pytest.approx(100 * np.sum(cyl & (dist <= r)) / cyl.sum(), rel=1e-6)


def test_eigenvector1_sign_rule():
    """v1 is the direction of the largest spread, signed so that z >= 0 (x >= 0 when z = 0)."""
    t = np.linspace(-2, 2, 81)
    for direction, want in (
        ((0.6, 0.0, -0.8), (-0.6, 0.0, 0.8)),
        ((-0.48, 0.64, 0.6), (-0.48, 0.64, 0.6)),
        ((-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
        ((-0.6, -0.8, 0.0), (0.6, 0.8, 0.0)),
    ):
        line = np.outer(t, direction) + UTM
        out = compute_features(PointCloud(line), "eigenvectors", radius=0.5)
        got = np.c_[out["eigenvector1_x"], out["eigenvector1_y"], out["eigenvector1_z"]]
        np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), atol=1e-6, err_msg=str(direction))


def test_stream_features_passes_every_option_on():
    """stream_features(...) pieces equal compute_features(...) with the same non-default options,
    which differ from the defaults' values on this cloud."""
    xyz = rough_plane(seed=3)
    rng = np.random.default_rng(3)
    xyz = xyz + rng.normal(0, 0.003, xyz.shape)
    cloud = PointCloud(xyz)
    feats = "eigenentropy,omnivariance,plane_inlier_ratio,z_range,dh_max_bin,msac_slope,msac_inlier_ratio"
    opts = dict(radius=0.35, convention="cloudcompare", height=0.5, d_max=0.03, hist_bins=4,
                msac_threshold=0.02, msac_iterations=30, seed=9)
    ref = compute_features(cloud, feats, **opts)
    default = compute_features(cloud, feats, radius=0.35)
    names, fill = stream_features(cloud, feats, **opts)
    cuts = [0, 333, 700, len(cloud)]
    pieces = [fill(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
    for name in names:
        got = np.concatenate([p[name] for p in pieces])
        np.testing.assert_array_equal(got, ref[name], err_msg=name)
        assert not np.array_equal(ref[name], default[name], equal_nan=True), name


# ---------------------------------------------------------------------------- CLI


@pytest.fixture(scope="module")
def levels_las(tmp_path_factory):
    """Flat ground (0.1 m grid, 3 m × 3 m) at z = 200, a flat roof 3 m above x < 1 m,
    and a ±4 cm checkerboard patch for x > 2 m; UTM coordinates."""
    g = int_grid(n=31, dims=2, offset=np.zeros(3)) * 0.1
    ij = np.rint(g[:, :2] / 0.1).astype(int)
    rough = g[:, 0] > 2.05
    g[rough, 2] = 0.04 * (-1.0) ** ij[rough].sum(1)
    roof = g[g[:, 0] < 1.0].copy()
    roof[:, 2] = 3.0
    xyz = np.vstack([g, roof]) + [500000.0, 5000000.0, 200.0]
    path = tmp_path_factory.mktemp("wiring") / "levels.las"
    lidarfx.write(PointCloud(xyz), path)
    return path


@pytest.fixture(scope="module")
def noisy_las(tmp_path_factory):
    rng = np.random.default_rng(11)
    n = 1500
    xyz = np.c_[rng.uniform(0, 4, n), rng.uniform(0, 4, n), rng.normal(0, 0.03, n)]
    xyz[::5, 2] += rng.uniform(0.1, 0.4, len(xyz[::5]))
    path = tmp_path_factory.mktemp("wiring") / "noisy.las"
    lidarfx.write(PointCloud(xyz + [500000.0, 5000000.0, 200.0]), path)
    return path


def run_cli(src, tmp_path, *args):
    out = tmp_path / "out.las"
    assert main(["features", str(src), str(out), "-q", "--force", *args]) == 0  # one output, run after run
    return lidarfx.read(out), lidarfx.read(src).xyz


def at(xyz, x, y):
    """Index of the ground point at (x, y) metres from the tile's corner."""
    p = np.array([500000.0 + x, 5000000.0 + y, 200.0])
    return int(np.argmin(((xyz - p) ** 2).sum(1)))


def test_cli_height_limits_the_cylinder(levels_las, tmp_path):
    """A ground point under the roof: z range 3 m in the unbounded cylinder, 0 within ±1 m;
    with -n cylinder the neighbour count (brute force) follows the half-height."""
    got, xyz = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "height", "--height", "1.0")
    i = at(xyz, 0.5, 1.5)
    assert got["z_range"][i] == 0.0 and got["dz_above"][i] == 0.0
    full, _ = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "height")
    assert full["z_range"][i] == pytest.approx(3.0, abs=1e-6)
    # -n cylinder: the roof 3 m above joins the neighbourhood only when the half-height reaches it
    for h, want in (("1.0", 37), ("3.5", 74)):
        cyl, _ = run_cli(levels_las, tmp_path, "-r", "0.35", "-n", "cylinder", "--height", h, "-f", "n_neighbours")
        assert cyl["n_neighbours"][i] == cylinder_count(xyz, xyz[i], 0.35, float(h)) == want, h


def test_cli_bins(levels_las, tmp_path):
    """Flat ground: every dh = 0 falls into bin ⌊B/2⌋, centre −1 + (⌊B/2⌋ + ½)·2/B (0.25 for
    B = 4, 0.1 for 10); under the roof the peaks are bins 0 and B/2 apart."""
    got, xyz = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "histogram", "--bins", "4")
    flat, under = at(xyz, 1.5, 1.5), at(xyz, 0.5, 1.5)
    assert got["dh_max_bin"][flat] == pytest.approx(0.25) and got["dh_entropy"][flat] == 0.0
    assert got["dh_peaks"][under] == 2 and got["dh_peak_distance"][under] == 2
    default, _ = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "histogram")
    assert default["dh_max_bin"][flat] == pytest.approx(0.1) and default["dh_peak_distance"][under] == 5


def test_cli_d_max(levels_las, tmp_path):
    """On the ±4 cm checkerboard the local plane is horizontal through the centroid:
    inliers (brute force) depend on --d-max (0.03: a few; default 0.10: all)."""
    got, xyz = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "plane_inlier_ratio", "--d-max", "0.03")
    default, _ = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "plane_inlier_ratio")
    for x, y in ((2.6, 1.5), (2.5, 0.9)):
        i = at(xyz, x, y)
        d = xyz - xyz[i]
        nb = xyz[(d**2).sum(1) <= 0.35**2]
        c = nb.mean(0)
        w, v = np.linalg.eigh(np.cov((nb - c).T, bias=True))
        dist = np.abs((nb - c) @ v[:, 0])
        assert got["plane_inlier_ratio"][i] == pytest.approx(np.mean(dist <= 0.03), abs=1e-6)
        assert got["plane_inlier_ratio"][i] < 0.5
        assert default["plane_inlier_ratio"][i] == 1.0


def test_cli_convention(levels_las, tmp_path):
    """--convention cloudcompare: eigenentropy of the raw eigenvalues, −Σ λ ln λ (numpy);
    pdal: linearity of μ = √λ.  The default gives ln 2 on a symmetric flat disc."""
    i_names = "eigenentropy,linearity"
    cc, xyz = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", i_names, "--convention", "cloudcompare")
    pd, _ = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", i_names, "--convention", "pdal")
    df, _ = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", i_names)
    for x, y in ((1.5, 1.5), (2.6, 1.5), (1.5, 0.0)):
        i = at(xyz, x, y)
        nb = xyz[((xyz - xyz[i]) ** 2).sum(1) <= 0.35**2]
        lam = np.clip(np.linalg.eigvalsh(np.cov(nb.T, bias=True))[::-1], 0, None)
        raw = -sum(v * math.log(v) for v in lam if v > 0)
        assert cc["eigenentropy"][i] == pytest.approx(raw, rel=1e-5, abs=1e-6)
        mu = np.sqrt(lam)
        assert pd["linearity"][i] == pytest.approx((mu[0] - mu[1]) / mu[0], abs=1e-5)
        assert df["linearity"][i] == pytest.approx((lam[0] - lam[1]) / lam[0], abs=1e-5)
    edge = at(xyz, 1.5, 0.0)
    assert abs(pd["linearity"][edge] - df["linearity"][edge]) > 0.01  # the half disc: not symmetric
    assert df["eigenentropy"][at(xyz, 1.5, 1.5)] == pytest.approx(math.log(2), abs=1e-5)


def test_cli_scanner_orients_normals_in_file_coordinates(levels_las, tmp_path):
    """A scanner 10 m below the tile: every normal points down."""
    got, xyz = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "normal_z", "--scanner", "500001.5,5000001.5,190")
    assert np.all(got["normal_z"] < -0.99)
    up, _ = run_cli(levels_las, tmp_path, "-r", "0.35", "-f", "normal_z")
    assert np.all(up["normal_z"] > 0.99)


def test_cli_seed_and_k(noisy_las, tmp_path):
    """--seed reaches MSAC: the file equals compute_features(seed=7), not seed 0;
    -n knn -k 7 gives the 7 nearest points (and any tied with the 7th: scipy)."""
    got, _ = run_cli(noisy_las, tmp_path, "-r", "0.5", "-f", "msac_slope,msac_plane_std", "--seed", "7")
    cloud = lidarfx.read(noisy_las)
    s7 = compute_features(cloud, "msac_slope,msac_plane_std", radius=0.5, seed=7)
    s0 = compute_features(cloud, "msac_slope,msac_plane_std", radius=0.5, seed=0)
    for name in ("msac_slope", "msac_plane_std"):
        np.testing.assert_array_equal(got[name], s7[name])
        assert np.mean(s7[name] != s0[name]) > 0.3
    knn, xyz = run_cli(noisy_las, tmp_path, "-n", "knn", "-k", "7", "-f", "n_neighbours")
    from scipy.spatial import cKDTree

    loc = xyz - xyz.min(0)
    tree = cKDTree(loc)
    d7 = tree.query(loc, 7)[0][:, -1]
    # ties at the 7th distance (millimetre coordinates) all count, as docs §1 says
    want = np.array([len(tree.query_ball_point(p, d * (1 + 1e-9) + 1e-12)) for p, d in zip(loc, d7)])
    assert np.mean(want == 7) > 0.9
    np.testing.assert_array_equal(knn["n_neighbours"], want)
