"""Robust 3-D lines (lidarfx.vector.lines) and the plane helpers of lidarfx.geometry:
real answers on synthetic shapes (closed forms, known parameters recovered from noisy data)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lidarfx.errors import LidarfxError
from lidarfx.geometry import intersect_planes, ransac_plane
from lidarfx.vector.lines import (
    LineSegment,
    chain_segments,
    closest_points_of_lines,
    douglas_peucker,
    extract_segments,
    fit_line,
    merge_collinear,
    point_line_distance,
    point_polyline_distance,
    polyline_of,
    ransac_line,
)
from lidarfx.vector.polyline import Polyline

UTM = np.array([5.0e5, 5.0e6, 300.0])


# ------------------------------------------------------------------ helpers
def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _angle_deg(a, b) -> float:
    """Axial angle (degrees) between two directions."""
    c = abs(float(_unit(a) @ _unit(b)))
    return math.degrees(math.acos(min(c, 1.0)))


def _noisy_line(rng, c, d, n=1000, length=10.0, sigma=0.01):
    """``n`` points on the line through ``c`` along ``d`` (t uniform in [0, length]) + isotropic noise."""
    t = rng.uniform(0.0, length, n)
    return np.asarray(c) + t[:, None] * _unit(d) + rng.normal(0.0, sigma, (n, 3)), t


def _band(rng, a, b, n, width, sigma=0.01):
    """``n`` points uniformly in a horizontal band of ``width`` m around the segment a→b (z = const)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    L = float(np.linalg.norm(d))
    d = d / L
    perp = np.array([-d[1], d[0], 0.0])
    t = rng.uniform(0.0, L, n)
    s = rng.uniform(-width / 2, width / 2, n)
    return a + t[:, None] * d + s[:, None] * perp + rng.normal(0.0, sigma, (n, 3))


def _seg(a, b, *, fixed=False, index=None, rms=0.0, label="") -> LineSegment:
    idx = np.zeros(0, np.int64) if index is None else np.asarray(index, np.int64)
    return LineSegment(np.asarray(a, float), np.asarray(b, float), idx, rms, label, fixed)


def _dist_to_axis_line(p, c, d):
    """Distance of point(s) to a line by the cross product (no √(|q|² − t²) cancellation)."""
    q = np.atleast_2d(np.asarray(p, float)) - np.asarray(c, float)
    return np.linalg.norm(np.cross(q, _unit(d)), axis=1)


# ------------------------------------------------------------------ fit_line
def test_fit_line_recovers_known_line_centroid_rms_and_extent():
    rng = np.random.default_rng(11)
    c0, d0, sigma = np.array([3.0, -2.0, 1.5]), _unit([1.0, 2.0, 0.5]), 0.01
    p, t = _noisy_line(rng, c0, d0, n=1000, length=10.0, sigma=sigma)
    c, d, rms, (t0, t1) = fit_line(p)
    ang = _angle_deg(d, d0)
    assert ang < 0.5
    assert ang < 0.05  # expected ≈ σ / (L √(n/12)) ≈ 0.006°
    assert abs(np.linalg.norm(d) - 1.0) < 1e-12
    # centroid: the mean of the points (the true mean position on the line + noise/√n)
    np.testing.assert_allclose(c, p.mean(axis=0), atol=1e-9)
    np.testing.assert_allclose(c, c0 + t.mean() * d0, atol=3 * sigma / math.sqrt(100))
    # perpendicular noise is 2-D: rms ≈ σ √2
    assert abs(rms - sigma * math.sqrt(2)) < 0.1 * sigma * math.sqrt(2)
    # t relative to the centroid spans the sampled extent
    assert abs(t0 - (t.min() - t.mean())) < 0.05
    assert abs(t1 - (t.max() - t.mean())) < 0.05
    assert abs((t1 - t0) - (t.max() - t.min())) < 0.05


def test_fit_line_exact_points_rms_zero_and_extent_exact():
    d0 = _unit([2.0, -1.0, 2.0])
    t = np.array([-4.0, -1.0, 0.0, 2.5, 7.5])
    p = np.array([1.0, 2.0, 3.0]) + t[:, None] * d0
    c, d, rms, (t0, t1) = fit_line(p)
    assert rms < 1e-9
    np.testing.assert_allclose(d, d0, atol=1e-12)  # already canonical (x > 0)
    np.testing.assert_allclose(c, [1.0, 2.0, 3.0] + t.mean() * d0, atol=1e-12)
    assert t0 == pytest.approx(t.min() - t.mean(), abs=1e-9)
    assert t1 == pytest.approx(t.max() - t.mean(), abs=1e-9)


@pytest.mark.parametrize(
    "d_true, expected",
    [
        ([-1.0, 2.0, 0.5], [1.0, -2.0, -0.5]),
        ([1.0, -2.0, -0.5], [1.0, -2.0, -0.5]),
        ([0.0, -1.0, 1.0], [0.0, 1.0, -1.0]),
        ([0.0, 0.0, -3.0], [0.0, 0.0, 1.0]),
    ],
)
def test_fit_line_direction_is_canonical(d_true, expected):
    t = np.linspace(-5.0, 5.0, 11)
    for sign in (1.0, -1.0):
        p = np.array([1.0, 1.0, 1.0]) + sign * t[:, None] * _unit(d_true)
        _, d, _, (t0, t1) = fit_line(p)
        np.testing.assert_allclose(d, _unit(expected), atol=1e-12)
        assert t0 == pytest.approx(-5.0) and t1 == pytest.approx(5.0)


def test_fit_line_utm_offsets_give_same_direction_and_rms():
    rng = np.random.default_rng(5)
    p, _ = _noisy_line(rng, [0.0, 0.0, 0.0], [0.3, -1.0, 0.2], n=1000, sigma=0.01)
    c0, d0, rms0, (a0, b0) = fit_line(p)
    c1, d1, rms1, (a1, b1) = fit_line(p + UTM)
    assert _angle_deg(d0, d1) < 1e-5
    np.testing.assert_allclose(d1, d0, atol=1e-7)  # same canonical sign
    assert rms1 == pytest.approx(rms0, rel=1e-5)
    np.testing.assert_allclose(c1 - UTM, c0, atol=1e-6)
    assert a1 == pytest.approx(a0, abs=1e-6) and b1 == pytest.approx(b0, abs=1e-6)


def test_fit_line_zero_weight_removes_outliers():
    rng = np.random.default_rng(8)
    p, _ = _noisy_line(rng, [0.0, 0.0, 0.0], [1.0, 1.0, 0.0], n=500, sigma=0.01)
    out = rng.uniform(-5.0, 15.0, (60, 3))
    allp = np.vstack([p, out])
    w = np.r_[np.ones(len(p)), np.zeros(len(out))]
    c_ref, d_ref, rms_ref, _ = fit_line(p)
    c, d, rms, _ = fit_line(allp, w)
    np.testing.assert_allclose(c, c_ref, atol=1e-9)
    np.testing.assert_allclose(d, d_ref, atol=1e-9)
    assert rms == pytest.approx(rms_ref, rel=1e-9)
    # unweighted, the outliers do pull the fit (the test above can fail)
    c_u, d_u, rms_u, _ = fit_line(allp)
    assert rms_u > 10 * rms_ref or _angle_deg(d_u, d_ref) > 1.0


def test_fit_line_weights_scale_invariant_and_count_like_duplicates():
    rng = np.random.default_rng(9)
    p = rng.normal(size=(40, 3)) * [5.0, 1.0, 0.2]
    w = rng.integers(1, 4, len(p)).astype(float)
    c1, d1, r1, _ = fit_line(p, w)
    c2, d2, r2, _ = fit_line(p, 7.5 * w)
    c3, d3, r3, _ = fit_line(np.repeat(p, w.astype(int), axis=0))
    for c, d, r in ((c2, d2, r2), (c3, d3, r3)):
        np.testing.assert_allclose(c, c1, atol=1e-12)
        np.testing.assert_allclose(d, d1, atol=1e-9)
        assert r == pytest.approx(r1, rel=1e-9)


@pytest.mark.parametrize(
    "points, weights",
    [
        (np.zeros((1, 3)), None),  # one point
        (np.zeros((0, 3)), None),
        (np.zeros((10, 2)), None),  # wrong shape
        (np.zeros(9), None),
        (np.zeros((4, 3, 1)), None),
        (np.arange(30.0).reshape(10, 3), np.zeros(10)),  # zero weights
        (np.arange(30.0).reshape(10, 3), np.full(10, np.nan)),
    ],
)
def test_fit_line_errors(points, weights):
    with pytest.raises(LidarfxError):
        fit_line(points, weights)


def test_fit_line_weights_of_wrong_length_raise():
    p = np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)]
    with pytest.raises(LidarfxError):
        fit_line(p, np.array([2.0]))


# ------------------------------------------------------------------ distances
def test_point_line_distance_hand_values():
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 6.0, -10.0], [1.0, 7.0, 0.0], [-2.0, 2.0, 100.0]])
    d = point_line_distance(pts, [1.0, 2.0, 3.0], [0.0, 0.0, 2.0])  # vertical line, non-unit direction
    np.testing.assert_allclose(d, [0.0, 5.0, 5.0, 3.0], atol=1e-12)
    # an oblique line: distance from (0, 0, 1) to the line through 0 along (1, 1, 0) is 1,
    # from (1, -1, 0) it is √2
    d = point_line_distance(np.array([[0.0, 0.0, 1.0], [1.0, -1.0, 0.0], [3.0, 3.0, 0.0]]), [0, 0, 0], [1, 1, 0])
    np.testing.assert_allclose(d, [1.0, math.sqrt(2), 0.0], atol=1e-7)  # √(|q|² − t²): ~√ε·|q| near 0
    # UTM-sized
    d = point_line_distance(pts + UTM, np.array([1.0, 2.0, 3.0]) + UTM, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(d, [0.0, 5.0, 5.0, 3.0], atol=1e-8)


def test_point_polyline_distance_hand_values():
    v = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 0.0]])
    pts = np.array([
        [5.0, 3.0, 0.0],     # above the first segment: 3
        [5.0, 0.0, 2.0],     # above it in z: 2
        [-3.0, 4.0, 0.0],    # before the start: to vertex 0 → 5
        [13.0, -4.0, 0.0],   # beyond the corner, outside: to vertex 1 → 5
        [10.0, 14.0, 3.0],   # beyond the end: to vertex 2 → 5
        [7.0, 7.0, 0.0],     # inside the corner: nearer the second segment → 3
        [10.0, 5.0, 0.0],    # on the second segment → 0
        [-6.0, -8.0, 0.0],   # far before the start → 10
    ])
    expected = [3.0, 2.0, 5.0, 5.0, 5.0, 3.0, 0.0, 10.0]
    np.testing.assert_allclose(point_polyline_distance(pts, v), expected, atol=1e-12)
    np.testing.assert_allclose(point_polyline_distance(pts + UTM, v + UTM), expected, atol=1e-8)
    # a single segment: beyond both ends the distance is to the end vertices
    s = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 4.0]])
    q = np.array([[0.0, 3.0, -4.0], [0.0, 0.0, 9.0], [1.0, 0.0, 2.0]])
    np.testing.assert_allclose(point_polyline_distance(q, s), [5.0, 5.0, 1.0], atol=1e-12)


def test_closest_points_of_skew_lines_closed_form():
    q1, q2, dist = closest_points_of_lines([5.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 3.0, 1.0], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(q1, [0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(q2, [0.0, 0.0, 1.0], atol=1e-12)
    assert dist == pytest.approx(1.0)
    # non-unit directions, UTM offsets: same answer
    q1, q2, dist = closest_points_of_lines(UTM + [5.0, 0.0, 0.0], [-3.0, 0.0, 0.0], UTM + [0.0, 3.0, 1.0], [0.0, 0.5, 0.0])
    np.testing.assert_allclose(q1 - UTM, [0.0, 0.0, 0.0], atol=1e-8)
    np.testing.assert_allclose(q2 - UTM, [0.0, 0.0, 1.0], atol=1e-8)
    assert dist == pytest.approx(1.0, abs=1e-8)


def test_closest_points_of_general_skew_lines_are_mutually_perpendicular():
    rng = np.random.default_rng(3)
    for _ in range(20):
        p1, d1, p2, d2 = rng.normal(size=(4, 3)) * [[10], [1], [10], [1]]
        q1, q2, dist = closest_points_of_lines(p1, d1, p2, d2)
        w = q1 - q2
        assert abs(w @ _unit(d1)) < 1e-9 and abs(w @ _unit(d2)) < 1e-9
        assert _dist_to_axis_line(q1, p1, d1)[0] < 1e-9 and _dist_to_axis_line(q2, p2, d2)[0] < 1e-9
        # the distance is |(p2 - p1)·(d1 × d2)| / |d1 × d2|
        n = np.cross(d1, d2)
        assert dist == pytest.approx(abs((p2 - p1) @ n) / np.linalg.norm(n), abs=1e-9)


def test_closest_points_of_parallel_lines():
    q1, q2, dist = closest_points_of_lines([1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [7.0, 2.0, 0.0], [-2.0, 0.0, 0.0])
    np.testing.assert_allclose(q1, [1.0, 0.0, 0.0], atol=1e-12)  # p1 itself
    np.testing.assert_allclose(q2, [1.0, 2.0, 0.0], atol=1e-12)  # its foot on the second line
    assert dist == pytest.approx(2.0)
    # coincident lines: distance 0
    q1, q2, dist = closest_points_of_lines([0, 0, 0], [0, 0, 1], [0, 0, 5], [0, 0, 1])
    assert dist == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(q2, [0, 0, 0], atol=1e-12)


# ------------------------------------------------------------------ ransac_line
def _line_with_outliers(seed=0, n_line=200, n_out=200, sigma=0.02, offset=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    c0, d0 = np.array([1.0, 2.0, 3.0]), _unit([1.0, 0.7, 0.4])
    t = rng.uniform(0.0, 9.0, n_line)
    line = c0 + t[:, None] * d0 + rng.normal(0.0, sigma, (n_line, 3))
    out = rng.uniform(0.0, 10.0, (n_out, 3))
    pts = np.vstack([line, out]) + np.asarray(offset)
    truth = np.r_[np.ones(n_line, bool), np.zeros(n_out, bool)]
    return pts, truth, c0 + np.asarray(offset), d0


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), tuple(UTM)])
def test_ransac_line_finds_line_among_outliers(offset):
    pts, truth, c0, d0 = _line_with_outliers(offset=offset)
    found = ransac_line(pts, 0.1, seed=1)
    assert found is not None
    inl, c, d = found
    assert inl.dtype == bool and inl.shape == (len(pts),)
    assert inl[truth].mean() >= 0.95
    assert inl[~truth].mean() <= 0.05
    assert _angle_deg(d, d0) < 1.0
    assert abs(np.linalg.norm(d) - 1.0) < 1e-9
    assert _dist_to_axis_line(c, c0, d0)[0] < 0.05  # the returned point lies on the true line
    # every inlier within the threshold of the returned line, every other alive point beyond it
    dist = point_line_distance(pts, c, d)
    assert (dist[inl] <= 0.1).all() and (dist[~inl] > 0.1).all()


def test_ransac_line_alive_mask_restricts_search():
    pts, truth, c0, d0 = _line_with_outliers(seed=2)
    rng = np.random.default_rng(4)
    # a second, denser line; unmasked it is the best line
    t = rng.uniform(0.0, 9.0, 400)
    d2 = _unit([0.0, 1.0, -0.3])
    second = np.array([5.0, 0.5, 8.0]) + t[:, None] * d2 + rng.normal(0.0, 0.02, (400, 3))
    allp = np.vstack([pts, second])
    is_second = np.r_[np.zeros(len(pts), bool), np.ones(400, bool)]
    inl, _, d = ransac_line(allp, 0.1, seed=0)
    assert _angle_deg(d, d2) < 1.0 and inl[is_second].mean() >= 0.95
    alive = ~is_second
    inl, _, d = ransac_line(allp, 0.1, seed=0, alive=alive)
    assert _angle_deg(d, d0) < 1.0
    assert not inl[is_second].any()  # dead points are never inliers
    first = np.r_[truth, np.zeros(400, bool)]
    assert inl[first].mean() >= 0.95


def test_ransac_line_deterministic_for_seed():
    pts, _, _, _ = _line_with_outliers(seed=3)
    a = ransac_line(pts, 0.1, seed=7)
    b = ransac_line(pts, 0.1, seed=7)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(a[2], b[2])


def test_ransac_line_too_few_points_gives_none():
    assert ransac_line(np.zeros((0, 3)), 0.1) is None
    assert ransac_line(np.array([[0.0, 0.0, 0.0]]), 0.1) is None
    pts, _, _, _ = _line_with_outliers()
    alive = np.zeros(len(pts), bool)
    alive[5] = True
    assert ransac_line(pts, 0.1, alive=alive) is None


@pytest.mark.parametrize("thr", [0.0, -0.1, math.nan, math.inf])
def test_ransac_line_bad_threshold_raises(thr):
    pts, _, _, _ = _line_with_outliers()
    with pytest.raises(LidarfxError):
        ransac_line(pts, thr)


# ------------------------------------------------------------------ extract_segments
def _l_shape(seed, n=400, width=0.5):
    rng = np.random.default_rng(seed)
    a = _band(rng, (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), n, width, sigma=0.02)
    b = _band(rng, (0.0, 0.0, 0.0), (0.0, 8.0, 0.0), n, width, sigma=0.02)
    # sparse clutter 1.5–3 m above the bands: never within threshold of them
    clutter = np.c_[rng.uniform(-1.0, 11.0, 30), rng.uniform(-1.0, 9.0, 30), rng.uniform(1.5, 3.0, 30)]
    return np.vstack([a, b, clutter])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_extract_segments_l_shape(seed):
    p = _l_shape(seed)
    thr = 0.3
    segs = extract_segments(p, threshold=thr, seed=seed)
    assert len(segs) == 2
    corner = np.zeros(3)
    truths = {0: (np.array([10.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])),
              1: (np.array([0.0, 8.0, 0.0]), np.array([0.0, 1.0, 0.0]))}
    got = {}
    for s in segs:
        k = 0 if abs(s.direction[0]) > abs(s.direction[1]) else 1
        assert k not in got
        got[k] = s
    corner_gaps = []
    for k, s in got.items():
        far_true, d_true = truths[k]
        assert _angle_deg(s.direction, d_true) < 2.0
        ends = [s.start, s.end]
        far = min(ends, key=lambda e: np.linalg.norm(e - far_true))
        near = min(ends, key=lambda e: np.linalg.norm(e - corner))
        assert np.linalg.norm(far - far_true) < 0.3
        corner_gaps.append(float(np.linalg.norm(near - corner)))
        assert s.rms < thr
        assert s.support >= 0.9 * 400
    # the first segment claims the corner (its end within the half band width); the second
    # loses the points within threshold of the first line, so its end stops ≈ threshold short
    assert min(corner_gaps) < 0.3
    assert max(corner_gaps) < 2 * thr
    # the two lines meet at the true corner
    q1, q2, dist = closest_points_of_lines(got[0].start, got[0].direction, got[1].start, got[1].direction)
    assert np.linalg.norm(0.5 * (q1 + q2) - corner) < 0.05
    # indices: into the input points, disjoint, no clutter, every one within threshold of its line
    all_idx = np.concatenate([s.index for s in segs])
    assert len(np.unique(all_idx)) == len(all_idx)
    assert all_idx.max() < 800
    for s in segs:
        assert s.index.dtype == np.int64
        assert (point_line_distance(p[s.index], s.start, s.direction) <= thr).all()
        # ends are the extreme projections of the points
        t = (p[s.index] - s.start) @ s.direction
        assert abs(t.min()) < 1e-9 and abs(t.max() - s.length) < 1e-9


def test_extract_segments_utm_offset_same_segments():
    p = _l_shape(0)
    a = extract_segments(p, threshold=0.3, seed=0)
    b = extract_segments(p + UTM, threshold=0.3, seed=0)
    assert len(a) == len(b) == 2
    for sa, sb in zip(a, b):
        np.testing.assert_array_equal(np.sort(sa.index), np.sort(sb.index))
        np.testing.assert_allclose(sb.start - UTM, sa.start, atol=1e-5)
        np.testing.assert_allclose(sb.end - UTM, sa.end, atol=1e-5)


@pytest.mark.parametrize("gap, expected", [(2.0, 2), (0.5, 1)])
def test_extract_segments_gap_splits_collinear_pieces(gap, expected):
    rng = np.random.default_rng(21)
    a = _band(rng, (0.0, 0.0, 0.0), (5.0, 0.0, 0.0), 300, 0.2)
    b = _band(rng, (5.0 + gap, 0.0, 0.0), (10.0 + gap, 0.0, 0.0), 300, 0.2)
    p = np.vstack([a, b])
    segs = extract_segments(p, threshold=0.2, max_gap=1.0, seed=0)
    assert len(segs) == expected
    xs = sorted((min(s.start[0], s.end[0]), max(s.start[0], s.end[0])) for s in segs)
    assert abs(xs[0][0] - 0.0) < 0.1 and abs(xs[-1][1] - (10.0 + gap)) < 0.1
    if expected == 2:
        assert abs(xs[0][1] - 5.0) < 0.1 and abs(xs[1][0] - (5.0 + gap)) < 0.1
        assert sorted(s.support for s in segs) == [300, 300]
    else:
        assert segs[0].support == 600
    for s in segs:
        assert _angle_deg(s.direction, [1, 0, 0]) < 1.0


def _arc(seed, R=20.0, width=0.5, n=3000):
    rng = np.random.default_rng(seed)
    th = rng.uniform(0.0, math.pi / 2, n)
    r = R + rng.uniform(-width / 2, width / 2, n)
    return np.c_[r * np.cos(th), r * np.sin(th), rng.normal(0.0, 0.01, n)]


def _arc_deviation(s: LineSegment, R: float) -> float:
    """Largest distance of the segment (sampled) from the arc's centre line."""
    u = np.linspace(0.0, 1.0, 101)[:, None]
    q = s.start + u * (s.end - s.start)
    return float(np.abs(np.hypot(q[:, 0], q[:, 1]) - R).max())


def _angular_coverage(segs, lo=0.0, hi=math.pi / 2) -> float:
    iv = sorted(tuple(sorted((math.atan2(s.start[1], s.start[0]), math.atan2(s.end[1], s.end[0])))) for s in segs)
    total, cur = 0.0, None
    for a, b in iv:
        a, b = max(a, lo), min(b, hi)
        if cur is None or a > cur[1]:
            if cur is not None:
                total += cur[1] - cur[0]
            cur = [a, b]
        else:
            cur[1] = max(cur[1], b)
    if cur is not None:
        total += cur[1] - cur[0]
    return total / (hi - lo)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_extract_segments_arc_splits_at_bends(seed):
    R, thr = 20.0, 0.5
    p = _arc(seed, R=R)
    arc_len = R * math.pi / 2
    segs = extract_segments(p, threshold=thr, seed=seed)
    assert len(segs) >= 6
    for s in segs:
        assert _arc_deviation(s, R) <= thr  # split_tolerance (thr/2) keeps each piece on the arc
        assert s.length >= 1.0
    assert sum(s.length for s in segs) >= 0.9 * arc_len
    assert _angular_coverage(segs) >= 0.9
    # without splitting, the segments are the long chords RANSAC finds: fewer, and farther off the arc
    loose = extract_segments(p, threshold=thr, split_tolerance=1e3, seed=seed)
    assert len(loose) < len(segs)
    assert max(s.length for s in loose) > max(s.length for s in segs)
    assert max(_arc_deviation(s, R) for s in loose) > thr
    assert _angular_coverage(loose) >= 0.9


def test_extract_segments_arc_every_index_within_threshold():
    p = _arc(0, width=0.5)
    thr = 0.3
    segs = extract_segments(p, threshold=thr, seed=0)
    worst = max(float(point_line_distance(p[s.index], s.start, s.direction).max()) for s in segs)
    assert worst <= thr


def test_extract_segments_min_points_and_min_length():
    rng = np.random.default_rng(31)
    long_band = _band(rng, (0.0, 0.0, 0.0), (6.0, 0.0, 0.0), 200, 0.1)
    short_band = _band(rng, (0.0, 5.0, 0.0), (0.8, 5.0, 0.0), 100, 0.1)  # 0.8 m long
    sparse = _band(rng, (0.0, 10.0, 0.0), (3.0, 10.0, 0.0), 8, 0.05)  # 8 points only
    p = np.vstack([long_band, short_band, sparse])
    kinds = np.r_[np.zeros(200), np.ones(100), np.full(8, 2)]

    def labels(segs):
        return sorted(int(np.bincount(kinds[s.index].astype(int)).argmax()) for s in segs)

    assert labels(extract_segments(p, threshold=0.15, max_gap=2.0, seed=0)) == [0]
    assert labels(extract_segments(p, threshold=0.15, max_gap=2.0, min_length=0.5, seed=0)) == [0, 1]
    assert labels(extract_segments(p, threshold=0.15, max_gap=2.0, min_length=0.5, min_points=5, seed=0)) == [0, 1, 2]
    assert labels(extract_segments(p, threshold=0.15, max_gap=2.0, min_length=0.5, min_points=150, seed=0)) == [0]
    assert extract_segments(p, threshold=0.15, max_gap=2.0, min_points=250, seed=0) == []


def test_extract_segments_deterministic_and_indices_valid():
    p = _l_shape(4)
    a = extract_segments(p, threshold=0.3, seed=5)
    b = extract_segments(p, threshold=0.3, seed=5)
    assert len(a) == len(b) > 0
    for sa, sb in zip(a, b):
        np.testing.assert_array_equal(sa.index, sb.index)
        np.testing.assert_array_equal(sa.start, sb.start)
        np.testing.assert_array_equal(sa.end, sb.end)
        assert sa.rms == sb.rms
    # indices refer to the input array: permuting the input permutes them
    perm = np.random.default_rng(0).permutation(len(p))
    c = extract_segments(p[perm], threshold=0.3, seed=5)
    for s in c:
        assert (point_line_distance(p[perm][s.index], s.start, s.direction) <= 0.3).all()
        # and the points are the band points (none of the clutter, whose original index ≥ 800)
        assert (perm[s.index] < 800).all()


def test_extract_segments_errors_and_empty():
    with pytest.raises(LidarfxError):
        extract_segments(np.zeros((10, 2)), threshold=0.1)
    for thr in (0.0, -1.0, math.nan):
        with pytest.raises(LidarfxError):
            extract_segments(np.zeros((10, 3)), threshold=thr)
    assert extract_segments(np.zeros((0, 3)), threshold=0.1) == []
    # isotropic noise holds no segment of 10 points over 1 m at 5 cm
    rng = np.random.default_rng(1)
    assert extract_segments(rng.uniform(0, 20, (200, 3)), threshold=0.05) == []


# ------------------------------------------------------------------ merge_collinear
def test_merge_overlapping_collinear():
    a = _seg([0, 0, 0], [6, 0, 0], index=[0, 1, 2])
    b = _seg([4, 0, 0], [10, 0, 0], index=[2, 3])
    out = merge_collinear([a, b])
    assert len(out) == 1
    m = out[0]
    xs = sorted([m.start[0], m.end[0]])
    assert xs == pytest.approx([0.0, 10.0], abs=1e-9)
    assert np.abs(m.start[1:]).max() < 1e-9 and np.abs(m.end[1:]).max() < 1e-9
    np.testing.assert_array_equal(m.index, [0, 1, 2, 3])


def test_merge_reversed_direction_and_contained():
    a = _seg([0, 0, 0], [10, 0, 0], index=[0])
    b = _seg([7, 0, 0], [3, 0, 0], index=[1])  # inside, pointing the other way
    out = merge_collinear([a, b])
    assert len(out) == 1 and out[0].length == pytest.approx(10.0)


@pytest.mark.parametrize("gap_between, merges", [(0.5, True), (0.99, True), (1.5, False)])
def test_merge_gap(gap_between, merges):
    a = _seg([0, 0, 0], [4, 0, 0], index=[0])
    b = _seg([4 + gap_between, 0, 0], [10, 0, 0], index=[1])
    out = merge_collinear([a, b], gap=1.0)
    assert len(out) == (1 if merges else 2)
    if merges:
        assert out[0].length == pytest.approx(10.0)
    else:
        assert sorted(s.length for s in out) == pytest.approx([4.0, 6.0 - gap_between])


@pytest.mark.parametrize("deg, merges", [(3.0, True), (8.0, False)])
def test_merge_angle(deg, merges):
    a = _seg([0, 0, 0], [5, 0, 0], index=[0])
    r = math.radians(deg)
    b = _seg([5.2, 0, 0], [5.2 + 5 * math.cos(r), 5 * math.sin(r), 0], index=[1])
    out = merge_collinear([a, b], angle=5.0, offset=10.0, gap=1.0)  # offset large: the angle decides
    assert len(out) == (1 if merges else 2)


@pytest.mark.parametrize("lateral, merges", [(0.1, True), (0.4, False)])
def test_merge_lateral_offset(lateral, merges):
    a = _seg([0, 0, 0], [5, 0, 0], index=[0])
    b = _seg([5.3, 0, lateral], [10, 0, lateral], index=[1])
    out = merge_collinear([a, b], offset=0.25)
    assert len(out) == (1 if merges else 2)
    if merges:
        # unfixed, no points: the principal axis of the four ends (it tilts between the two lines)
        m = out[0]
        ends = np.array([a.start, a.end, b.start, b.end])
        c, d, _, _ = fit_line(ends)
        assert _angle_deg(m.direction, d) < 1e-9
        assert _dist_to_axis_line(ends, m.start, m.direction).max() < lateral
        assert sorted([m.start[0], m.end[0]]) == pytest.approx([0.0, 10.0], abs=0.01)


def test_merge_fixed_keeps_its_line():
    f = _seg([0, 0, 0], [5, 0, 0], fixed=True, index=[0, 1], label="edge")
    u = _seg([5.2, 0.1, 0.05], [12, 0.15, 0.1], index=[2, 3, 4], label="border")  # longer, off the line
    for order in ([f, u], [u, f]):
        out = merge_collinear(order)
        assert len(out) == 1
        m = out[0]
        assert m.fixed
        # exactly on the fixed line (y = z = 0), extended over both
        assert m.start[1] == 0.0 and m.start[2] == 0.0 and m.end[1] == 0.0 and m.end[2] == 0.0
        assert sorted([m.start[0], m.end[0]]) == pytest.approx([0.0, 12.0])
        np.testing.assert_array_equal(m.index, [0, 1, 2, 3, 4])
        assert m.label == "border"  # label of the longer segment


def test_merge_two_fixed_keeps_longer_line():
    a = _seg([0, 0, 0], [3, 0.03, 0], fixed=True, index=[0])  # short, slightly tilted (0.6°)
    b = _seg([3.5, 0, 0], [10, 0, 0], fixed=True, index=[1])  # long, along x
    for order in ([a, b], [b, a]):
        out = merge_collinear(order)
        assert len(out) == 1
        m = out[0]
        assert m.fixed
        assert _dist_to_axis_line(m.start, [0, 0, 0], [1, 0, 0])[0] < 1e-12
        assert _dist_to_axis_line(m.end, [0, 0, 0], [1, 0, 0])[0] < 1e-12
        assert sorted([m.start[0], m.end[0]]) == pytest.approx([0.0, 10.0])


def test_merge_refits_on_union_of_points():
    rng = np.random.default_rng(41)
    x = rng.uniform(0.0, 10.0, 400)
    pts = np.c_[x, 0.05 + 0.002 * x, rng.normal(0.0, 0.01, 400)]
    ia, ib = np.flatnonzero(x < 5.0), np.flatnonzero(x >= 5.5)
    # end points deliberately off the points' line (y = 0.15 / -0.05)
    a = _seg([0, 0.15, 0], [5, 0.15, 0], index=ia, rms=0.01)
    b = _seg([5.5, -0.05, 0], [10, -0.05, 0], index=ib, rms=0.01)
    m = merge_collinear([a, b], pts)[0]
    ref_c, ref_d, ref_rms, _ = fit_line(pts[np.r_[ia, ib]])
    assert _angle_deg(m.direction, ref_d) < 1e-6
    assert _dist_to_axis_line(m.start, ref_c, ref_d)[0] < 1e-9
    assert m.rms == pytest.approx(ref_rms, rel=1e-9)
    np.testing.assert_array_equal(m.index, np.sort(np.r_[ia, ib]))
    # the full extent of both segments is kept
    assert sorted([m.start[0], m.end[0]]) == pytest.approx([0.0, 10.0], abs=0.01)
    # without points: the support-weighted fit to the ends lies between the two end lines
    m2 = merge_collinear([a, b])[0]
    assert abs(m2.start[1] - m.start[1]) > 0.02


def test_merge_chain_of_three_in_passes_and_sorted():
    segs = [_seg([0, 0, 0], [3, 0, 0], index=[0]), _seg([3.5, 0, 0], [6, 0, 0], index=[1]),
            _seg([6.5, 0, 0], [9, 0, 0], index=[2]), _seg([0, 5, 0], [1, 5, 0], index=[3])]
    out = merge_collinear(segs, gap=1.0)
    assert len(out) == 2
    assert out[0].length == pytest.approx(9.0) and out[1].length == pytest.approx(1.0)  # longest first
    np.testing.assert_array_equal(out[0].index, [0, 1, 2])


# ------------------------------------------------------------------ chain_segments
RECT = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 6.0, 0.0], [0.0, 6.0, 0.0]])


def _rect_sides(short=0.2, flip=(False, True, False, True)):
    segs = []
    for k in range(4):
        a, b = RECT[k], RECT[(k + 1) % 4]
        d = _unit(b - a)
        s, e = a + short * d, b - short * d
        segs.append(_seg(e, s) if flip[k] else _seg(s, e))
    return segs


@pytest.mark.parametrize("flip", [(False, False, False, False), (False, True, False, True), (True, True, False, True)])
def test_chain_rectangle_closes(flip):
    segs = _rect_sides(flip=flip)
    order = [2, 0, 3, 1]  # input order does not matter
    out = chain_segments([segs[k] for k in order], join=1.0)
    assert len(out) == 1
    verts, ids, closed = out[0]
    assert closed
    assert sorted(ids) == [0, 1, 2, 3]
    assert verts.shape == (4, 3)
    for c in RECT:  # every vertex a corner, every corner a vertex
        assert np.linalg.norm(verts - c, axis=1).min() < 1e-6
    # vertices follow the ring (consecutive vertices are adjacent corners)
    side = np.linalg.norm(np.diff(np.vstack([verts, verts[:1]]), axis=0), axis=1)
    assert sorted(side) == pytest.approx([6.0, 6.0, 10.0, 10.0], abs=1e-6)


def test_chain_open_three():
    segs = [_seg([0, 0, 0], [4.8, 0, 0]), _seg([5, 0.2, 0], [5, 4.8, 0]), _seg([4.8, 5, 0], [1, 5, 0])]
    out = chain_segments(segs, join=1.0)
    assert len(out) == 1
    verts, ids, closed = out[0]
    assert not closed
    assert verts.shape == (4, 3)
    ordered = [[0, 0, 0], [5, 0, 0], [5, 5, 0], [1, 5, 0]]
    if np.linalg.norm(verts[0] - [0, 0, 0]) > 1e-9:
        ordered = ordered[::-1]
        ids = ids[::-1]
    np.testing.assert_allclose(verts, ordered, atol=1e-9)  # free ends stay, corners are the line crossings
    assert ids == [0, 1, 2]


def test_chain_side_by_side_parallel_not_joined():
    # a ladder: the nearest ends are 0.3 m apart but the segments do not continue each other
    segs = [_seg([0, 0, 0], [5, 0, 0]), _seg([0, 0.3, 0], [5, 0.3, 0])]
    out = chain_segments(segs, join=1.0, offset=0.1)
    assert len(out) == 2 and all(len(v) == 2 and not c for v, _, c in out)
    # nearly parallel (3°), staggered: end 0.6 m off the other line > offset 0.5 (join / 2)
    r = math.radians(3.0)
    segs = [_seg([0, 0, 0], [5, 0, 0]), _seg([5.3, 0.6, 0], [5.3 + 5 * math.cos(r), 0.6 + 5 * math.sin(r), 0])]
    out = chain_segments(segs, join=1.0)
    assert len(out) == 2
    # the same, within the offset: joined at the midpoint of the two ends
    segs = [_seg([0, 0, 0], [5, 0, 0]), _seg([5.3, 0.1, 0], [10, 0.1, 0])]
    out = chain_segments(segs, join=1.0)
    assert len(out) == 1
    np.testing.assert_allclose(out[0][0], [[0, 0, 0], [5.15, 0.05, 0], [10, 0.1, 0]], atol=1e-9)


def test_chain_fixed_end_is_vertex_of_continuation():
    f = _seg([0, 0, 0], [5, 0, 0], fixed=True)
    u = _seg([5.3, 0.05, 0.02], [10, 0.05, 0.02])
    for segs in ([f, u], [u, f]):
        out = chain_segments(segs, join=1.0)
        assert len(out) == 1
        verts = out[0][0]
        assert len(verts) == 3
        np.testing.assert_array_equal(verts[1], [5.0, 0.0, 0.0])


def test_chain_fixed_corner_vertex_on_fixed_line():
    f = _seg([0, 0, 0], [4.9, 0, 0], fixed=True)
    u = _seg([5.0, 0.2, 0.05], [5.0, 5.0, 0.05])  # perpendicular, skew (0.05 m above)
    for segs in ([f, u], [u, f]):
        verts = chain_segments(segs, join=1.0)[0][0]
        assert len(verts) == 3
        np.testing.assert_allclose(verts[1], [5.0, 0.0, 0.0], atol=1e-12)
    # both unfixed: the midpoint of the two closest points
    verts = chain_segments([_seg(f.start, f.end), u], join=1.0)[0][0]
    np.testing.assert_allclose(verts[1], [5.0, 0.0, 0.025], atol=1e-12)


def test_chain_far_segments_stay_separate():
    segs = [_seg([0, 0, 0], [5, 0, 0]), _seg([7, 0, 0], [10, 0, 0]), _seg([5, 2, 0], [5, 6, 0])]
    out = chain_segments(segs, join=1.0)
    assert len(out) == 3
    assert sorted(i for _, ids, _ in out for i in ids) == [0, 1, 2]
    for verts, ids, closed in out:
        assert not closed and len(verts) == 2
    # with a larger join the collinear pair joins (gap 2 m)
    out = chain_segments(segs[:2], join=2.5)
    assert len(out) == 1 and len(out[0][0]) == 3
    assert chain_segments([], join=1.0) == []


def test_chain_corner_too_far_from_ends_not_joined():
    # ends 0.5 m apart, but the lines (12° apart, > min_angle) cross 1.6 m behind the ends
    r = math.radians(12.0)
    segs = [_seg([0, 0, 0], [5, 0, 0]), _seg([5.3, 0.4, 0], [5.3 + 4 * math.cos(r), 0.4 + 4 * math.sin(r), 0])]
    q1, _, _ = closest_points_of_lines(segs[0].start, segs[0].direction, segs[1].start, segs[1].direction)
    assert np.linalg.norm(segs[1].start - segs[0].end) == pytest.approx(0.5)
    assert np.linalg.norm(q1 - segs[0].end) > 1.0
    assert len(chain_segments(segs, join=1.0)) == 2
    # the same corner with the crossing near the ends joins there
    segs = [_seg([0, 0, 0], [5, 0, 0]), _seg([5.3, 0.05, 0], [5.3 + 4 * math.cos(r), 0.05 + 4 * math.sin(r), 0])]
    out = chain_segments(segs, join=1.0)
    assert len(out) == 1
    np.testing.assert_allclose(out[0][0][1], [5.3 - 0.05 / math.tan(r), 0.0, 0.0], atol=1e-9)


# ------------------------------------------------------------------ douglas_peucker
def test_dp_zigzag_collapses():
    x = np.arange(0.0, 10.01, 0.5)
    v = np.c_[x, 0.04 * (-1.0) ** np.arange(len(x)), np.zeros(len(x))]
    out = douglas_peucker(v, 0.1)
    np.testing.assert_array_equal(out, v[[0, -1]])
    # below the zig-zag amplitude every vertex stays
    assert len(douglas_peucker(v, 0.01)) == len(v)


def test_dp_corner_stays():
    x = np.arange(0.0, 5.01, 0.25)
    leg1 = np.c_[x, 0.03 * np.sin(7 * x), np.zeros(len(x))]
    leg2 = np.c_[np.full(len(x) - 1, 5.0) + 0.03 * np.sin(5 * x[1:]), x[1:], 0.02 * x[1:]]
    v = np.vstack([leg1, leg2])
    out = douglas_peucker(v, 0.1)
    assert len(out) == 3
    np.testing.assert_array_equal(out[0], v[0])
    np.testing.assert_array_equal(out[-1], v[-1])
    assert np.linalg.norm(out[1] - [5.0, 0.0, 0.0]) < 0.1
    # the result keeps every dropped vertex within tolerance
    assert point_polyline_distance(v, out).max() <= 0.1


def test_dp_tolerance_zero_drops_only_collinear():
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0], [3, 2, 0], [4, 4, 1]], float)
    out = douglas_peucker(v, 0.0)
    np.testing.assert_array_equal(out, v[[0, 2, 3, 4, 5]])
    # the simplification is a subset in order, and an exact 3-D line keeps only its ends
    line = np.outer(np.linspace(0, 1, 9), [3.0, -2.0, 5.0])
    np.testing.assert_array_equal(douglas_peucker(line, 0.0), line[[0, -1]])


def test_dp_3d_deviation_counts():
    # the middle vertex is off the chord in z only
    v = np.array([[0, 0, 0], [5, 0, 0.3], [10, 0, 0]], float)
    assert len(douglas_peucker(v, 0.2)) == 3
    assert len(douglas_peucker(v, 0.4)) == 2


def test_dp_closed_square_ring():
    # a square ring sampled every 0.5 m, starting at a corner
    side = np.arange(0.0, 4.0, 0.5)
    z = np.zeros(len(side))
    ring = np.vstack([np.c_[side, z, z], np.c_[4 + z, side, z], np.c_[4 - side, 4 + z, z], np.c_[z, 4 - side, z]])
    out = douglas_peucker(ring, 0.1, closed=True)
    assert len(out) == 4
    np.testing.assert_array_equal(out, [[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]])
    # the 4 corners alone stay 4 below the half diagonal (2√2 m)
    corners = ring[[0, 8, 16, 24]]
    assert len(douglas_peucker(corners, 2.5, closed=True)) == 4
    # above it the ring keeps only its first vertex and the farthest one (documented; callers
    # must reopen such a ring, see lidarfx.edges)
    np.testing.assert_array_equal(douglas_peucker(corners, 3.0, closed=True), corners[[0, 2]])


def test_dp_short_and_errors():
    v = np.array([[0, 0, 0], [1, 1, 1]], float)
    out = douglas_peucker(v, 0.5)
    np.testing.assert_array_equal(out, v)
    assert out is not v
    for tol in (-0.1, math.nan, math.inf):
        with pytest.raises(LidarfxError):
            douglas_peucker(v, tol)


def test_polyline_of():
    pl = polyline_of(RECT, support=12, rms=0.05, kind="edge", closed=True, edge_share=1.0)
    assert isinstance(pl, Polyline)
    assert pl.closed and pl.support == 12 and pl.kind == "edge" and pl.attrs == {"edge_share": 1.0}
    assert pl.length == pytest.approx(32.0)
    with pytest.raises(LidarfxError):
        polyline_of(RECT[:1])


# ------------------------------------------------------------------ geometry.ransac_plane / intersect_planes
def _plane_with_outliers(seed, n_in=500, out_frac=0.3, offset=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    n_true = _unit([0.3, -0.4, 1.0])
    e1 = _unit(np.cross(n_true, [1.0, 0.0, 0.0]))
    e2 = np.cross(n_true, e1)
    c0 = np.array([2.0, 3.0, 1.0])
    uv = rng.uniform(-5.0, 5.0, (n_in, 2))
    pin = c0 + uv[:, :1] * e1 + uv[:, 1:] * e2 + rng.normal(0.0, 0.01, (n_in, 1)) * n_true
    n_out = int(round(n_in * out_frac / (1 - out_frac)))
    pout = c0 + rng.uniform(-5.0, 5.0, (n_out, 3))
    pts = np.vstack([pin, pout]) + np.asarray(offset)
    return pts, np.r_[np.ones(n_in, bool), np.zeros(n_out, bool)], c0 + np.asarray(offset), n_true


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), tuple(UTM)])
def test_ransac_plane_recovers_plane(offset):
    pts, truth, c0, n_true = _plane_with_outliers(1, offset=offset)
    assert (~truth).mean() == pytest.approx(0.3, abs=0.01)
    found = ransac_plane(pts, 0.05, seed=0)
    assert found is not None
    c, n, inl = found
    assert n[2] >= 0
    assert abs(np.linalg.norm(n) - 1.0) < 1e-9
    assert _angle_deg(n, n_true) < 1.0
    assert abs((c - c0) @ n_true) < 0.01  # the centroid lies on the true plane
    assert inl[truth].mean() >= 0.95
    assert inl[~truth].mean() < 0.05
    assert (np.abs((pts[inl] - c) @ n) <= 0.05).all()


def test_ransac_plane_normal_flipped_up():
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 10, (300, 2))
    pts = np.c_[xy, 0.5 * xy[:, 0] - 0.2 * xy[:, 1]]  # z = 0.5x − 0.2y: normal ∝ (−0.5, 0.2, 1)
    c, n, inl = ransac_plane(pts, 0.01, seed=3)
    np.testing.assert_allclose(n, _unit([-0.5, 0.2, 1.0]), atol=1e-9)
    assert inl.all()


def test_ransac_plane_alive_respected():
    pts, truth, _, n_true = _plane_with_outliers(2)
    rng = np.random.default_rng(6)
    # a second, larger horizontal plane z = 20: the dominant one when all points are alive
    big = np.c_[rng.uniform(0, 10, (900, 2)), np.full(900, 20.0)]
    allp = np.vstack([pts, big])
    is_big = np.r_[np.zeros(len(pts), bool), np.ones(900, bool)]
    c, n, inl = ransac_plane(allp, 0.05, seed=0)
    assert _angle_deg(n, [0, 0, 1]) < 1.0 and inl[is_big].all()
    c, n, inl = ransac_plane(allp, 0.05, seed=0, alive=~is_big)
    assert _angle_deg(n, n_true) < 1.0
    assert not inl[is_big].any()
    assert inl[np.r_[truth, np.zeros(900, bool)]].mean() >= 0.95


def test_ransac_plane_too_few_points():
    assert ransac_plane(np.zeros((2, 3)), 0.1) is None
    assert ransac_plane(np.zeros((0, 3)), 0.1) is None
    pts, _, _, _ = _plane_with_outliers(0)
    alive = np.zeros(len(pts), bool)
    alive[:2] = True
    assert ransac_plane(pts, 0.1, alive=alive) is None


def test_ransac_plane_deterministic():
    pts, _, _, _ = _plane_with_outliers(3)
    a, b = ransac_plane(pts, 0.05, seed=9), ransac_plane(pts, 0.05, seed=9)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


def test_intersect_planes_closed_form():
    c1, n1 = np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])  # z = 0
    c2, n2 = np.array([2.0, 5.0, 7.0]), np.array([1.0, 0.0, 0.0])  # x = 2
    point, d = intersect_planes(c1, n1, c2, n2)
    assert _angle_deg(d, [0, 1, 0]) < 1e-9 and abs(np.linalg.norm(d) - 1) < 1e-12
    # the line (2, y, 0); nearest to the midpoint (1, 2.5, 3.5) is (2, 2.5, 0)
    np.testing.assert_allclose(point, [2.0, 2.5, 0.0], atol=1e-12)
    # UTM-sized
    point, d = intersect_planes(c1 + UTM, n1, c2 + UTM, n2)
    np.testing.assert_allclose(point - UTM, [2.0, 2.5, 0.0], atol=1e-8)


def test_intersect_planes_general():
    rng = np.random.default_rng(12)
    for _ in range(20):
        c1, c2 = rng.normal(size=(2, 3)) * 10
        n1, n2 = _unit(rng.normal(size=3)), _unit(rng.normal(size=3))
        if abs(n1 @ n2) > 0.99:
            continue
        point, d = intersect_planes(c1, n1, c2, n2)
        assert abs((point - c1) @ n1) < 1e-9 and abs((point - c2) @ n2) < 1e-9  # on both planes
        assert abs(d @ n1) < 1e-12 and abs(d @ n2) < 1e-12
        m = 0.5 * (c1 + c2)
        assert abs((point - m) @ d) < 1e-9  # the foot of the midpoint on the line


def test_intersect_planes_parallel_gives_none():
    n1 = np.array([0.0, 0.0, 1.0])
    for deg, none in ((0.0, True), (0.5, True), (2.0, False)):
        r = math.radians(deg)
        n2 = np.array([math.sin(r), 0.0, math.cos(r)])
        res = intersect_planes([0, 0, 0], n1, [0, 0, 3], n2)
        assert (res is None) == none
    assert intersect_planes([0, 0, 0], n1, [1, 1, 1], -n1) is None  # anti-parallel
