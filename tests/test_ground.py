"""Ground filter (SMRF), DTM, height above ground and filter accuracy."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import lidarfx
import lidarfx.ground
from lidarfx import PointCloud, synth
from lidarfx.cli import main
from lidarfx.errors import LidarfxError
from lidarfx.ground import (
    DEFAULTS,
    Raster,
    apply_ground_classification,
    candidate_mask,
    classify_ground,
    dtm,
    ground_errors,
    height_above_ground,
)
from lidarfx.surface.tin import tin_interpolate

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
SAMPLES = ["samp11", "samp21", "samp23", "samp31", "samp41", "samp51", "samp53", "samp61"]

# Total error (%) of the default parameters on each ISPRS sample, as measured
# (docs/ground.md §4; re-measured on 2026-11-22 with the fixed-offset inpainting), and the bound the test holds
# them to (measured + 0.5 percentage points, to allow tiny numerical changes).
ISPRS_TOTAL = {
    "samp11": 7.73,
    "samp21": 1.37,
    "samp23": 5.84,
    "samp31": 3.36,
    "samp41": 3.88,
    "samp51": 3.73,
    "samp53": 5.64,
    "samp61": 1.60,
}
ISPRS_MARGIN = 0.5


# ------------------------------------------------------------------ helpers
def _scene(seed: int = 3):
    """Synthetic ALS scene: terrain with a dike and a ditch + box buildings + trees.

    Returns the coordinates (UTM-sized, no classes) and the true ground mask.
    """
    rng = np.random.default_rng(seed)
    g = synth.terrain(size=120.0, density=2.0, seed=seed).xyz
    occluded = np.zeros(len(g), bool)
    objects = []  # (kind, xy, extra)
    # buildings: flat roofs 6-12 m above the highest ground at their edges, sparse walls
    for cx, cy, w, d, h in [(-30, -30, 20, 14, 8), (25, 30, 30, 18, 12), (30, -35, 12, 12, 6), (-35, 30, 16, 26, 10)]:
        n = int(w * d * 2)
        roof_xy = np.column_stack([cx + (rng.random(n) - 0.5) * w, cy + (rng.random(n) - 0.5) * d])
        k = int(2 * (w + d) * h * 0.3)
        s = rng.random(k) * 2 * (w + d)
        wx = np.where(s < w, cx - w / 2 + s, np.where(s < w + d, cx + w / 2, np.where(s < 2 * w + d, cx + w / 2 - (s - w - d), cx - w / 2)))
        wy = np.where(s < w, cy - d / 2, np.where(s < w + d, cy - d / 2 + (s - w), np.where(s < 2 * w + d, cy + d / 2, cy + d / 2 - (s - 2 * w - d))))
        edges = np.array([[cx - w / 2, cy], [cx + w / 2, cy], [cx, cy - d / 2], [cx, cy + d / 2]])
        objects.append(("building", edges, (roof_xy, np.column_stack([wx, wy]), h)))
        occluded |= (np.abs(g[:, 0] - cx) < w / 2) & (np.abs(g[:, 1] - cy) < d / 2)
    # trees: crowns 3-8 m wide, 5-15 m high
    for _ in range(25):
        cx, cy = rng.uniform(-55, 55, 2)
        r = rng.uniform(1.5, 4.0)
        htop = rng.uniform(5, 15)
        n = int(np.pi * r * r * 3)
        a = rng.random(n) * 2 * np.pi
        rr = r * np.sqrt(rng.random(n))
        xy = np.column_stack([cx + rr * np.cos(a), cy + rr * np.sin(a)])
        objects.append(("tree", xy, (htop - (rr / r) ** 2 * htop * 0.5 + rng.normal(0, 0.3, n))))
    # the ground height under every object point: one linear TIN of the terrain
    zg = tin_interpolate(g[:, :2], g[:, 2], np.vstack([xy for _, xy, _ in objects]))
    parts, at = [g[~occluded]], 0
    for kind, xy, extra in objects:
        z = zg[at : at + len(xy)]
        at += len(xy)
        if kind == "building":
            roof_xy, wall_xy, h = extra
            base = float(z.max())
            parts.append(np.column_stack([roof_xy, base + h + rng.normal(0, 0.03, len(roof_xy))]))
            parts.append(np.column_stack([wall_xy, base + rng.random(len(wall_xy)) * h]))
        else:
            parts.append(np.column_stack([xy, z + extra]))
    xyz = np.vstack(parts)
    ref = np.zeros(len(xyz), bool)
    ref[: len(parts[0])] = True
    return xyz + [500000.0, 5400000.0, 200.0], ref


# ------------------------------------------------------------ ground_errors
def test_ground_errors_hand_made():
    ref = np.array([1, 1, 1, 1, 0, 0, 0, 0, 0, 0], bool)  # 4 ground, 6 object
    pred = np.array([1, 1, 0, 1, 1, 0, 0, 1, 0, 0], bool)  # 1 ground rejected, 2 objects accepted
    e = ground_errors(pred, ref)
    assert e["type_i"] == pytest.approx(1 / 4)
    assert e["type_ii"] == pytest.approx(2 / 6)
    assert e["total"] == pytest.approx(3 / 10)
    assert (e["n_type_i"], e["n_type_ii"], e["n_ground"], e["n_object"]) == (1, 2, 4, 6)
    assert e["table"] == [[3, 1], [2, 4]]
    with pytest.raises(LidarfxError):
        ground_errors(pred[:3], ref)


def test_ground_errors_empty_class_is_nan():
    e = ground_errors(np.array([True, False]), np.array([True, True]))
    assert e["type_i"] == pytest.approx(0.5)
    assert np.isnan(e["type_ii"])


# --------------------------------------------------------------- synthetic
def test_synthetic_terrain_buildings_trees():
    xyz, ref = _scene()
    mask = classify_ground(xyz)
    e = ground_errors(mask, ref)
    assert e["type_i"] < 0.02, e
    assert e["type_ii"] < 0.02, e
    assert e["total"] < 0.02, e
    # shift-invariance: the same scene at the origin gives the same answer
    assert np.array_equal(classify_ground(xyz - xyz.min(axis=0)), mask)


def test_final_test_in_chunks_equals_one_pass(monkeypatch):
    import sys

    xyz, _ = _scene()
    one = classify_ground(xyz)
    monkeypatch.setattr(sys.modules["lidarfx.ground.smrf"], "POINT_CHUNK", 997)
    assert len(xyz) > 3 * 997 and np.array_equal(classify_ground(xyz), one)


def test_dike_and_ditch_stay_ground():
    # plain SMRF opens the 3 m dike (1:2 slopes) away and rejects its crest;
    # the step check returns the smooth, step-free region to the terrain
    t = synth.terrain(size=120.0, density=2.0, seed=3)
    lf = t["landform"]
    mask = classify_ground(t)
    for k in range(5):
        assert mask[lf == k].mean() > 0.99, k
    plain = classify_ground(t, edge_share=0.0)
    assert plain[lf == 1].mean() < 0.7  # what the step check fixes


def test_synthetic_powerline_scene():
    pl = synth.powerline(seed=0)
    cls = pl["classification"]
    mask = classify_ground(pl)
    keep = cls != 7
    e = ground_errors(mask[keep], (cls == 2)[keep])
    assert e["total"] < 0.01, e
    assert not mask[cls == 14].any()  # no wire point is ground
    assert not mask[cls == 7].any()  # noise never ground


def test_noise_and_virtual_points_never_ground():
    t = synth.terrain(size=60.0, density=2.0, seed=2)
    xyz = t.xyz
    cls = np.full(len(xyz), 1, np.uint8)
    rng = np.random.default_rng(0)
    idx = rng.choice(len(xyz), 300, replace=False)
    cls[idx[:100]] = 7  # noise lying exactly on the ground surface
    cls[idx[100:200]] = 18
    cls[idx[200:]] = 66
    c = PointCloud(xyz, {"classification": cls})
    mask = classify_ground(c)
    assert not mask[idx].any()
    assert mask[cls == 1].mean() > 0.99
    out = apply_ground_classification(c, mask)
    assert np.array_equal(out["classification"][idx], cls[idx])  # kept
    assert set(np.unique(out["classification"][cls == 1])) <= {1, 2}
    assert out["classification"].dtype == cls.dtype
    assert c["classification"] is cls  # the input is not modified
    # with ignore_classes=None the noise on the surface becomes ground
    assert classify_ground(c, ignore_classes=None)[idx].mean() > 0.9


def test_last_returns_only():
    t = synth.terrain(size=60.0, density=2.0, seed=4)
    n = len(t)
    rn = np.ones(n, np.uint8)
    nr = np.ones(n, np.uint8)
    nr[:50] = 2  # first of two returns although lying on the ground
    c = PointCloud(t.xyz, {"return_number": rn, "number_of_returns": nr})
    mask = classify_ground(c)
    assert not mask[:50].any()
    assert mask[50:].mean() > 0.99
    assert classify_ground(c, last_returns=False)[:50].mean() > 0.9
    # zeros = no return information: every point is a candidate
    c0 = PointCloud(t.xyz, {"return_number": np.zeros(n, np.uint8), "number_of_returns": np.zeros(n, np.uint8)})
    assert candidate_mask(c0).all()


def test_apply_ground_classification_sets_classes_and_meta():
    xyz, ref = _scene(seed=5)
    c = PointCloud(xyz, {"classification": np.full(len(xyz), 6, np.uint8)})
    out = apply_ground_classification(c)
    assert set(np.unique(out["classification"])) == {1, 2}
    assert out.meta["ground"]["method"] == "smrf"
    assert out.meta["ground"]["slope"] == DEFAULTS["slope"]
    assert (out["classification"] == 2).sum() == out.meta["ground"]["ground_points"]


def test_units_follow_the_crs():
    f = REAL / "autzen_trim.laz"  # US survey feet
    if not f.exists():
        pytest.skip(f"missing {f}")
    c = lidarfx.read(f).subset(np.arange(30000))
    ft = lidarfx.ground.cloud_crs(c)["unit_to_metre"]
    auto = classify_ground(c)
    lengths = {k: DEFAULTS[k] / ft for k in ("cell", "window", "threshold", "scalar", "edge_step")}
    native = classify_ground(c, units="native", **lengths)
    assert np.array_equal(auto, native)
    assert not np.array_equal(auto, classify_ground(c, units="native"))
    with pytest.raises(LidarfxError):
        classify_ground(c, units="feet")


def test_ground_eval_converts_units_as_the_ground_command_does(tmp_path, capsys):
    """ground-eval filters a copy without classes; it must keep the header's CRS (feet here)."""
    f = REAL / "autzen_trim.laz"  # US survey feet
    if not f.exists():
        pytest.skip(f"{f.name} (US-feet ALS sample) is not in ../shared/data/real")
    c = lidarfx.read(f).subset(np.arange(30000))
    p = tmp_path / "autzen_part.laz"
    lidarfx.write(c, p)
    assert main(["ground-eval", str(p), "--json", "-q"]) == 0
    got = json.loads(capsys.readouterr().out)
    got = got["files"][0]
    want = lidarfx.ground.ground_errors(classify_ground(c), np.asarray(c["classification"]) == 2)
    native = lidarfx.ground.ground_errors(classify_ground(c, units="native"), np.asarray(c["classification"]) == 2)
    assert native["n_type_ii"] != want["n_type_ii"] or native["n_type_i"] != want["n_type_i"]  # the unit matters
    assert (got["n_type_i"], got["n_type_ii"]) == (want["n_type_i"], want["n_type_ii"])


def test_bad_parameters_and_empty_input():
    xyz = np.random.default_rng(0).random((50, 3))
    with pytest.raises(LidarfxError):
        classify_ground(xyz, cell=0)
    with pytest.raises(LidarfxError):
        classify_ground(xyz, slope=-1)
    with pytest.raises(LidarfxError):
        classify_ground(np.zeros((4, 2)))
    assert classify_ground(np.empty((0, 3))).shape == (0,)
    one = classify_ground(np.array([[1.0, 2.0, 3.0]]))
    assert one.tolist() == [True]


@pytest.mark.parametrize("share", [1.5, 1.0000001, -0.1, float("nan"), float("inf")])
def test_edge_share_is_a_share_from_0_to_1(share):
    """1.5 was accepted (no region can have more than all its boundary as steps: a silent no-op)."""
    xyz = np.random.default_rng(0).random((50, 3))
    with pytest.raises(LidarfxError, match="edge_share"):
        classify_ground(xyz, edge_share=share)


def test_edge_share_bounds_are_accepted():
    xyz = np.random.default_rng(0).random((50, 3))
    assert classify_ground(xyz, edge_share=0.0).shape == (50,)
    assert classify_ground(xyz, edge_share=1.0).shape == (50,)


@pytest.mark.parametrize("classes", [[256], [7, -1], [10**9], [10**23], [2.5], ["a"], 7, "7"])
def test_ignore_classes_are_class_codes_0_to_255(classes):
    """256, -1, 1e9 and a 23-digit code were accepted silently (they match no LAS class byte)."""
    c = PointCloud(np.random.default_rng(0).random((50, 3)), {"classification": np.ones(50, np.uint8)})
    with pytest.raises(LidarfxError, match="ignore_classes must be class codes from 0 to 255"):
        classify_ground(c, ignore_classes=classes)
    with pytest.raises(LidarfxError, match="ignore_classes must be class codes from 0 to 255"):
        candidate_mask(c, ignore_classes=classes)
    with pytest.raises(LidarfxError, match="ignore_classes must be class codes from 0 to 255"):
        apply_ground_classification(c, np.zeros(50, bool), ignore_classes=classes)


def test_ignore_classes_accepts_codes_arrays_and_none():
    cls = np.array([0, 255, 7, 1] * 5, np.uint8)
    c = PointCloud(np.random.default_rng(0).random((20, 3)), {"classification": cls})
    assert candidate_mask(c, ignore_classes=[0, 255]).tolist() == (~np.isin(cls, [0, 255])).tolist()
    assert candidate_mask(c, ignore_classes=np.array([7], np.uint8)).tolist() == (cls != 7).tolist()
    assert candidate_mask(c, ignore_classes=None).all() and candidate_mask(c, ignore_classes=[]).all()
    out = apply_ground_classification(c, np.zeros(20, bool), ignore_classes=(np.int64(255),))
    assert out.meta["ground"]["ignore_classes"] == [255]


# -------------------------------------------------------------- DTM and HAG
def _plane(x, y):
    return 0.3 * x - 0.2 * y + 100.0


def test_dtm_of_tilted_plane_is_the_plane():
    gx, gy = np.meshgrid(np.linspace(0, 40, 81), np.linspace(0, 30, 61))
    x = gx.ravel() + 652000.0
    y = gy.ravel() + 4300000.0
    xyz = np.column_stack([x, y, _plane(x - 652000.0, y - 4300000.0)])
    r = dtm(xyz, resolution=2.0)
    assert isinstance(r, Raster)
    assert r.resolution == 2.0
    assert r.origin[0] % 2.0 == 0 and r.origin[1] % 2.0 == 0  # aligned to the resolution
    cx, cy = r.cell_centres()
    X, Y = np.meshgrid(cx, cy)
    inside = (X <= x.max()) & (Y <= y.max())
    expect = _plane(X - 652000.0, Y - 4300000.0)
    assert np.allclose(r.array[inside], expect[inside], atol=1e-3)
    # row 0 is north
    assert cy[0] > cy[-1]
    assert r.transform == (r.origin[0], 2.0, 0.0, r.origin[1], 0.0, -2.0)
    # sampling the raster returns the plane between the centres too
    q = np.array([[652010.3, 4300007.7]])
    assert r.sample(q[:, 0], q[:, 1])[0] == pytest.approx(_plane(10.3, 7.7), abs=1e-3)


def test_dtm_from_cloud_uses_class_2_and_crs_from_header():
    f = REAL / "samp61-utm.laz"
    if not f.exists():
        pytest.skip(f"ISPRS sample missing: {f}")
    c = lidarfx.read(f)
    r = dtm(c, 5.0)
    assert r.crs is not None and r.crs["epsg"] == 32632
    g = c.xyz[c["classification"] == 2]
    # every ground point lies close to the DTM at its position (5 m cells, smooth terrain)
    d = g[:, 2] - r.sample(g[:, 0], g[:, 1])
    assert np.median(np.abs(d)) < 0.5
    with pytest.raises(LidarfxError):
        dtm(PointCloud(np.zeros((3, 3))), 1.0)  # no classification
    with pytest.raises(LidarfxError):
        dtm(c, 1.0, ground=np.zeros(len(c), bool))  # no ground points
    with pytest.raises(LidarfxError):
        dtm(c, 0.0)


def test_height_above_ground_on_plane():
    rng = np.random.default_rng(1)
    n = 2000
    x = rng.uniform(0, 50, n)
    y = rng.uniform(0, 50, n)
    ground = np.column_stack([x, y, _plane(x, y)])
    m = 500
    ox = rng.uniform(2, 48, m)
    oy = rng.uniform(2, 48, m)
    off = rng.uniform(0.2, 25.0, m)
    above = np.column_stack([ox, oy, _plane(ox, oy) + off])
    xyz = np.vstack([ground, above]) + [300000.0, 5000000.0, 0.0]
    cls = np.r_[np.full(n, 2, np.uint8), np.full(m, 1, np.uint8)]
    c = PointCloud(xyz, {"classification": cls})
    h = height_above_ground(c)
    assert h.dtype == np.float32
    assert np.allclose(h[n:], off, atol=1e-3)
    assert np.allclose(h[:n], 0.0, atol=1e-3)
    # same with an explicit mask and with a DTM raster
    assert np.allclose(height_above_ground(c, cls == 2), h)
    r = dtm(c, 1.0)
    assert np.allclose(height_above_ground(c, r)[n:], off, atol=0.02)
    # outside the hull of the ground: the nearest ground point's height
    far = PointCloud(np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0], [10.0, 10.0, 7.0]]),
                     {"classification": np.array([2, 2, 2, 1], np.uint8)})
    assert height_above_ground(far)[3] == pytest.approx(2.0)
    # no ground: NaN
    none = PointCloud(xyz[:10], {"classification": np.ones(10, np.uint8)})
    assert np.isnan(height_above_ground(none)).all()
    with pytest.raises(LidarfxError):
        height_above_ground(PointCloud(xyz[:10]))  # no classification, no mask


def test_tin_interpolate_is_linear_and_falls_back_to_nearest():
    xy = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    v = xy[:, 0] * 2 + xy[:, 1]
    q = np.array([[2.5, 7.5], [5.0, 5.0], [20.0, 0.0]])
    out = tin_interpolate(xy, v, q)
    assert out[0] == pytest.approx(12.5)
    assert out[1] == pytest.approx(15.0)
    assert out[2] == pytest.approx(20.0)  # nearest vertex (10, 0)
    assert np.isnan(tin_interpolate(xy, v, q, nearest_outside=False)[2])
    # collinear points: nearest everywhere
    assert tin_interpolate(xy[:2], v[:2], q[:1])[0] == pytest.approx(v[0])


def _gappy_ground(seed: int, n: int = 6000):
    """Random ground points (float coordinates: no cocircular quadruples) over 200 m x 120 m with
    two large holes (a 'building' and a 'lake') and a ragged edge."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([0, 0], [200, 120], (3 * n, 2))
    keep = ~((np.abs(xy[:, 0] - 60) < 25) & (np.abs(xy[:, 1] - 60) < 20))  # 50 x 40 m hole
    keep &= np.hypot(xy[:, 0] - 150, xy[:, 1] - 40) > 30  # 60 m round hole
    keep &= xy[:, 1] < 100 + 15 * np.sin(xy[:, 0] / 9)  # ragged northern edge
    xy = xy[keep][:n]
    z = 0.05 * xy[:, 0] + 3 * np.sin(xy[:, 1] / 17) + rng.normal(0, 0.2, len(xy))
    return xy, z


@pytest.mark.parametrize("max_points", [300, 1500])
def test_tin_tiled_equals_one_piece(max_points, monkeypatch):
    import sys

    tin_module = sys.modules["lidarfx.surface.tin"]
    xy, z = _gappy_ground(1)
    rng = np.random.default_rng(2)
    q = rng.uniform([-30, -30], [230, 150], (10_000, 2))  # also far outside the hull, and in the holes
    one = tin_interpolate(xy, z, q)
    widths = []
    real = tin_module._tin_one
    monkeypatch.setattr(tin_module, "_tin_one",
                        lambda *a: widths.append(a[4][2] - a[4][0] if len(a) > 4 else np.inf) or real(*a))
    tiled = tin_interpolate(xy, z, q, max_points=max_points, workers=1)
    assert np.array_equal(one, tiled)
    assert np.array_equal(tiled, tin_interpolate(xy, z, q, max_points=max_points, workers=3))  # tiles in threads
    # tiles were used, and the queries in the holes needed larger areas than their tile's
    assert len(widths) > 4 and max(w for w in widths if np.isfinite(w)) > 1.5 * min(widths)
    assert np.array_equal(tin_interpolate(xy, z, q, nearest_outside=False),
                          tin_interpolate(xy, z, q, nearest_outside=False, max_points=max_points), equal_nan=True)


def test_inpaint_from_border_cells_equals_all_known_cells():
    from lidarfx.surface.grid import GridSpec, inpaint

    rng = np.random.default_rng(5)
    ny, nx = 120, 150
    yy, xx = np.mgrid[0:ny, 0:nx]
    grid = 0.3 * xx - 0.1 * yy + 4 * np.sin(xx / 11.0) + rng.normal(0, 0.5, (ny, nx))
    grid[rng.random((ny, nx)) < 0.15] = np.nan  # scattered empty cells
    grid[30:70, 40:100] = np.nan  # a building-sized hole: rectangles of cocircular cell centres
    grid[:, :12] = np.nan  # a strip outside the hull, along the grid edge
    grid[(xx - 120) ** 2 + (yy - 95) ** 2 < 15 ** 2] = np.nan  # a round hole
    spec = GridSpec(np.array([[nx * 1.5 - 0.1, ny * 1.5 - 0.1]]), 1.5)
    assert spec.shape == (ny, nx)
    full = inpaint(grid, spec, all_known=True)
    border = inpaint(grid, spec)
    assert np.isfinite(border).all()
    assert np.array_equal(full, border)
    known = np.isfinite(grid)
    assert np.array_equal(border[known], grid[known])
    # a linear surface is reproduced inside the hull (up to the jitter of a thousandth of a cell)
    plane = np.where(known, 2.0 + 0.3 * xx - 0.2 * yy, np.nan)
    filled = inpaint(plane, spec)
    inside = (~known) & (xx >= 14) & (xx < nx - 2) & (yy >= 2) & (yy < ny - 2)  # within the hull
    assert np.abs(filled - (2.0 + 0.3 * xx - 0.2 * yy))[inside].max() < 1e-3


def test_height_above_ground_is_tiled_above_the_limit(monkeypatch):
    import sys

    dtm_module = sys.modules["lidarfx.ground.dtm"]  # lidarfx.ground.dtm is also the name of a function
    tin_module = sys.modules["lidarfx.surface.tin"]

    xy, z = _gappy_ground(3, 4000)
    rng = np.random.default_rng(4)
    objects = np.column_stack([rng.uniform(0, 200, 3000), rng.uniform(0, 120, 3000), rng.uniform(0, 20, 3000)])
    xyz = np.vstack([np.column_stack([xy, z]), objects]) + [600_000.0, 5_000_000.0, 100.0]
    mask = np.r_[np.ones(len(xy), bool), np.zeros(len(objects), bool)]
    one = height_above_ground(xyz, mask)
    calls = []
    real = tin_module._tin_tiled
    monkeypatch.setattr(tin_module, "_tin_tiled", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(dtm_module, "TIN_TILE_POINTS", 800)
    tiled = height_above_ground(xyz, mask)
    # ground points are triangle corners: a neighbouring triangle may give the last bit differently
    assert calls and np.allclose(one, tiled, rtol=0, atol=1e-6)


# ------------------------------------------------------------------ rasters
def test_raster_cell_of():
    r = Raster(np.zeros((3, 4), np.float32), (10.0, 25.0), 0.5)  # x 10–12, y 23.5–25, row 0 = north
    row, col = r.cell_of([10.0, 10.49, 10.5, 11.99, 9.0, 13.0], [25.0, 24.99, 24.5, 23.51, 30.0, 20.0])
    assert row.tolist() == [0, 0, 1, 2, 0, 2] and col.tolist() == [0, 0, 1, 3, 0, 3]  # outside: nearest edge cell


def test_raster_writers(tmp_path):
    PIL = pytest.importorskip("PIL.Image")
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    a[0, 0] = np.nan
    r = Raster(a, (500000.0, 5400003.0), 1.0, {"wkt": None, "epsg": 32632})
    p = r.write(tmp_path / "b.tif", engine="builtin")
    img = PIL.open(p)
    got = np.array(img, dtype=np.float32)
    assert np.array_equal(np.isnan(got), np.isnan(a))
    assert np.allclose(got[1:], a[1:])
    tags = img.tag_v2
    assert tuple(tags[33550])[:2] == (1.0, 1.0)
    assert tuple(tags[33922])[3:5] == (500000.0, 5400003.0)
    assert 32632 in tuple(tags[34735])
    wld = (tmp_path / "b.tfw").read_text().split()
    assert [float(v) for v in wld] == [1.0, 0.0, 0.0, -1.0, 500000.5, 5400002.5]
    q = r.write(tmp_path / "a.asc")
    lines = q.read_text().splitlines()
    assert lines[0] == "ncols 4" and lines[1] == "nrows 3"
    assert lines[3] == "yllcorner 5400000.0"
    assert lines[6].split()[0] == "-9999.000"
    with pytest.raises(LidarfxError):
        r.write(tmp_path / "x.png")
    with pytest.raises(LidarfxError):
        r.write(tmp_path / "missing" / "x.tif", engine="builtin")


def test_raster_rasterio_roundtrip(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    a = np.random.default_rng(0).random((5, 7)).astype(np.float32)
    r = Raster(a, (10.0, 25.0), 0.5, {"wkt": None, "epsg": 32632})
    for engine in ("rasterio", "builtin"):
        path = r.write(tmp_path / f"{engine}.tif", engine=engine)
        with rasterio.open(path) as ds:
            assert ds.crs.to_epsg() == 32632
            assert ds.transform.a == 0.5 and ds.transform.c == 10.0 and ds.transform.f == 25.0
            assert np.allclose(ds.read(1), a)


# -------------------------------------------------------------------- ISPRS
def _isprs(name):
    f = REAL / f"{name}-utm.laz"
    if not f.exists():
        pytest.skip(f"ISPRS filter-test sample missing: {f} (see shared/data/real/SOURCES.md)")
    c = lidarfx.read(f)
    ref = c["classification"] == 2
    bare = PointCloud(c.xyz, {k: c[k] for k in ("return_number", "number_of_returns")})  # no classes
    return bare, ref


@pytest.fixture(scope="module")
def isprs_results():
    out = {}
    for s in SAMPLES:
        bare, ref = _isprs(s)
        out[s] = ground_errors(classify_ground(bare), ref)
    return out


@pytest.mark.parametrize("sample", SAMPLES)
def test_isprs_sample_total_error(isprs_results, sample):
    e = isprs_results[sample]
    assert 100 * e["total"] <= ISPRS_TOTAL[sample] + ISPRS_MARGIN, e


def test_isprs_mean_total_error_at_most_5_percent(isprs_results):
    mean = np.mean([isprs_results[s]["total"] for s in SAMPLES])
    assert mean <= 0.05, mean


# ---------------------------------------------------------------------- CLI
@pytest.fixture()
def scene_file(tmp_path):
    xyz, ref = _scene(seed=7)
    cls = np.where(ref, 2, 6).astype(np.uint8)
    cls[:20] = 7
    c = PointCloud(xyz, {"classification": cls})
    path = tmp_path / "scene.laz"
    lidarfx.write(c, path)
    return path, ref, cls


def test_cli_ground_writes_classes_hag_and_dtm(scene_file, tmp_path, capsys):
    path, ref, cls = scene_file
    out = tmp_path / "out.laz"
    tif = tmp_path / "dtm.tif"
    rc = main(["ground", str(path), str(out), "--hag", "--dtm", str(tif), "--json", "-q"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == len(ref)
    c = lidarfx.read(out)
    assert "height_above_ground" in c
    new = c["classification"]
    assert np.array_equal(new[:20], cls[:20])  # noise kept
    e = ground_errors(new[20:] == 2, ref[20:])
    assert e["total"] < 0.02
    assert summary["ground_points"] == int((new == 2).sum())
    assert tif.exists()
    h = c["height_above_ground"]
    assert np.nanmax(np.abs(h[new == 2])) < 1e-3
    assert np.nanmedian(h[(new != 2) & (cls == 6)]) > 3.0


def test_cli_ground_eval_json(scene_file, capsys):
    path, ref, cls = scene_file
    rc = main(["ground-eval", str(path), "--reference-class", "2", "--json", "-q"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    row = res["files"][0]
    assert row["ignored_points"] == 20  # class 7 removed before filtering and scoring
    assert row["n_points"] == len(ref) - 20
    assert row["total"] < 0.02
    assert res["mean"]["total"] == pytest.approx(row["total"])
    assert set(row) >= {"type_i", "type_ii", "total", "n_type_i", "n_type_ii", "table"}
    rc = main(["ground-eval", str(path), str(path), "-q"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "type I" in text and "mean" in text
    # no point of the reference class: type I is undefined, written as null (strict JSON, no NaN)
    assert main(["ground-eval", str(path), "--reference-class", "99", "--json", "-q"]) == 0
    out = capsys.readouterr().out
    assert "NaN" not in out
    res = json.loads(out)
    assert res["files"][0]["type_i"] is None and res["mean"]["type_i"] is None
    assert res["files"][0]["type_ii"] > 0  # every point the filter calls ground is then an error


def test_cli_dtm(scene_file, tmp_path, capsys):
    path, ref, cls = scene_file
    asc = tmp_path / "d.asc"
    assert main(["dtm", str(path), str(asc), "-r", "2", "--json", "-q"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["resolution"] == 2.0
    assert asc.read_text().startswith("ncols")
    assert main(["dtm", str(path), str(tmp_path / "c.tif"), "--classify", "-q"]) == 0


def test_cli_errors_exit_2(scene_file, tmp_path, capsys):
    path, ref, cls = scene_file
    assert main(["ground", str(tmp_path / "missing.laz"), str(tmp_path / "o.laz")]) == 2
    assert main(["ground", str(path), str(tmp_path / "o.laz"), "--cell", "0"]) == 2
    assert main(["ground", str(path), str(tmp_path / "o.laz"), "--dtm", str(tmp_path / "d.png")]) == 2
    assert main(["ground", str(path), str(path)]) == 2  # never overwrite the input
    assert main(["ground-eval", str(tmp_path / "nope.laz")]) == 2
    unlabelled = tmp_path / "u.xyz"
    np.savetxt(unlabelled, np.random.default_rng(0).random((20, 3)))
    assert main(["ground-eval", str(unlabelled)]) == 2
    assert main(["ground-eval", str(path), "--ignore-classes", "1,2,6,7"]) == 2  # nothing left to score
    assert "no points to evaluate" in capsys.readouterr().err
    assert main(["dtm", str(unlabelled), str(tmp_path / "d.tif")]) == 2  # no classification
    with pytest.raises(SystemExit) as exc:
        main(["ground", str(path), str(tmp_path / "o.laz"), "--ignore-classes", "a,b"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "lidarfx: error:" in err


@pytest.mark.parametrize("opts, message", [
    (["--edge-share", "1.5"], "edge_share is a share of the boundary from 0 to 1 (0 = off), got 1.5"),
    (["--ignore-classes", "256"], "ignore_classes must be class codes from 0 to 255, got 256"),
    (["--ignore-classes", "7,-1"], "ignore_classes must be class codes from 0 to 255, got -1"),
    (["--ignore-classes", "99999999999999999999999"],
     "ignore_classes must be class codes from 0 to 255, got 99999999999999999999999"),
])
def test_cli_edge_share_and_class_codes_are_checked(scene_file, tmp_path, capsys, opts, message):
    """ground, ground-eval and dtm --classify refuse them before reading (they were accepted)."""
    path, ref, cls = scene_file
    assert main(["ground", str(path), str(tmp_path / "o.laz"), *opts]) == 2
    assert main(["ground-eval", str(path), "--json", *opts]) == 2
    assert main(["dtm", str(path), str(tmp_path / "o.tif"), "--classify", *opts]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.splitlines() == [f"lidarfx: error: {message}"] * 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.laz"]


def test_tiny_resolution_message_is_short(scene_file, tmp_path, capsys):
    """-r 1e-300 was refused with two ~300-digit cell counts in the message."""
    path, ref, cls = scene_file
    assert main(["dtm", str(path), str(tmp_path / "d.tif"), "-r", "1e-300", "-q"]) == 2
    assert main(["ground", str(path), str(tmp_path / "o.laz"), "--dtm", str(tmp_path / "d.tif"), "-r", "1e-300", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all(len(e) < 150 and "cells of 1e-300 is too large" in e for e in err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.laz"]


def test_points_with_nan_coordinates(tmp_path):
    """A point with a NaN coordinate is never ground, its height above ground is NaN and the DTM
    ignores it; the other points get what they get without it (a traceback before)."""
    rng = np.random.default_rng(5)
    xy = rng.uniform(0, 20, (400, 2))
    z = 0.1 * xy[:, 0] + 0.05 * xy[:, 1]
    xyz = np.column_stack([xy, z])
    xyz[::50, 2] += 3.0  # some objects
    bad = np.vstack([xyz, [[np.nan, 5.0, 1.0], [5.0, np.inf, 1.0]]])
    clean, dirty = PointCloud(xyz), PointCloud(bad)
    m0, m1 = classify_ground(clean, progress=False), classify_ground(dirty, progress=False)
    assert np.array_equal(m1[:400], m0) and not m1[400:].any()
    h0, h1 = height_above_ground(clean, m0), height_above_ground(dirty, m1)
    assert np.array_equal(h1[:400], h0) and np.isnan(h1[400:]).all()
    assert np.allclose(h0[::50][1:], 3.0, atol=1e-4)
    r0, r1 = dtm(clean, 2.0, ground=m0), dtm(dirty, 2.0, ground=m1)
    assert r1.array.shape == r0.array.shape and r1.origin == r0.origin
    assert np.array_equal(r1.array, r0.array)
    # a NaN point labelled ground (class 2) does not poison the surface either
    lab = PointCloud(bad, {"classification": np.where(np.append(m0, [True, True]), 2, 1).astype(np.uint8)})
    assert np.array_equal(dtm(lab, 2.0).array, r0.array)
    s = r0.sample(np.array([5.0, np.nan, 5.0]), np.array([5.0, 5.0, np.inf]))
    assert np.isfinite(s[0]) and np.isnan(s[1:]).all()
    assert np.isclose(s[0], 0.1 * 5 + 0.05 * 5, atol=0.05)
    assert np.isnan(r0.sample(np.nan, 5.0)) and np.isclose(r0.sample(5.0, 5.0), s[0])  # scalars too
    assert np.isnan(height_above_ground(dirty, r0)[400:]).all()
    # the CLI: text output keeps the NaN point, with NaN height; the DTM is written
    src = tmp_path / "nan.xyz"
    src.write_text("1 2 3\nnan 2 3\n4 5 6\n2 6 3.1\n")
    out, tif = tmp_path / "o.xyz", tmp_path / "d.tif"
    assert main(["ground", str(src), str(out), "--hag", "--dtm", str(tif), "-q"]) == 0
    rows = [line.split() for line in out.read_text().splitlines()[1:]]
    # the reader leaves the NaN point out (with a warning: docs/io.md); the others are classified
    assert [r[:3] for r in rows] == [["1.000", "2.000", "3.000"], ["4.000", "5.000", "6.000"],
                                     ["2.000", "6.000", "3.100"]]
    assert tif.exists()


def test_huge_window_is_capped_at_the_grid_diagonal():
    """Openings with disks larger than the grid change nothing more: a window of 1e308 m gives the
    result of a window just over the diagonal, at once (it ran for minutes before)."""
    from lidarfx.ground.smrf import window_radius

    assert window_radius(21.0, 1.0, 1000, 1000) == 21  # the default is untouched
    assert window_radius(1e308, 1.0, 30, 40) == window_radius(1e9, 1.0, 30, 40) == 50  # ceil(hypot(29, 39)) + 1
    assert window_radius(0.1, 1.0, 30, 40) == 1
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 30, (3000, 2))
    z = 2 * np.sin(xy[:, 0] / 6) + 0.05 * xy[:, 1]
    roof = (np.abs(xy[:, 0] - 12) < 5) & (np.abs(xy[:, 1] - 15) < 6)
    z[roof] += 6.0
    cloud = PointCloud(np.column_stack([xy, z]))
    diag = float(np.hypot(30, 30))
    ref = classify_ground(cloud, window=2 * diag, progress=False)
    assert not ref[roof].any() and ref[~roof].mean() > 0.9
    assert np.array_equal(classify_ground(cloud, window=1e308, progress=False), ref)
    assert np.array_equal(classify_ground(cloud, window=1.2 * diag, progress=False), ref)
    # the claim itself, without the cap: openings beyond the diagonal flag nothing more
    from lidarfx.ground.smrf import progressive_objects

    grid = np.random.default_rng(7).normal(0, 1, (12, 17)).cumsum(axis=0).cumsum(axis=1)
    cap = window_radius(1e308, 1.0, 17, 12)
    assert cap == 21  # ceil(hypot(16, 11)) + 1
    assert np.array_equal(progressive_objects(grid, 1.0, 0.1, cap), progressive_objects(grid, 1.0, 0.1, cap + 25))
    assert not np.array_equal(progressive_objects(grid, 1.0, 0.1, 3), progressive_objects(grid, 1.0, 0.1, cap))
