"""The sorted column grid index against scipy's KD-tree."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarfx.errors import LidarfxError
from lidarfx.neighbors import NeighborIndex


def cloud(n=20000, seed=0, offset=(500000.0, 5000000.0, 100.0)):
    rng = np.random.default_rng(seed)
    xyz = np.c_[rng.uniform(0, 30, n), rng.uniform(0, 20, n), rng.uniform(0, 4, n)]
    xyz[: n // 10] = xyz[n // 10 : 2 * (n // 10)]  # exact duplicates, as in real LAS files
    return xyz + offset


def as_sets(offsets, idx):
    return [set(idx[offsets[i] : offsets[i + 1]].tolist()) for i in range(len(offsets) - 1)]


@pytest.mark.parametrize("cell", [0.5, 0.2, 1.3])
def test_sphere_and_cylinder_match_kdtree(cell):
    xyz = cloud()
    idx = NeighborIndex(xyz, cell)
    local = xyz - xyz.min(0)
    q = xyz[::97]
    off, nb, dist = idx.query_radius(q, 0.5)
    ref = cKDTree(local).query_ball_point(q - xyz.min(0), 0.5)
    assert as_sets(off, nb) == [set(r) for r in ref]
    assert np.all(dist <= 0.5) and np.allclose(dist, np.linalg.norm(xyz[nb] - np.repeat(q, np.diff(off), axis=0), axis=1))
    off2, nb2, _ = idx.query_radius(q, 0.5, cylinder=True)
    ref2 = cKDTree(local[:, :2]).query_ball_point((q - xyz.min(0))[:, :2], 0.5)
    assert as_sets(off2, nb2) == [set(r) for r in ref2]
    np.testing.assert_array_equal(idx.count(q, 0.5, cylinder=True), np.diff(off2))


def test_height_limited_cylinder():
    xyz = cloud()
    idx = NeighborIndex(xyz, 0.5)
    q = xyz[::211]
    off, nb, _ = idx.query_radius(q, 0.4, cylinder=True, height=0.3)
    for i in range(len(q)):
        d = xyz - q[i]
        want = np.flatnonzero((d[:, 0] ** 2 + d[:, 1] ** 2 <= 0.16) & (np.abs(d[:, 2]) <= 0.3))
        assert set(nb[off[i] : off[i + 1]].tolist()) == set(want.tolist())


def test_per_point_radius_and_queries_outside():
    xyz = cloud()
    idx = NeighborIndex(xyz, 0.5)
    q = np.array([[-5.0, -5.0, 0.0], [15.0, 10.0, 2.0], [1e3, 1e3, 1e3]]) + xyz.min(0)
    r = np.array([7.5, 0.25, 1.0])
    counts = idx.count(q, r)
    tree = cKDTree(xyz - xyz.min(0))
    want = [len(tree.query_ball_point(p - xyz.min(0), rr)) for p, rr in zip(q, r)]
    np.testing.assert_array_equal(counts, want)


def test_knn_and_capped_knn():
    xyz = cloud()
    idx = NeighborIndex(xyz, 0.3)
    tree = cKDTree(xyz - xyz.min(0))
    q = xyz[::53]
    ki, kd = idx.knn(q, 10)
    rd, _ = tree.query(q - xyz.min(0), 10)
    np.testing.assert_allclose(kd, rd, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(xyz[ki] - q[:, None, :], axis=2), kd, atol=1e-9)
    ci, cd = idx.knn(q, 50, max_radius=0.2)
    rd, _ = tree.query(q - xyz.min(0), 50, distance_upper_bound=0.2)
    np.testing.assert_allclose(cd, rd, atol=1e-9)
    assert np.all((ci == -1) == np.isinf(cd))


def test_sparse_grid_path():
    """A huge extent for a tiny cell switches the dense cell table off; answers stay exact."""
    rng = np.random.default_rng(1)
    xyz = np.c_[rng.uniform(0, 5000, 3000), rng.uniform(0, 5000, 3000), rng.uniform(0, 1, 3000)]
    xyz = np.vstack([xyz, xyz[:500] + rng.normal(0, 0.01, (500, 3))])
    idx = NeighborIndex(xyz, 0.05)
    assert idx.grid.table.shape[0] == 0
    off, nb, _ = idx.query_radius(xyz[:600], 0.05)
    ref = cKDTree(xyz - xyz.min(0)).query_ball_point(xyz[:600] - xyz.min(0), 0.05)
    assert as_sets(off, nb) == [set(r) for r in ref]


def test_columns_sorted_by_z_and_bad_input():
    xyz = cloud(n=5000)
    idx = NeighborIndex(xyz, 0.5)
    g = idx.grid
    for c in range(len(g.cstart)):
        z = g.pts[g.cstart[c] : g.cend[c], 2]
        assert np.all(np.diff(z) >= 0)
    assert sorted(idx.order.tolist()) == list(range(len(xyz)))
    with pytest.raises(LidarfxError):
        NeighborIndex(np.array([[0, 0, np.nan]]), 0.5)
    with pytest.raises(LidarfxError):
        NeighborIndex(xyz, 0.0)
    with pytest.raises(LidarfxError):
        idx.knn(xyz[:2], 0)


@pytest.mark.parametrize("xyz", [[[1.0, 2.0, 3.0]], [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]], np.random.default_rng(3).random((40, 3))])
def test_contiguous_z_column_tiny_clouds(xyz):
    """One point (its z column is C-contiguous, a second kernel specialisation) and duplicates:
    the index holds every point, sorted by z, and each point finds itself and its copies."""
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    idx = NeighborIndex(xyz, 0.5)
    assert sorted(idx.order.tolist()) == list(range(len(xyz)))
    g = idx.grid
    for c in range(len(g.cstart)):
        assert np.all(np.diff(g.pts[g.cstart[c]:g.cend[c], 2]) >= 0)
    off, _, _ = idx.query_radius(xyz, 1e-9)
    same = (np.abs(xyz[:, None, :] - xyz[None, :, :]).max(axis=2) == 0).sum(axis=1)
    assert np.array_equal(np.diff(off), same)
    nn, d = idx.knn(xyz[:1], 1)
    assert d[0, 0] == 0.0 and np.array_equal(xyz[nn[0, 0]], xyz[0])
