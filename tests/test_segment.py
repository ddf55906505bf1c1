"""Plane segmentation by surface growing (docs/segmentation.md, issue 6): real answers on known shapes."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx import LidarfxError, PointCloud
from lidarfx.cli import main
from lidarfx.geometry import normal_from_dip, plane_basis
from lidarfx.segment import (
    DEFAULTS,
    TABLE_COLUMNS,
    segment_planes,
    segments_table,
    write_segments_csv,
    write_segments_json,
)
from lidarfx.synth._common import sample_cylinder_surface, sample_patch, sample_rect

REAL = (Path(__file__).parents[1] / ".." / "shared" / "data" / "real").resolve()

# gable-roof house: x length L, y width W, eave height H, ridge rise R
L, W, H, R = 10.0, 8.0, 4.0, 3.0
ROOF_DIP = math.degrees(math.atan2(R, W / 2))  # 36.87°


def house(seed: int = 0, density: float = 400.0, noise: float = 0.003, origin=(0.0, 0.0, 0.0)) -> PointCloud:
    """Walls y=0, y=W, gable walls x=0, x=L (pentagons), two roof planes; ``plane`` = truth 0..5."""
    rng = np.random.default_rng(seed)
    parts, lab = [], []

    def add(p, k):
        parts.append(p)
        lab.append(np.full(len(p), k))

    for k, yv in ((0, 0.0), (1, W)):
        uv = sample_rect(rng, (0, L), (0, H), density)
        add(np.c_[uv[:, 0], np.full(len(uv), yv), uv[:, 1]], k)
    for k, xv in ((2, 0.0), (3, L)):
        uv = sample_rect(rng, (0, W), (0, H + R), density)
        uv = uv[uv[:, 1] <= H + R * (1 - np.abs(uv[:, 0] - W / 2) / (W / 2))]
        add(np.c_[np.full(len(uv), xv), uv[:, 0], uv[:, 1]], k)
    slant = math.hypot(W / 2, R)
    for k, side in ((4, 0), (5, 1)):
        uv = sample_rect(rng, (0, L), (0, slant), density)
        t = uv[:, 1] / slant
        y = t * W / 2 if side == 0 else W - t * W / 2
        add(np.c_[uv[:, 0], y, H + t * R], k)
    xyz = np.vstack(parts) + rng.normal(0.0, noise, (sum(map(len, parts)), 3))
    return PointCloud(xyz + np.asarray(origin), {"plane": np.concatenate(lab).astype(np.int32)})


# expected (dip, dip direction) per truth plane; walls: dip 90, dip direction = azimuth of the normal (axial)
HOUSE_ORIENT = {0: (90.0, 0.0), 1: (90.0, 0.0), 2: (90.0, 90.0), 3: (90.0, 90.0), 4: (ROOF_DIP, 180.0), 5: (ROOF_DIP, 0.0)}


@pytest.fixture(scope="module")
def house_cloud():
    return house()


@pytest.fixture(scope="module")
def house_seg(house_cloud):
    # min_width = the growing radius releases the thin strips of intermediate normals along edges
    return segment_planes(house_cloud, min_width=0.15)


def _dominant(ids: np.ndarray) -> tuple[int, float]:
    v, c = np.unique(ids, return_counts=True)
    k = int(np.argmax(c))
    return int(v[k]), float(c[k] / len(ids))


def _axial_azimuth_diff(a: float, b: float) -> float:
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


# ------------------------------------------------------------------ the house
def test_house_split_into_exactly_its_planes(house_cloud, house_seg):
    sid = house_seg["segment_id"]
    truth = house_cloud["plane"]
    assert sid.max() + 1 == 6  # exactly six segments: 4 walls + 2 roof planes
    seen = set()
    for k in range(6):
        s, share = _dominant(sid[truth == k])
        assert s >= 0 and share >= 0.95, (k, s, share)
        seen.add(s)
    assert len(seen) == 6  # one segment per plane, no plane shares a segment
    # and each segment holds (almost) only its own plane
    for s in range(6):
        _, purity = _dominant(truth[sid == s])
        assert purity >= 0.99
    assert (sid >= 0).mean() > 0.96


def test_house_table_orientations(house_cloud, house_seg):
    rows = {r["id"]: r for r in segments_table(house_seg)}
    assert len(rows) == 6
    sid = house_seg["segment_id"]
    truth = house_cloud["plane"]
    for k, (dip, ddir) in HOUSE_ORIENT.items():
        s, _ = _dominant(sid[truth == k])
        r = rows[s]
        assert r["dip"] == pytest.approx(dip, abs=0.3)
        if dip < 89.0:
            assert r["dip_direction"] == pytest.approx(ddir, abs=0.5)
        else:  # vertical: the up-flipped normal can point either way
            assert _axial_azimuth_diff(r["dip_direction"], ddir) < 0.5
        assert r["rms"] == pytest.approx(0.003, abs=0.0015)
        assert r["size"] == int((sid == s).sum())
        # convex hull in the plane: walls L×H, gable pentagons W×H + W·R/2, roofs L × slant
        area = {0: L * H, 1: L * H, 2: W * H + W * R / 2, 3: W * H + W * R / 2}.get(k, L * math.hypot(W / 2, R))
        assert r["area"] == pytest.approx(area, rel=0.03)


def test_house_min_size_for_the_density_also_gives_exactly_its_planes(house_cloud, house_seg):
    # instead of min_width: a min_size for this density (400 pts/m²): 150 points = 0.375 m²
    sid = segment_planes(house_cloud, min_size=150)["segment_id"]
    assert sid.max() + 1 == 6
    assert np.array_equal(sid, house_seg["segment_id"])


def test_house_defaults_only_add_small_edge_strips(house_cloud):
    seg = segment_planes(house_cloud)  # default min_size = 30, no min_width
    sid, truth = seg["segment_id"], house_cloud["plane"]
    for k in range(6):
        s, share = _dominant(sid[truth == k])
        assert s < 6 and share >= 0.95  # the six planes are the six largest segments
    sizes = np.bincount(sid[sid >= 0])
    assert (sizes[6:] < 0.005 * len(sid)).all()  # the rest: thin strips of intermediate normals along edges
    assert seg.meta["segmentation"]["parameters"]["min_size"] == 30


def test_ids_by_decreasing_size_and_dtypes(house_seg):
    sid, ssz = house_seg["segment_id"], house_seg["segment_size"]
    assert sid.dtype == np.int32 and ssz.dtype == np.int32
    sizes = np.bincount(sid[sid >= 0])
    assert (np.diff(sizes) <= 0).all()
    assert (ssz[sid >= 0] == sizes[sid[sid >= 0]]).all()
    assert (ssz[sid < 0] == 0).all()


def test_deterministic_and_utm_safe(house_cloud, house_seg):
    again = segment_planes(house_cloud, min_width=0.15)
    assert np.array_equal(again["segment_id"], house_seg["segment_id"])
    shifted = house(origin=(500_000.0, 5_400_000.0, 300.0))
    s2 = segment_planes(shifted, min_width=0.15)
    same = (s2["segment_id"] == house_seg["segment_id"]).mean()
    assert same > 0.999
    r0, r1 = segments_table(house_seg)[0], segments_table(s2)[0]
    assert r1["centroid_x"] - 500_000.0 == pytest.approx(r0["centroid_x"], abs=1e-3)
    assert r1["dip"] == pytest.approx(r0["dip"], abs=1e-3)


def test_input_not_modified_unless_inplace(house_cloud):
    small = house_cloud.subset(house_cloud["plane"] == 4)
    out = segment_planes(small)
    assert "segment_id" not in small and "segment_id" in out
    segment_planes(small, inplace=True, keep_features=True)
    assert {"segment_id", "segment_size", "normal_x", "plane_std"} <= set(small.names)


def test_scanner_orients_the_kept_normals_only():
    c = _two_parallel_planes(0.3)
    up = segment_planes(c, keep_features=True)
    down = segment_planes(c, keep_features=True, scanner=(2.0, 2.0, -5.0))
    ok = np.isfinite(up["normal_z"])
    assert ok.mean() > 0.999
    assert (up["normal_z"][ok] > 0.5).all() and (down["normal_z"][ok] < -0.5).all()
    assert np.array_equal(up["segment_id"], down["segment_id"])  # the growing compares normals axially


# ---------------------------------------------------------- other geometries
def _two_parallel_planes(gap: float, seed: int = 1) -> PointCloud:
    rng = np.random.default_rng(seed)
    a = sample_patch(rng, (0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 4), (0, 4), 600)
    b = sample_patch(rng, (0, 0, gap), (1, 0, 0), (0, 1, 0), (0, 4), (0, 4), 600)
    xyz = np.vstack([a, b]) + rng.normal(0, 0.003, (len(a) + len(b), 3))
    return PointCloud(xyz, {"plane": np.r_[np.zeros(len(a)), np.ones(len(b))].astype(np.int32)})


@pytest.mark.parametrize("growing_radius", [0.15, 0.5])
def test_parallel_planes_03m_apart_stay_separate(growing_radius):
    c = _two_parallel_planes(0.3)
    sid = segment_planes(c, growing_radius=growing_radius)["segment_id"]
    s0, f0 = _dominant(sid[c["plane"] == 0])
    s1, f1 = _dominant(sid[c["plane"] == 1])
    assert s0 >= 0 and s1 >= 0 and s0 != s1
    assert f0 >= 0.95 and f1 >= 0.95
    # no segment holds points of both planes (0.3 m > max distance 0.10 m to the segment plane)
    for s in np.unique(sid[sid >= 0]):
        assert len(np.unique(c["plane"][sid == s])) == 1


def test_cylinder_is_not_one_plane():
    rng = np.random.default_rng(3)
    xyz = sample_cylinder_surface(rng, (0, 0, 0), (0, 0, 1), 1.0, 3.0, 500)
    xyz += rng.normal(0, 0.002, xyz.shape)
    sid = segment_planes(PointCloud(xyz))["segment_id"]
    sizes = np.bincount(sid[sid >= 0])
    # ±15° of normal deviation allows at most ~30° of the 360° circumference per segment
    assert sizes.max() < 0.15 * len(xyz)
    assert len(sizes) >= 8


def test_tilted_plane_table_exact():
    dip, ddir = 35.0, 120.0
    n = normal_from_dip(dip, ddir)
    e1, e2, _ = plane_basis(n)
    rng = np.random.default_rng(7)
    centre = np.array([1000.0, 2000.0, 50.0])
    xyz = sample_patch(rng, centre - 2.0 * e1 - 1.5 * e2, e1, e2, (0, 4), (0, 3), 800)
    xyz += rng.normal(0, 0.002, (len(xyz), 1)) * n
    seg = segment_planes(PointCloud(xyz))
    rows = segments_table(seg)
    assert len(rows) == 1
    r = rows[0]
    assert r["size"] == len(xyz)
    assert r["dip"] == pytest.approx(dip, abs=0.1)
    assert r["dip_direction"] == pytest.approx(ddir, abs=0.1)
    assert r["area"] == pytest.approx(12.0, rel=0.03)
    assert r["rms"] == pytest.approx(0.002, rel=0.15)
    assert [r["centroid_x"], r["centroid_y"], r["centroid_z"]] == pytest.approx(centre.tolist(), abs=0.02)
    assert np.dot([r["normal_x"], r["normal_y"], r["normal_z"]], n) == pytest.approx(1.0, abs=1e-5)
    assert list(r) == TABLE_COLUMNS


def test_small_segments_released_and_isolated_points_unsegmented():
    rng = np.random.default_rng(5)
    big = sample_patch(rng, (0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 2), (0, 2), 500)  # 2000 pts
    tiny = sample_patch(rng, (5, 5, 0), (1, 0, 0), (0, 1, 0), (0, 0.2), (0, 0.2), 500)  # 20 pts
    lone = np.array([[9.0, 9.0, 9.0], [9.0, 9.5, 9.0]])  # no neighbours: normal is NaN
    c = PointCloud(np.vstack([big, tiny, lone]))
    seg = segment_planes(c, min_size=30)
    sid = seg["segment_id"]
    assert (sid[: len(big)] == 0).mean() > 0.998  # a corner point may have < 3 neighbours (no normal)
    assert (sid[len(big) :] == -1).all()
    assert (seg["segment_size"][len(big) :] == 0).all()
    assert seg.meta["segmentation"]["no_normal_points"] >= 2
    assert (seg["segment_size"][sid == 0] == (sid == 0).sum()).all()
    assert segment_planes(c, min_size=10)["segment_id"][len(big) : len(big) + len(tiny)].max() == 1


def test_min_width_releases_thin_strips():
    rng = np.random.default_rng(11)
    wide = sample_patch(rng, (0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 2), (0, 1), 1500)
    strip = sample_patch(rng, (0, 3, 0), (1, 0, 0), (0, 1, 0), (0, 3), (0, 0.08), 1500)  # 8 cm wide
    c = PointCloud(np.vstack([wide, strip]))
    kept = segment_planes(c)["segment_id"]
    assert (kept[len(wide):] >= 0).mean() > 0.95  # width not tested by default
    sid = segment_planes(c, min_width=0.15)["segment_id"]
    assert (sid[:len(wide)] == 0).mean() > 0.99 and (sid[len(wide):] == -1).all()
    assert sid.max() == 0


@pytest.mark.parametrize(
    "kw",
    [
        {"normal_radius": 0.0},
        {"growing_radius": -1.0},
        {"max_distance": float("nan")},
        {"max_angle": 0.0},
        {"max_angle": 95.0},
        {"min_size": 0},
        {"min_size": 2.5},
        {"min_width": -0.1},
        # integers beyond the numba kernel's int64 were a TypingError traceback
        {"min_size": 99999999999999999999999},
        {"min_size": 10**12 + 1},
        {"min_size": float("inf")},
        {"first_refit": 10**23},
        {"first_refit": 2},
        {"refit_max": 10**23},
        {"refit_max": 0},
    ],
)
def test_bad_parameters(kw):
    with pytest.raises(LidarfxError):
        segment_planes(_two_parallel_planes(0.3), **kw)


def test_integer_options_range_message_and_upper_bound():
    cloud = _two_parallel_planes(0.3)
    with pytest.raises(LidarfxError) as exc:
        segment_planes(cloud, min_size=99999999999999999999999)
    assert str(exc.value) == "min_size must be an integer from 1 to 10^12, got 99999999999999999999999"
    # the largest min_size is valid: it releases every segment
    out = segment_planes(cloud, min_size=10**12, first_refit=10**12, refit_max=10**12)
    assert (out["segment_id"] == -1).all() and out.meta["segmentation"]["segments"] == 0


def test_empty_or_wrong_input():
    with pytest.raises(LidarfxError, match="empty"):
        segment_planes(PointCloud(np.empty((0, 3))))
    with pytest.raises(LidarfxError, match="PointCloud"):
        segment_planes(np.zeros((10, 3)))


def test_lis_defaults():
    assert DEFAULTS == {
        "normal_radius": 0.10, "max_distance": 0.10, "growing_radius": 0.15, "max_angle": 15.0,
        "min_size": 30, "min_width": 0.0,
    }


# ------------------------------------------------------------------ real data
def test_real_plane_laz_one_segment():
    path = REAL / "plane.laz"
    if not path.exists():
        pytest.skip(f"real data not found: {path} (../shared/data/real)")
    cloud = lidarfx.read(path)
    sid = segment_planes(cloud)["segment_id"]  # LIS defaults
    s, share = _dominant(sid)
    assert s == 0 and share >= 0.95


# ------------------------------------------------------------------ writers
def test_table_writers(tmp_path):
    seg = segment_planes(_two_parallel_planes(0.3))
    rows = segments_table(seg)
    rows.append(dict(rows[0], id=99, rms=float("nan")))
    pc = write_segments_csv(rows, tmp_path / "t.csv")
    pj = write_segments_json(rows, tmp_path / "t.json", {"k": 1})
    with open(pc, newline="") as fh:
        got = list(csv.DictReader(fh))
    assert list(got[0]) == TABLE_COLUMNS and len(got) == 3
    assert float(got[0]["dip"]) == pytest.approx(rows[0]["dip"], abs=1e-5)
    assert got[2]["rms"] == ""
    doc = json.loads(pj.read_text())
    assert doc["columns"] == TABLE_COLUMNS and doc["segmentation"] == {"k": 1}
    assert doc["segments"][2]["rms"] is None and doc["segments"][0]["size"] == rows[0]["size"]
    assert not list(tmp_path.glob(".*part*"))


# ------------------------------------------------------------------ CLI
def test_cli_segment(tmp_path, capsys):
    c = _two_parallel_planes(0.3)
    src = tmp_path / "two.laz"
    lidarfx.write(c, src)
    out = tmp_path / "seg.laz"
    assert main(["segment", str(src), str(out), "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["segments"] == 2 and summary["points"] == len(c)
    assert summary["parameters"]["growing_radius"] == 0.15
    back = lidarfx.read(out)
    assert back["segment_id"].dtype == np.int32 and set(np.unique(back["segment_id"])) <= {-1, 0, 1}
    with open(tmp_path / "seg.laz.segments.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2
    assert json.loads((tmp_path / "seg.laz.segments.json").read_text())["segments"][0]["id"] == 0
    # --table stem, parameters, rich summary on stderr
    assert main(["segment", str(src), str(tmp_path / "b.laz"), "--table", str(tmp_path / "planes.csv"),
                 "--max-angle", "10", "--min-size", "50", "--min-width", "0.15"]) == 0
    err = capsys.readouterr().err
    assert "2 plane segments" in err and "largest" in err
    assert (tmp_path / "planes.csv").exists() and (tmp_path / "planes.json").exists()


def test_cli_segment_errors(tmp_path, capsys):
    src = tmp_path / "two.laz"
    lidarfx.write(_two_parallel_planes(0.3), src)
    assert main(["segment", str(src), str(tmp_path / "o.laz"), "--max-angle", "120"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "max_angle" in err[0]
    assert not (tmp_path / "o.laz").exists()
    # a picture that cannot be written is refused before any work (no point cloud written)
    assert main(["segment", str(src), str(tmp_path / "o.laz"), "--picture", str(tmp_path / "no" / "p.png")]) == 2
    assert "output folder does not exist" in capsys.readouterr().err
    assert not (tmp_path / "o.laz").exists()
    # an integer beyond the kernel's int64 was a numba TypingError traceback; refused before reading
    assert main(["segment", str(src), str(tmp_path / "o.laz"), "--min-size", "99999999999999999999999"]) == 2
    assert capsys.readouterr().err == "lidarfx: error: min_size must be an integer from 1 to 10^12, got 99999999999999999999999\n"
    assert not (tmp_path / "o.laz").exists()
    # a negative --top listed nothing and said nothing
    assert main(["segment", str(src), str(tmp_path / "o.laz"), "--top", "-1"]) == 2
    assert "--top is the number of segments listed, 0 or more; got -1" in capsys.readouterr().err
    assert not (tmp_path / "o.laz").exists()


def test_cli_picture(tmp_path):
    """--picture draws the segments: a PNG with real content next to the outputs."""
    import lidarfx
    from lidarfx.cli import main

    src = tmp_path / "plane.las"
    lidarfx.write(lidarfx.synth.plane(2.0, density=2000.0, noise=0.002, seed=1), src)
    png = tmp_path / "seg.png"
    assert main(["segment", str(src), str(tmp_path / "seg.las"), "--picture", str(png), "-q"]) == 0
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
