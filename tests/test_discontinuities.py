"""Rock-face discontinuities: Fisher statistics, joint-set search, the analysis on synthetic faces, the CLI."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx import PointCloud
from lidarfx.discontinuities import analyse_discontinuities, parse_reference_plane
from lidarfx.discontinuities.stats import axial_angle, axial_mean, find_sets, fisher_stats
from lidarfx.errors import LidarfxError
from lidarfx.geometry import normal_from_dip, plane_basis

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def fisher_sample(rng, mean, kappa, n):
    """Fisher-distributed unit vectors around ``mean`` (inverse-CDF of cos θ)."""
    u = rng.uniform(size=n)
    w = 1.0 + np.log(u + (1.0 - u) * np.exp(-2.0 * kappa)) / kappa
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    e1, e2, m = plane_basis(mean)
    s = np.sqrt(np.clip(1.0 - w * w, 0.0, None))
    return w[:, None] * m + s[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)


# ----------------------------------------------------------------------------- statistics
def test_fisher_closed_forms():
    n = normal_from_dip(40.0, 120.0)
    st = fisher_stats(np.array([n, n, -n]))  # axial: -n is the same plane
    assert st["kappa"] == math.inf and st["alpha95"] == 0.0 and st["n"] == 3
    assert axial_angle(st["mean"], n) < 1e-9
    # two poles 10 degrees apart: R = 2 cos 5°, kappa = 1 / (2 - R)
    a = normal_from_dip(30.0, 0.0)
    b = normal_from_dip(40.0, 0.0)
    st = fisher_stats(np.array([a, b]))
    r = 2.0 * math.cos(math.radians(5.0))
    assert st["R"] == pytest.approx(r, rel=1e-12)
    assert st["kappa"] == pytest.approx(1.0 / (2.0 - r), rel=1e-9)
    cos_a = 1.0 - (2.0 - r) / r * (20.0 ** (1.0 / 1.0) - 1.0)
    assert st["alpha95"] == pytest.approx(math.degrees(math.acos(cos_a)), rel=1e-9)
    assert axial_angle(st["mean"], normal_from_dip(35.0, 0.0)) < 1e-9
    # weights: scaled to a mean of 1, so N stays 2; the mean leans to the heavier pole
    w = fisher_stats(np.array([a, b]), [1.0, 3.0])
    assert w["n"] == 2
    resultant = 0.5 * a + 1.5 * b
    assert w["R"] == pytest.approx(np.linalg.norm(resultant), rel=1e-12)
    assert axial_angle(w["mean"], resultant) < 1e-9
    assert w["kappa"] == pytest.approx(1.0 / (2.0 - np.linalg.norm(resultant)), rel=1e-9)
    with pytest.raises(LidarfxError, match="weights"):
        fisher_stats(np.array([a, b]), [0.0, 0.0])
    one = fisher_stats(np.array([a]))
    assert math.isnan(one["kappa"]) and math.isnan(one["alpha95"])


def test_fisher_recovers_kappa():
    rng = np.random.default_rng(3)
    m = normal_from_dip(70.0, 300.0)
    v = fisher_sample(rng, m, 50.0, 4000)
    v[::2] *= -1  # half of the poles on the other side: axial data
    st = fisher_stats(v)
    assert st["kappa"] == pytest.approx(50.0, rel=0.08)
    assert axial_angle(st["mean"], m) < 3 * st["alpha95"]
    assert st["alpha95"] == pytest.approx(140.0 / math.sqrt(50.0 * 4000), rel=0.1)  # the usual approximation
    assert axial_mean(v)[2] >= 0


def test_find_sets_finds_four_sets_and_ignores_noise():
    rng = np.random.default_rng(0)
    truth = [(80, 170, 60, 6000), (65, 245, 40, 3000), (88, 90, 40, 1000), (30, 20, 80, 500)]
    v = [fisher_sample(rng, normal_from_dip(d, a), k, n) for d, a, k, n in truth]
    v = np.vstack(v + [rng.normal(size=(300, 3))])
    v *= rng.choice([-1.0, 1.0], len(v))[:, None]
    res = find_sets(v)
    assert len(res.means) == 4
    for (d, a, _, n), mean, share in zip(truth, res.means, res.shares):  # ordered by weight
        assert axial_angle(mean, normal_from_dip(d, a)) < 1.5
        assert share == pytest.approx(n / 10800, abs=0.02)
    assert (res.labels == -1).sum() < 400  # the uniform noise is mostly outside every cone
    two = find_sets(v, n_sets=2)
    assert len(two.means) == 2 and axial_angle(two.means[0], normal_from_dip(80, 170)) < 1.5
    # weights: the same poles weighted count like repeated poles
    few = np.array([normal_from_dip(50, 10)] * 3 + [normal_from_dip(50, 190)])
    assert len(find_sets(few, [1, 1, 1, 1], min_share=0.3).means) == 1
    assert len(find_sets(few, [1, 1, 1, 3], min_share=0.3).means) == 2


def test_find_sets_refuses_bad_input():
    with pytest.raises(LidarfxError, match="normals"):
        find_sets(np.zeros((3, 2)))
    with pytest.raises(LidarfxError, match="weights"):
        find_sets(np.eye(3), [1, 2])
    with pytest.raises(LidarfxError, match="cone"):
        find_sets(np.eye(3), cone=120)
    with pytest.raises(LidarfxError, match="number of sets"):
        find_sets(np.eye(3), n_sets=0)
    empty = find_sets(np.zeros((0, 3)))
    assert len(empty.means) == 0 and len(empty.labels) == 0


# ----------------------------------------------------------------------------- the synthetic rock face
def _match(res, truth_sets):
    """Our set id → the nearest true set, and the angles."""
    out, ang = {}, {}
    for s in res.sets:
        a = [float(axial_angle(normal_from_dip(s["dip"], s["dip_direction"]), t["normal"])) for t in truth_sets]
        out[s["id"]] = int(np.argmin(a))
        ang[s["id"]] = min(a)
    return out, ang


def _accuracy(res, cloud, mapping):
    js = np.asarray(cloud["joint_set"])
    got = np.asarray(res.cloud["set_id"])
    table = np.array([-1] + [mapping.get(k, -1) for k in range(len(res.sets))])
    ok = js >= 0
    return float((table[got + 1][ok] == js[ok]).mean())


@pytest.fixture(scope="module")
def face():
    cloud = lidarfx.synth.rockface(density=250, seed=1)
    res = analyse_discontinuities(cloud, scanner=cloud.meta["truth"]["scanners"])
    return cloud, res


def test_rockface_sets_orientations_assignment_overhang(face):
    cloud, res = face
    truth = cloud.meta["truth"]
    assert len(res.sets) == 3  # not told
    mapping, ang = _match(res, truth["sets"])
    assert sorted(mapping.values()) == [0, 1, 2]
    assert max(ang.values()) < 2.0, ang
    assert _accuracy(res, cloud, mapping) >= 0.95
    ov = np.asarray(cloud["overhang"]) == 1
    flag = np.asarray(res.cloud["overhang"]) == 1
    assert flag[ov].mean() >= 0.95
    assert flag[~ov].mean() < 0.01
    # the reference horizon: a horizontal plane at the scanners' height
    assert res.reference["kind"] == "horizontal"
    assert np.allclose(res.cloud["reference_distance"], cloud.z - truth["reference_horizon"]["z"], atol=1e-4)
    # outward normals face the scanners: the main face looks south, roofs look down
    ours = {v: k for k, v in mapping.items()}
    roof = np.asarray(res.cloud["set_id"]) == ours[2]
    assert np.median(np.asarray(res.cloud["normal_z"])[roof]) < -0.5
    m0 = np.asarray(res.cloud["set_id"]) == ours[0]
    assert np.median(np.asarray(res.cloud["normal_y"])[m0]) < -0.9
    # per-point dip / dip direction of the local planes
    d = np.asarray(res.cloud["dip"])[m0]
    assert np.nanmedian(d) == pytest.approx(80.0, abs=1.0)
    assert np.nanmedian(np.asarray(res.cloud["dip_direction"])[m0]) == pytest.approx(170.0, abs=1.0)


def test_rockface_records(face):
    cloud, res = face
    s0 = res.sets[0]
    assert s0["strike"] == pytest.approx((s0["dip_direction"] - 90) % 360)
    assert s0["pole_plunge"] == pytest.approx(90 - s0["dip"])
    assert sum(s["share"] for s in res.sets) == pytest.approx(1.0)
    assert sum(s["points"] for s in res.sets) == res.meta["set_points"]
    for s in res.sets:
        assert s["segments"] == sum(1 for g in res.segments if g["set_id"] == s["id"])
        assert s["kappa"] > 100 and s["alpha95"] < 2.0
    # every main facet is 5 m x 4 m (minus 5 cm gaps): no segment larger than two facets side by side,
    # and the areas add up to about the scanned facet area
    true_area = sum(f["area"] for f in cloud.meta["truth"]["facets"])
    assert sum(g["area"] for g in res.segments) == pytest.approx(true_area, rel=0.1)
    seg = np.asarray(res.cloud["segment_id"])
    assert (seg >= 0).mean() > 0.9
    assert np.asarray(res.cloud["selected"])[seg < 0].sum() == 0


def test_rockface_without_scanner_and_with_scatter():
    cloud = lidarfx.synth.rockface(density=200, seed=3, scatter=3.0)
    res = analyse_discontinuities(cloud)
    assert len(res.sets) == 3
    assert res.reference["kind"] == "fit"
    truth = cloud.meta["truth"]
    mapping, _ = _match(res, truth["sets"])
    facets = truth["facets"]
    for s in res.sets:  # the area-weighted mean of the facets actually generated, not the population mean
        mine = [f for f in facets if f["joint_set"] == mapping[s["id"]]]
        want = fisher_stats(np.array([f["normal"] for f in mine]), [f["area"] for f in mine])["mean"]
        assert axial_angle(normal_from_dip(s["dip"], s["dip_direction"]), want) < 1.0
    assert _accuracy(res, cloud, mapping) >= 0.95
    ov = np.asarray(cloud["overhang"]) == 1
    assert (np.asarray(res.cloud["overhang"])[ov] == 1).mean() >= 0.9


def _patch(rng, normal, centre, lengths, density, noise=0.005):
    e1, e2, n = plane_basis(normal)
    k = int(lengths[0] * lengths[1] * density)
    u = rng.uniform(-lengths[0] / 2, lengths[0] / 2, k)
    v = rng.uniform(-lengths[1] / 2, lengths[1] / 2, k)
    return centre + u[:, None] * e1 + v[:, None] * e2 + rng.normal(0, noise, k)[:, None] * n


def test_spacing_trace_and_area_closed_forms():
    rng = np.random.default_rng(5)
    n = normal_from_dip(40.0, 120.0)
    pts = [_patch(rng, n, np.array([0.0, 0.0, 0.0]) + k * 0.8 * n, (4.0, 2.0), 600) for k in range(4)]
    cloud = PointCloud(np.vstack(pts))
    res = analyse_discontinuities(cloud, radius=0.15)
    assert len(res.sets) == 1
    s = res.sets[0]
    assert s["dip"] == pytest.approx(40.0, abs=0.2) and s["dip_direction"] == pytest.approx(120.0, abs=0.3)
    assert s["spacing_count"] == 3
    assert s["spacing_mean"] == pytest.approx(0.8, abs=0.01)
    assert s["spacing_median"] == pytest.approx(0.8, abs=0.01)
    assert len(res.segments) == 4
    for g in res.segments:
        assert g["strike_length"] == pytest.approx(4.0, abs=0.05)
        assert g["dip_length"] == pytest.approx(2.0, abs=0.05)
        assert g["trace_length"] == pytest.approx(math.hypot(4.0, 2.0), abs=0.1)  # corners sampled to a few cm
        assert g["area"] == pytest.approx(8.0, rel=0.03)


# ----------------------------------------------------------------------------- reference planes
def test_reference_planes():
    rng = np.random.default_rng(1)
    cloud = PointCloud(_patch(rng, normal_from_dip(75.0, 180.0), np.array([0.0, 0.0, 5.0]), (6.0, 4.0), 400))
    res = analyse_discontinuities(cloud, radius=0.2, reference_plane="horizontal@2.5")
    assert np.allclose(res.cloud["reference_distance"], cloud.z - 2.5, atol=1e-4)
    res = analyse_discontinuities(cloud, radius=0.2, reference_plane="1,2,3,0,-2,0")
    assert np.allclose(res.cloud["reference_distance"], -(cloud.y - 2.0), atol=1e-4)
    res = analyse_discontinuities(cloud, radius=0.2, reference_plane="fit")
    assert np.abs(res.cloud["reference_distance"]).max() < 0.05  # every point on the fitted face
    assert res.reference["normal"][2] > 0  # turned up: outwards of a face leaning back
    assert res.cloud["overhang"].sum() == 0
    # the same face, seen from the north: the scanner tells which side is outside
    res = analyse_discontinuities(cloud, radius=0.2, scanner=(0.0, 20.0, 5.0))
    assert np.median(res.cloud["normal_y"]) > 0.9 and res.cloud["overhang"].mean() > 0.95


def test_parse_reference_plane():
    assert parse_reference_plane(None) is None
    assert parse_reference_plane("FIT")["kind"] == "fit"
    h = parse_reference_plane("horizontal", np.array([[0, 0, 1.0], [0, 0, 2.0]]))
    assert h["point"][2] == 1.5 and list(h["normal"]) == [0, 0, 1]
    p = parse_reference_plane([0, 0, 0, 3, 0, 4])
    assert np.allclose(p["normal"], [0.6, 0, 0.8])
    for bad, msg in (("horizontal", "needs a height"), ("horizontal@x", "must be a number"), ("1,2,3", "six"),
                     ("0,0,0,0,0,0", "must not be zero"), ("tilted", "use fit"), ("horizontal 3", "horizontal@Z")):
        with pytest.raises(LidarfxError, match=msg):
            parse_reference_plane(bad)


def test_analyse_refuses_bad_input():
    cloud = PointCloud(np.random.default_rng(0).uniform(size=(50, 3)))
    for kw, msg in (({"radius": -1}, "radius"), ({"max_angle": 0}, "max_angle"), ({"min_planarity": 2}, "min_planarity"),
                    ({"scanner": (1, 2)}, "scanner"), ({"n_sets": 0}, "n_sets"), ({"cone": 95}, "cone"),
                    ({"reference_plane": "up"}, "reference plane")):
        with pytest.raises(LidarfxError, match=msg):
            analyse_discontinuities(cloud, **kw)
    with pytest.raises(LidarfxError, match="at least 3"):
        analyse_discontinuities(PointCloud(np.zeros((2, 3))))
    with pytest.raises(LidarfxError, match="PointCloud"):
        analyse_discontinuities(np.zeros((10, 3)))


def test_a_cloud_without_planes_gives_no_sets():
    cloud = PointCloud(np.random.default_rng(0).uniform(0, 3, size=(3000, 3)))  # a box of random points
    res = analyse_discontinuities(cloud, radius=0.3)
    assert res.sets == [] and (np.asarray(res.cloud["set_id"]) == -1).all()


# ----------------------------------------------------------------------------- CLI
def test_cli_outputs(tmp_path, run_cli):
    cloud = lidarfx.synth.rockface(density=120, seed=2)
    src = tmp_path / "face.laz"
    lidarfx.write(cloud, src)
    sc = cloud.meta["truth"]["scanners"]
    args = ["discontinuities", str(src), str(tmp_path / "out"), "--json"]
    for s in sc:
        args += ["--scanner", ",".join(f"{v:g}" for v in s)]
    rc, out, err = run_cli(args)
    assert rc == 0, err
    summary = json.loads(out)
    assert len(summary["sets"]) == 3 and summary["reference_plane"]["kind"] == "horizontal"
    folder = tmp_path / "out"
    for name in ("cloud.laz", "sets.csv", "sets.json", "segments.csv", "stereonet.png", "rose.png", "sets.png"):
        assert (folder / name).stat().st_size > 0, name
    rows = list(csv.DictReader(open(folder / "sets.csv")))
    assert [int(r["id"]) for r in rows] == [0, 1, 2]
    segs = list(csv.DictReader(open(folder / "segments.csv")))
    assert {int(r["set_id"]) for r in segs} >= {0, 1, 2}
    doc = json.load(open(folder / "sets.json"))
    assert doc["sets"][0]["dip"] == pytest.approx(80.0, abs=2.0)
    back = lidarfx.read(folder / "cloud.laz")
    for name in ("dip", "dip_direction", "set_id", "segment_id", "reference_distance", "overhang", "selected"):
        assert name in back.names
    assert (back["set_id"] >= 0).mean() > 0.9


def test_cli_errors(tmp_path, run_cli):
    src = tmp_path / "face.laz"
    lidarfx.write(lidarfx.synth.rockface(density=20, seed=0), src)
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    for args, msg in (
        ([str(src), str(tmp_path / "o"), "--sets", "many"], "--sets"),
        ([str(src), str(tmp_path / "o"), "--reference-plane", "tilted"], "reference plane"),
        ([str(src), str(afile)], "not a folder"),
        ([str(tmp_path / "missing.laz"), str(tmp_path / "o")], "missing.laz"),
        ([str(src), str(tmp_path / "o"), "--scanner", "1,2"], "x,y,z"),
        ([str(src), str(tmp_path / "o"), "--max-angle", "0"], "max_angle"),
    ):
        rc, out, err = run_cli(["discontinuities", *args])
        assert rc == 2, (args, err)
        assert msg in err and "Traceback" not in err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


@pytest.mark.skipif(not (REAL / "lone-star.laz").exists(), reason="real file lone-star.laz not in ../shared/data/real")
def test_real_lone_star():
    cloud = lidarfx.read(REAL / "lone-star.laz")
    res = analyse_discontinuities(cloud)
    assert 2 <= len(res.sets) <= 6
    ground = res.sets[0] if res.sets[0]["dip"] < 10 else res.sets[1]
    assert ground["dip"] < 10 and ground["share"] > 0.3  # the sinter mound and the ground around it
    steep = [s for s in res.sets if s["dip"] > 75]
    assert steep  # the faces of the tree crowns turned to the scanner
    assert res.meta["selected_points"] > 0.3 * len(cloud)
