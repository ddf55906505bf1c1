"""Structure lines (breaklines): robust patch planes, the intersection and its sigma, the synthetic dike and ditch, the CLI."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx import PointCloud
from lidarfx.breaklines import _Model, _robust_plane, extract_breaklines, line_distances
from lidarfx.errors import LidarfxError
from lidarfx.vector import douglas_peucker

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
PRM = {"patch_length": 6.0, "patch_width": 2.5, "gap": 0.3, "step": 2.0, "min_angle": 8.0, "min_points": 8}


def test_robust_plane_ignores_points_above():
    rng = np.random.default_rng(0)
    s, t = rng.uniform(0, 3, 200), rng.uniform(-3, 3, 200)
    z = 1.0 + 0.2 * s - 0.1 * t
    z_off = z.copy()
    z_off[:20] += rng.uniform(0.5, 3.0, 20)  # vegetation left in the ground class
    p, cov, rms, ne, above = _robust_plane(s, t, z_off, 0.01)
    assert np.allclose(p, [1.0, 0.2, -0.1], atol=1e-6)
    assert above == pytest.approx(0.1) and ne == pytest.approx(180.0, abs=0.5) and rms < 1e-6


def _roof(rng, noise, n=4000, slope_l=0.0, slope_r=0.5, line_s=0.2):
    """Two planes meeting in the line s = line_s (x across, y along), height 2 there."""
    x, y = rng.uniform(-4, 4, n), rng.uniform(-6, 6, n)
    z = 2.0 + np.where(x > line_s, slope_l * (x - line_s), -slope_r * (x - line_s))
    return np.column_stack([x, y, z + rng.normal(0, noise, n) if noise else z])


def test_intersection_exact_and_sigma_matches_the_scatter():
    rng = np.random.default_rng(1)
    m = _Model(_roof(rng, 0.0), PRM, 0.01, 0.2, 0.15)
    v = m.pair(np.array([0.0, 0.0]), np.array([0.0, 1.0]))
    assert v.xy[0] == pytest.approx(0.2, abs=1e-9) and v.z == pytest.approx(2.0, abs=1e-9)
    assert v.angle == pytest.approx(math.degrees(math.atan(0.5)), abs=1e-6)
    # the sigma from the adjustment against the scatter of 60 noisy realisations
    got, sig_s, sig_z = [], [], []
    for k in range(60):
        pts = _roof(np.random.default_rng(100 + k), 0.05, n=400)
        v = _Model(pts, PRM, 0.01, 0.3, 0.5).settle(np.array([0.0, 0.0]), np.array([0.0, 1.0]))
        got.append((v.xy[0], v.z))
        sig_s.append(v.sigma_xy)
        sig_z.append(v.sigma_z)
    got = np.array(got)
    assert np.std(got[:, 0]) == pytest.approx(np.mean(sig_s), rel=0.35)
    assert np.std(got[:, 1]) == pytest.approx(np.mean(sig_z), rel=0.35)
    assert abs(np.mean(got[:, 0]) - 0.2) < 0.05


def _ditch(rng, noise, density=4.0, bottom=1.0, depth=1.2, slope_w=1.5):
    """A straight trapezoidal ditch along y: bottom |x| <= bottom/2, slopes slope_w wide, flat around."""
    n = int(density * 12 * 12)
    x, y = rng.uniform(-6, 6, n), rng.uniform(-6, 6, n)
    d = np.abs(x) - bottom / 2.0
    z = -depth + depth * np.clip(d / slope_w, 0.0, 1.0)
    return np.column_stack([x, y, z + rng.normal(0, noise, n)])


def test_narrow_face_gives_both_edges_of_a_ditch_bottom():
    prm = dict(PRM, patch_length=6.0, patch_width=2.5, gap=0.3)
    # noise-free, 4 pts/m²: both bottom edges, from trial lines in and beside the bottom's middle
    for k, x0 in ((0, 0.0), (1, 0.25), (2, -0.2)):
        m = _Model(_ditch(np.random.default_rng(k), 0.0), prm, 0.005, 0.013, 0.5)
        a, b = m.narrow_face(np.array([x0, 0.0]), np.array([0.0, 1.0]))
        assert sorted([a.xy[0], b.xy[0]]) == pytest.approx([-0.5, 0.5], abs=0.02)
        assert a.z == pytest.approx(-1.2, abs=0.02) and b.z == pytest.approx(-1.2, abs=0.02)
        assert a.angle == pytest.approx(math.degrees(math.atan(1.2 / 1.5)), abs=1.0)
    # 4 pts/m², 5 cm noise: within 0.15 m, over several realisations
    for k in range(5):
        m = _Model(_ditch(np.random.default_rng(10 + k), 0.05), prm, 0.025, 0.065, 0.5)
        got = m.narrow_face(np.array([0.0, 0.0]), np.array([0.0, 1.0]))
        assert got is not None
        assert sorted([got[0].xy[0], got[1].xy[0]]) == pytest.approx([-0.5, 0.5], abs=0.15)


def test_narrow_face_leaves_a_single_break_alone():
    prm = dict(PRM, patch_length=6.0, patch_width=2.5, gap=0.3)
    for k in range(5):
        pts = _roof(np.random.default_rng(30 + k), 0.05, n=400, slope_l=0.0, slope_r=0.5, line_s=0.0)
        assert _Model(pts, prm, 0.025, 0.065, 0.5).narrow_face(np.array([0.0, 0.0]), np.array([0.0, 1.0])) is None


def test_douglas_peucker_indices():
    v = np.array([[0, 0, 0], [1, 0.01, 0], [2, 0, 0], [3, 1, 0], [4, 0, 0.0]])
    idx = douglas_peucker(v, 0.1, return_index=True)
    assert idx.tolist() == [0, 2, 3, 4]
    assert np.array_equal(douglas_peucker(v, 0.1), v[idx])


def test_line_distances_closed_form():
    ref = [np.array([[0.0, 0.0, 1.0], [100.0, 0.0, 1.0]])]
    d = line_distances([np.array([[-10.0, 0.3, 1.2], [110.0, 0.3, 1.2]])], ref)
    assert d["completeness"] == 1.0 and d["correctness"] == pytest.approx(100 / 120, abs=0.01)
    assert d["rms_xy"] == pytest.approx(0.3, abs=1e-9) and d["rms_z"] == pytest.approx(0.2, abs=1e-9)
    assert d["mean_3d"] == pytest.approx(math.hypot(0.3, 0.2), abs=1e-9)
    half = line_distances([np.array([[0.0, 0.3, 1.2], [60.0, 0.3, 1.2]])], ref)
    assert half["completeness"] == pytest.approx(0.6, abs=0.015) and half["correctness"] == 1.0


@pytest.fixture(scope="module")
def terrain():
    cloud = lidarfx.synth.terrain(density=4, noise=0.05, vegetation=0.1, off_terrain=0.1, seed=1)
    return cloud, extract_breaklines(cloud)


def test_dike_lines_recovered(terrain):
    cloud, res = terrain
    truth = cloud.meta["truth"]["breaklines"]
    for b in truth:
        if not b["kind"].startswith("dike"):
            continue
        d = line_distances(res.lines, [b["points"]])
        assert d["completeness"] >= 0.95, b["kind"]
        assert d["rms_xy"] <= 0.1 and d["rms_z"] <= 0.05, (b["kind"], d)
    edges = [b["points"] for b in truth if b["kind"] == "ditch_edge"]
    d = line_distances(res.lines, edges)
    assert d["completeness"] >= 0.9 and d["rms_xy"] <= 0.3 and d["rms_z"] <= 0.05


def test_no_false_lines_and_vertex_records(terrain):
    cloud, res = terrain
    truth = [b["points"] for b in cloud.meta["truth"]["breaklines"]]
    for ln in res.lines:
        d = line_distances([ln], truth, step=0.5)
        assert (1.0 - d["correctness"]) * ln.length_2d <= 5.0  # no false part longer than 5 m
        assert len(ln.attrs["sigma_xy"]) == len(ln.attrs["sigma_z"]) == len(ln.attrs["angle"]) == ln.n_vertices
        assert ln.attrs["form"] in ("convex", "concave")
        assert 0 < ln.attrs["mean_sigma_xy"] < 0.2 and ln.attrs["mean_angle"] >= 8.0
    crest = [ln for ln in res.lines if line_distances([ln], truth[:2])["correctness"] > 0.9]
    assert crest and all(ln.attrs["form"] == "convex" for ln in crest)  # the dike crests are convex


def test_smooth_terrain_gives_no_line():
    rng = np.random.default_rng(4)
    xy = rng.uniform(0, 120, (60000, 2))
    z = 5 + 1.5 * np.sin(xy[:, 0] / 25.0) * np.cos(xy[:, 1] / 30.0) + 0.01 * xy[:, 0] + rng.normal(0, 0.05, len(xy))
    res = extract_breaklines(PointCloud(np.column_stack([xy, z]), {"classification": np.full(len(xy), 2, np.uint8)}))
    assert sum(ln.length_2d for ln in res.lines) <= 5.0


def test_approximations_replace_the_start_points(terrain):
    cloud, _ = terrain
    crest = np.asarray([b["points"] for b in cloud.meta["truth"]["breaklines"] if b["kind"] == "dike_crest"][0])
    rough = crest[::10, :2] + np.array([0.4, -0.3])  # a rough 2-D sketch, off by half a metre
    res = extract_breaklines(cloud, approximations=[rough])
    d = line_distances(res.lines, [crest])
    assert d["completeness"] >= 0.9 and d["rms_xy"] <= 0.1
    assert res.meta["start_points"] == 0
    assert {ln.attrs["form"] for ln in res.lines if ln.length_2d > 50} == {"convex"}  # a crest
    toe = np.asarray([b["points"] for b in cloud.meta["truth"]["breaklines"] if b["kind"] == "dike_toe"][0])
    res = extract_breaklines(cloud, approximations=[toe[::10, :2]])
    assert {ln.attrs["form"] for ln in res.lines if ln.length_2d > 50} == {"concave"}  # a toe


def test_refuses_bad_input():
    cloud = lidarfx.synth.terrain(density=1, seed=0, size=40)
    for kw, msg in (({"patch_width": -1}, "patch_width"), ({"min_angle": 100}, "min_angle"),
                    ({"approximations": [[[0, 0]]]}, "approximation"), ({"radius": 0}, "radius")):
        with pytest.raises(LidarfxError, match=msg):
            extract_breaklines(cloud, **kw)
    with pytest.raises(LidarfxError, match="ground points"):
        extract_breaklines(PointCloud(np.zeros((10, 3)) + np.arange(10)[:, None]), classes=None)
    with pytest.raises(LidarfxError, match="PointCloud"):
        extract_breaklines(np.zeros((10, 3)))


def test_synth_terrain_vegetation():
    plain = lidarfx.synth.terrain(seed=3, size=60)
    same = lidarfx.synth.terrain(seed=3, size=60, vegetation=0.0)
    assert np.array_equal(plain.xyz, same.xyz)
    veg = lidarfx.synth.terrain(seed=3, size=60, vegetation=0.2, off_terrain=0.25)
    info = veg.meta["truth"]["vegetation"]
    cls = np.asarray(veg["classification"])
    assert info["points"] == len(veg) - len(plain) > 0
    assert int((cls != 2).sum()) == info["points"] - info["off_terrain"]
    assert info["off_terrain"] == pytest.approx(0.25 * info["points"], rel=0.2)
    assert np.array_equal(veg.xyz[: len(plain)], plain.xyz)  # the ground is the same scene


# ----------------------------------------------------------------------------- CLI
def test_cli_outputs_and_errors(tmp_path, run_cli):
    cloud = lidarfx.synth.terrain(density=4, noise=0.05, seed=2, size=80)
    src = tmp_path / "t.laz"
    lidarfx.write(cloud, src)
    out = tmp_path / "lines.geojson"
    rc, so, err = run_cli(["breaklines", str(src), str(out), "--dxf", str(tmp_path / "l.dxf"), "--csv",
                        "--picture", str(tmp_path / "l.png"), "--json"])
    assert rc == 0, err
    s = json.loads(so)
    assert s["lines"] >= 4 and s["total_length"] > 200
    doc = json.loads(out.read_text())
    assert doc["features"][0]["geometry"]["type"] == "LineString"
    assert len(doc["features"][0]["geometry"]["coordinates"][0]) == 3
    assert len(doc["features"][0]["properties"]["sigma_xy"]) == len(doc["features"][0]["geometry"]["coordinates"])
    for name in ("l.dxf", "lines.csv", "lines.vertices.csv", "l.png"):
        assert (tmp_path / name).stat().st_size > 0
    for args, msg in ((["--classes", "x"], "--classes"), (["--approximations", str(tmp_path / "none.geojson")], "not found"),
                      (["--min-angle", "-3"], "min_angle")):
        rc, so, err = run_cli(["breaklines", str(src), str(tmp_path / "o.geojson"), *args])
        assert rc == 2 and msg in err and "Traceback" not in err
    rc, so, err = run_cli(["breaklines", str(src), str(tmp_path / "o.txt")])
    assert rc == 2 and "GeoJSON" in err


def test_hillshade_closed_form():
    from lidarfx.render import hillshade

    z = np.tile(np.arange(5.0), (5, 1))  # rising to the east at 45°
    # normal (-1, 0, 1)/√2, sun from the north-west at 45°: (-½, ½, 1/√2)
    assert hillshade(z, 1.0)[2, 2] == pytest.approx((0.5 + math.sqrt(0.5)) / math.sqrt(2.0))
    assert hillshade(np.zeros((1, 1)), 1.0)[0, 0] == pytest.approx(math.sin(math.radians(45)))
    assert hillshade(np.zeros((3, 1)), 1.0).shape == (3, 1)
