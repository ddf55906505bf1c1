"""Section projection: exactly the points of the slab (vertical and inclined cut planes, points on the
faces), s / h / d in closed form, the attributes in the output, features on the fly, the picture, the CLI."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx import PointCloud
from lidarfx.errors import LidarfxError
from lidarfx.section import read_near_section, section, section_frame, section_indices

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def _box(seed=0, n=20_000, lo=(-10.0, -10.0, 0.0), hi=(10.0, 10.0, 5.0), offset=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, (n, 3)) + np.asarray(offset)


def test_vertical_section_against_brute_force():
    off = np.array([500_000.0, 5_000_000.0, 300.0])
    xyz = _box(1, offset=off)
    a, b, w = off[:2] + (-6.0, -2.0), off[:2] + (5.0, 7.0), 0.8
    idx, s, h, d = section_indices(xyz, a, b, w)
    # brute force, point by point, in the plan-view formulas
    L = math.hypot(b[0] - a[0], b[1] - a[1])
    tx, ty = (b[0] - a[0]) / L, (b[1] - a[1]) / L
    want, ref = [], {}
    for i, (x, y, z) in enumerate(xyz.tolist()):
        ss = (x - a[0]) * tx + (y - a[1]) * ty
        dd = (x - a[0]) * ty - (y - a[1]) * tx  # > 0 on the right looking from a to b
        if abs(dd) <= w / 2 and 0 <= ss <= L:
            want.append(i)
            ref[i] = (ss, z, dd)
    assert idx.tolist() == want and len(want) > 300
    got = np.column_stack([s, h, d])
    assert np.allclose(got, [ref[i] for i in want], atol=1e-9, rtol=0)


def test_given_z_is_the_zero_of_h_and_right_is_positive():
    xyz = np.array([[5.0, -0.2, 12.0], [5.0, 0.2, 12.0]])
    idx, s, h, d = section_indices(xyz, (0.0, 0.0, 10.0), (10.0, 0.0), 1.0)
    assert idx.tolist() == [0, 1] and s.tolist() == [5.0, 5.0] and h.tolist() == [2.0, 2.0]
    assert d.tolist() == [0.2, -0.2]  # looking east, south (-y) is on the right


def test_faces_and_ends_are_kept():
    # section along +x from (0, 0) to (10, 0), width 1: d = -y, s = x, both exact in float64
    eps = 1e-9
    pts = {  # point: kept?
        (0.0, 0.5, 1.0): True, (0.0, -0.5, 1.0): True, (10.0, 0.5, 1.0): True, (10.0, -0.5, -3.0): True,
        (5.0, 0.5 + eps, 1.0): False, (5.0, -0.5 - eps, 1.0): False, (-eps, 0.0, 1.0): False,
        (10.0 + 1e-8, 0.0, 1.0): False, (5.0, 0.0, 1e6): True,  # no limit on h
    }
    xyz = np.array(list(pts))
    idx, *_ = section_indices(xyz, (0.0, 0.0), (10.0, 0.0), 1.0)
    assert idx.tolist() == [i for i, keep in enumerate(pts.values()) if keep]


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_inclined_section_recovers_local_coordinates(seed):
    """Points made in a known frame (s, h, d) come back with those coordinates."""
    rng = np.random.default_rng(seed)
    R = _rotation(rng)
    n = R[:, 2]
    e_s = R[:, 0]
    e_h = np.cross(n, e_s)
    if e_h[2] < 0:
        e_h = -e_h
    a = np.array([1000.0, 2000.0, 50.0]) + rng.normal(size=3)
    L, w = 12.0, 0.6
    local = rng.uniform([-2, -5, -1], [14, 5, 1], (30_000, 3))  # s, h, d
    xyz = a + local[:, :1] * e_s + local[:, 1:2] * e_h + local[:, 2:] * n
    b = a + L * e_s + 3.7 * n  # the end off the plane: only its projection counts
    idx, s, h, d = section_indices(xyz, a, b, w, normal=(2.0 * n).tolist())
    want = np.flatnonzero((np.abs(local[:, 2]) <= w / 2) & (local[:, 0] >= 0) & (local[:, 0] <= L))
    # points within 1e-9 of a face may fall either way in floating point
    edge = (np.abs(np.abs(local[:, 2]) - w / 2) < 1e-9) | (np.abs(local[:, 0]) < 1e-9) | (np.abs(local[:, 0] - L) < 1e-9)
    assert set(idx.tolist()) ^ set(want.tolist()) <= set(np.flatnonzero(edge).tolist())
    assert np.allclose(np.column_stack([s, h, d]), local[idx], atol=1e-8, rtol=0)
    fr = section_frame(a, b, w, normal=n)
    assert fr.length == pytest.approx(L, abs=1e-9) and fr.up[2] >= 0


def test_horizontal_cut_plane():
    xyz = _box(2, n=5000)
    idx, s, h, d = section_indices(xyz, (0.0, 0.0, 2.0), (3.0, 0.0), 0.2, normal=(0, 0, 1))
    want = np.flatnonzero((np.abs(xyz[:, 2] - 2.0) <= 0.1) & (xyz[:, 0] >= 0) & (xyz[:, 0] <= 3.0))
    assert idx.tolist() == want.tolist()
    assert np.allclose(s, xyz[idx, 0]) and np.allclose(d, xyz[idx, 2] - 2.0) and np.allclose(h, xyz[idx, 1])


def test_errors():
    with pytest.raises(LidarfxError, match="width must be a number"):
        section_frame((0, 0), (1, 0), 0)
    for bad in (-1, math.nan, math.inf):
        with pytest.raises(LidarfxError, match="width"):
            section_frame((0, 0), (1, 0), bad)
    with pytest.raises(LidarfxError, match="same point in plan view"):
        section_frame((1, 2, 0), (1, 2, 9), 0.2)
    with pytest.raises(LidarfxError, match="same point"):
        section_frame((1, 2, 3), (1, 2, 3), 0.2, normal=(1, 0, 0))
    with pytest.raises(LidarfxError, match="parallel"):
        section_frame((0, 0, 0), (2, 0, 0), 0.2, normal=(-3, 0, 0))
    with pytest.raises(LidarfxError, match="not be zero"):
        section_frame((0, 0, 0), (2, 0, 0), 0.2, normal=(0, 0, 0))
    with pytest.raises(LidarfxError, match="from needs x,y,z"):
        section_frame((0, 0), (2, 0), 0.2, normal=(0, 1, 0))
    with pytest.raises(LidarfxError, match="from must be 2 or 3 finite"):
        section_frame((0, math.nan), (2, 0), 0.2)


def test_section_cloud_keeps_attributes(tmp_path):
    xyz = _box(3, n=8000)
    cloud = PointCloud(xyz, {"intensity": np.arange(8000, dtype=np.uint16), "classification": np.full(8000, 6, np.uint8)})
    cut = section(cloud, (-5, -5), (5, 5), 0.5)
    idx, s, h, d = section_indices(xyz, (-5, -5), (5, 5), 0.5)
    assert np.array_equal(cut["intensity"], idx.astype(np.uint16)) and np.array_equal(cut["section_s"], s)
    assert np.array_equal(cut["section_h"], h) and np.array_equal(cut["section_d"], d)
    assert cut.meta["section"]["length"] == pytest.approx(math.sqrt(200))
    lidarfx.write(cut, tmp_path / "cut.laz")
    back = lidarfx.read(tmp_path / "cut.laz")
    for name in ("section_s", "section_h", "section_d"):
        assert back[name].dtype == np.float32 and np.allclose(back[name], cut[name], atol=1e-5)


def test_streamed_read_keeps_only_points_near_the_slab(tmp_path):
    xyz = _box(4, n=30_000, offset=(600_000.0, 4_000_000.0, 100.0))
    lidarfx.write(PointCloud(xyz, {"intensity": np.arange(30_000, dtype=np.uint16)}), tmp_path / "in.laz")
    full = lidarfx.read(tmp_path / "in.laz")
    fr = section_frame((600_000.0, 4_000_000.0), (600_008.0, 4_000_003.0), 0.4)
    near = read_near_section(tmp_path / "in.laz", fr, margin=0.5)
    p = full.xyz - fr.origin
    s, d = p @ fr.along, p @ fr.normal
    want = np.flatnonzero((np.abs(d) <= 0.7) & (s >= -0.5) & (s <= fr.length + 0.5))
    assert np.array_equal(near["intensity"], full["intensity"][want]) and np.array_equal(near.xyz, full.xyz[want])


# ----------------------------------------------------------------------------- CLI
def _one_line_error(rc, err, match):
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("lidarfx")]
    assert rc == 2 and lines and match in lines[-1], err
    assert "Traceback" not in err


@pytest.fixture
def scene(tmp_path):
    """A synthetic lattice tower (TLS-like) as LAZ."""
    cloud = lidarfx.synth.tower(density=300.0, seed=1)
    path = tmp_path / "tower.laz"
    lidarfx.write(cloud, path)
    return path


def test_cli_section_and_picture(tmp_path, scene, run_cli):
    out, png = tmp_path / "cut.laz", tmp_path / "cut.png"
    rc, so, err = run_cli(["section", str(scene), str(out), "--from", "-4,0", "--to", "4,0", "--width", "0.3",
                           "--image", str(png), "--by", "z", "--json"])
    assert rc == 0, err
    s = json.loads(so)
    full = lidarfx.read(scene)
    idx, *_ = section_indices(full.xyz, (-4, 0), (4, 0), 0.3)
    got = lidarfx.read(out)
    assert s["points"] == len(idx) == len(got) and np.allclose(got.xyz, full.xyz[idx])
    assert np.array_equal(got["member_id"], full["member_id"][idx]) and "section_s" in got
    from PIL import Image

    im = Image.open(png)
    assert im.size[1] > 1000 and 400 < im.size[0] < im.size[1]  # a tall section: a tall picture
    rc, so, err = run_cli(["section", str(scene), str(tmp_path / "c.laz"), "--from", "-4,0", "--to", "4,0",
                           "--width", "0.3", "--image", str(tmp_path / "cls.png"), "--by", "classification", "-q"])
    assert rc == 0 and so == "" and err == "", err


def test_cli_feature_on_the_fly_equals_whole_cloud(tmp_path, scene, run_cli):
    """--by a feature the file lacks: computed with neighbours from the whole cloud near the slab."""
    out = tmp_path / "cut.npz"
    rc, _, err = run_cli(["section", str(scene), str(out), "--from", "-3,-0.5", "--to", "3,-0.5", "--width", "0.4",
                          "--image", str(tmp_path / "p.png"), "--by", "plane_std", "-r", "0.15",
                          "--features", "eigenvalue1", "-q"])
    assert rc == 0, err
    full = lidarfx.read(scene)
    ref = lidarfx.compute_features(full, ["plane_std", "eigenvalue1"], radius=0.15)
    idx, *_ = section_indices(full.xyz, (-3, -0.5), (3, -0.5), 0.4)
    got = lidarfx.read(out)
    for name in ("plane_std", "eigenvalue1"):
        assert np.allclose(got[name], ref[name][idx], equal_nan=True, rtol=1e-5, atol=1e-7)


def test_cli_help_has_examples(run_cli):
    rc, out, _ = run_cli(["section", "--help"])
    assert rc == 0 and "examples:" in out and "--normal" in out


def test_cli_negative_coordinates(tmp_path, scene, run_cli):
    rc, so, err = run_cli(["section", str(scene), str(tmp_path / "c.laz"), "--from", "-1,-3,10", "--to", "-1,3,10",
                           "--normal", "-1,0,0", "--width", "0.4", "--json"])
    assert rc == 0, err
    assert json.loads(so)["frame"]["normal"] == [-1.0, 0.0, 0.0]


@pytest.mark.parametrize("extra, match", [
    (["--width", "0"], "width must be a number"),
    (["--width", "nan"], "width must be a number"),
    (["--width", "-1"], "width must be a number"),
    (["--width", "0.2", "--from", "4,0,3"], "same point in plan view"),
    (["--width", "0.2", "--normal", "1,0,0", "--from", "0,0,5"], "parallel"),
    (["--width", "0.2", "--image", "cut.jpg"], "pictures are PNG files"),
    (["--width", "0.2", "--image", "p.png", "--by", "nothing_like_this"], "no such attribute"),
    (["--width", "0.2", "--image", "p.png", "--by", "planarity"], "give -r RADIUS"),
    (["--width", "0.2", "--features", "eigen"], "--features needs -r"),
    (["--width", "0.2", "--from", "100,100", "--to", "110,100"], "no point lies in the section"),
    (["--width", "0.2", "--from", "1,x"], "a position x,y[,z]"),
])
def test_cli_bad_options(tmp_path, scene, run_cli, extra, match, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["section", str(scene), "o.laz", "--from", "-4,0", "--to", "4,0", *extra]
    rc, _, err = run_cli(args)
    if "a position" in match:
        assert rc == 2 and match in err
    else:
        _one_line_error(rc, err, match)
    assert not (tmp_path / "o.laz").exists() and not (tmp_path / "p.png").exists()


def test_cli_bad_files(tmp_path, scene, run_cli):
    base = ["--from", "-4,0", "--to", "4,0", "--width", "0.2"]
    rc, _, err = run_cli(["section", str(tmp_path / "missing.laz"), str(tmp_path / "o.laz"), *base])
    _one_line_error(rc, err, "file not found")
    rc, _, err = run_cli(["section", str(scene), str(scene), *base])
    _one_line_error(rc, err, "is the input file")
    rc, _, err = run_cli(["section", str(scene), str(tmp_path / "o.laz"), *base, "--image", str(tmp_path / "nofolder" / "p.png")])
    _one_line_error(rc, err, "output folder does not exist")
    data = scene.read_bytes()
    (tmp_path / "trunc.laz").write_bytes(data[: len(data) // 2])
    rc, _, err = run_cli(["section", str(tmp_path / "trunc.laz"), str(tmp_path / "o.laz"), *base])
    _one_line_error(rc, err, "trunc.laz")
    assert not (tmp_path / "o.laz").exists()


@pytest.mark.skipif(not (REAL / "lone-star.laz").exists(), reason=f"real TLS scan not found: {REAL / 'lone-star.laz'}")
def test_real_tls_scan(tmp_path, run_cli):
    src = REAL / "lone-star.laz"
    a, b = (515371.0, 4918346.0), (515400.0, 4918378.0)
    rc, so, err = run_cli(["section", str(src), str(tmp_path / "cut.laz"), "--from", ",".join(map(str, a)),
                           "--to", ",".join(map(str, b)), "--width", "0.4", "--image", str(tmp_path / "cut.png"),
                           "--by", "intensity", "--json"])
    assert rc == 0, err
    full = lidarfx.read(src)
    idx, *_ = section_indices(full.xyz, a, b, 0.4)
    assert json.loads(so)["points"] == len(idx) > 5000
    got = lidarfx.read(tmp_path / "cut.laz")
    assert np.array_equal(got["gps_time"], full["gps_time"][idx])
    assert lidarfx.io.info(tmp_path / "cut.laz")["crs"] == lidarfx.io.info(src)["crs"]
