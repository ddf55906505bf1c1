"""``lidarfx.colour`` and ``lidarfx colour``: morphology HSV, attribute / set / class colours, pictures."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import hsv_to_rgb, rgb_to_hsv, to_rgb

import lidarfx
from lidarfx.neighbors import default_radius
from lidarfx import synth
from lidarfx.cli import main
from lidarfx.cloud import PointCloud
from lidarfx.colour import (
    NO_VALUE,
    class_colour,
    colour_cloud,
    colour_picture,
    morphology_hsv,
    morphology_rgb,
    to_uint16,
)
from lidarfx.errors import LidarfxError
from lidarfx.render import CLASS_COLOURS, NOT_CLASSIFIED
from lidarfx.render.palette import NO_SET, set_colour

SRC = Path(__file__).resolve().parents[1] / "src"
S45 = math.sin(math.radians(45.0))


def normal_of(dip: float, dip_direction: float) -> np.ndarray:
    """Upward unit normal of a plane dipping ``dip`` towards ``dip_direction`` (x East, y North)."""
    d, a = math.radians(dip), math.radians(dip_direction)
    return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])


def rgb_of(cloud: PointCloud) -> np.ndarray:
    return np.column_stack([cloud["red"], cloud["green"], cloud["blue"]])


def plane_cloud(dip: float, dip_direction: float, *, n: int = 6000, size: float = 8.0, seed: int = 0,
                noise: float = 0.0) -> PointCloud:
    rng = np.random.default_rng(seed)
    nv = normal_of(dip, dip_direction)
    xy = rng.uniform(0.0, size, (n, 2))
    z = -(nv[0] * xy[:, 0] + nv[1] * xy[:, 1]) / nv[2] + rng.normal(0.0, noise, n)
    return PointCloud(np.column_stack([xy + [1000.0, 2000.0], z + 300.0]))


def circular_diff(a, b):
    """a − b on the unit circle of hues, in −0.5 .. 0.5."""
    return (np.asarray(a) - b + 0.5) % 1.0 - 0.5


# --------------------------------------------------------------------------- closed forms
def test_plane_dipping_30_towards_east_closed_form():
    n = normal_of(30.0, 90.0)
    hsv = morphology_hsv(np.array([n, -n]))  # -n: flipped up first, same colour
    sun = np.array([S45 * math.sin(math.radians(315)), S45 * math.cos(math.radians(315)), S45])
    by_hand = -0.5 * 0.5 + math.cos(math.radians(30.0)) * S45  # n = (1/2, 0, cos 30°), L = (−1/2, 1/2, sin 45°)
    assert by_hand == pytest.approx(float(n @ sun), abs=1e-12)
    for row in hsv:
        assert row[0] == pytest.approx(0.25, abs=1e-12)
        assert row[1] == pytest.approx(1.0 / 3.0, abs=1e-12)
        assert row[2] == pytest.approx(by_hand, abs=1e-12)
    np.testing.assert_allclose(morphology_rgb(np.array([n])), hsv_to_rgb(hsv[:1]), atol=1e-12)


def test_horizontal_plane_and_plane_facing_the_sun():
    hsv = morphology_hsv(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -2.0]]))  # any length, either sign
    np.testing.assert_allclose(hsv[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(hsv[:, 2], S45, atol=1e-12)
    facing = morphology_hsv(normal_of(45.0, 315.0)[None])[0]
    assert facing[2] == pytest.approx(1.0, abs=1e-12)
    assert facing[0] == pytest.approx(315.0 / 360.0, abs=1e-12) and facing[1] == pytest.approx(0.5, abs=1e-12)
    # the same plane lit from the opposite side: n·L = 0; a vertical face turned away is clipped to 0
    assert morphology_hsv(normal_of(45.0, 315.0)[None], sun_azimuth=135.0)[0, 2] == pytest.approx(0.0, abs=1e-12)
    assert morphology_hsv(normal_of(90.0, 135.0)[None])[0, 2] == 0.0
    # a lower sun: the horizontal plane gets sin(altitude)
    assert morphology_hsv(np.array([[0.0, 0.0, 1.0]]), sun_altitude=20.0)[0, 2] == pytest.approx(
        math.sin(math.radians(20.0)), abs=1e-12)


@pytest.mark.parametrize("dip_direction", [0.0, 45.0, 90.0, 180.0, 270.0, 359.0])
def test_aspect_clockwise_from_north(dip_direction):
    hsv = morphology_hsv(normal_of(60.0, dip_direction)[None])
    assert hsv[0, 0] == pytest.approx(dip_direction / 360.0, abs=1e-12)
    assert hsv[0, 1] == pytest.approx(60.0 / 90.0, abs=1e-12)


def test_sun_azimuth_is_taken_mod_360_and_bad_suns_refused():
    normals = np.array([normal_of(d, a) for d, a in ((10, 20), (40, 200), (80, 300))])
    ref = morphology_hsv(normals, sun_azimuth=315.0)
    np.testing.assert_allclose(morphology_hsv(normals, sun_azimuth=-45.0), ref, atol=1e-12)
    np.testing.assert_allclose(morphology_hsv(normals, sun_azimuth=675.0), ref, atol=1e-12)
    for az, alt in ((float("nan"), 45.0), (315.0, 120.0), (315.0, -1.0), (float("inf"), 10.0)):
        with pytest.raises(LidarfxError, match="sun"):
            morphology_hsv(normals, sun_azimuth=az, sun_altitude=alt)


def test_nan_and_zero_normals_are_black():
    normals = np.array([[np.nan, np.nan, np.nan], [0.0, 0.0, 0.0], [0.1, np.nan, 0.9], normal_of(30.0, 90.0)])
    hsv = morphology_hsv(normals)
    np.testing.assert_array_equal(hsv[:3], 0.0)
    assert hsv[3, 1] == pytest.approx(1 / 3)
    rgb = morphology_rgb(normals)
    np.testing.assert_array_equal(rgb[:3], 0.0)
    assert rgb[3].max() > 0.2
    # through the cloud: attributes with NaN normals -> RGB 0, counted in meta
    cloud = PointCloud(np.arange(12.0).reshape(4, 3), {"normal_x": normals[:, 0], "normal_y": normals[:, 1],
                                                       "normal_z": normals[:, 2]})
    out = colour_cloud(cloud)
    assert out.meta["colour"]["normals"] == "attributes" and out.meta["colour"]["no_normal"] == 3
    np.testing.assert_array_equal(rgb_of(out)[:3], 0)
    np.testing.assert_array_equal(rgb_of(out), to_uint16(rgb))


def test_to_uint16_rounds_to_65535():
    np.testing.assert_array_equal(to_uint16([[0.0, 0.5, 1.0], [1.2, -0.1, np.nan]]), [[0, 32768, 65535], [65535, 0, 0]])
    assert to_uint16([[0.0, 0.5, 1.0]]).dtype == np.uint16


# --------------------------------------------------------------------------- colour_cloud
def test_normals_from_attributes_are_used_as_they_are():
    cloud = plane_cloud(30.0, 90.0, n=50)  # the attributes say otherwise: a plane dipping 70° to 200°
    nv = normal_of(70.0, 200.0)
    for k, name in enumerate(("normal_x", "normal_y", "normal_z")):
        cloud[name] = np.full(len(cloud), -nv[k], dtype=np.float32)  # pointing down: flipped up
    out = colour_cloud(cloud)
    expect = to_uint16(morphology_rgb(np.tile(-nv.astype(np.float32), (len(cloud), 1))))
    np.testing.assert_array_equal(rgb_of(out), expect)
    assert out["red"].dtype == np.uint16 and "red" not in cloud  # a copy: the input is not changed
    assert out.meta["colour"]["radius"] is None


def test_computed_normals_on_a_plane_and_the_auto_radius():
    cloud = plane_cloud(30.0, 90.0, n=8000, size=8.0, noise=0.002)
    out = colour_cloud(cloud)
    meta = out.meta["colour"]
    assert meta["normals"] == "computed" and meta["radius_source"] == "auto"
    assert meta["radius"] == pytest.approx(default_radius(cloud))
    hsv = rgb_to_hsv(rgb_of(out) / 65535.0)
    assert np.median(np.abs(circular_diff(hsv[:, 0], 0.25))) < 0.003
    assert np.median(hsv[:, 1]) == pytest.approx(1 / 3, abs=0.005)
    assert np.median(hsv[:, 2]) == pytest.approx(-0.25 + math.cos(math.radians(30)) * S45, abs=0.005)
    given = colour_cloud(cloud, radius=0.5)
    assert given.meta["colour"]["radius"] == 0.5 and given.meta["colour"]["radius_source"] == "given"


def test_attribute_colours_percentiles_to_the_ends():
    from matplotlib import colormaps

    v = np.r_[np.linspace(0.0, 100.0, 1001), np.nan]  # 2nd / 98th percentile: 2 and 98, values of points
    cloud = PointCloud(np.column_stack([v * 0, v * 0, np.arange(1002.0)]), {"height": v})
    lo, hi = np.percentile(v[np.isfinite(v)], [2, 98])
    assert (lo, hi) == pytest.approx((2.0, 98.0))
    out = colour_cloud(cloud, "height", cmap="plasma")
    meta = out.meta["colour"]
    assert meta["range"] == pytest.approx([lo, hi]) and meta["cmap"] == "plasma" and meta["no_value"] == 1
    cm = colormaps["plasma"]
    rgb = rgb_of(out)
    i_lo, i_hi = int(np.nanargmin(np.abs(v - lo))), int(np.nanargmin(np.abs(v - hi)))
    assert v[i_lo] == pytest.approx(lo) and v[i_hi] == pytest.approx(hi)
    np.testing.assert_array_equal(rgb[i_lo], to_uint16(np.array(cm(0.0))[None, :3])[0])
    np.testing.assert_array_equal(rgb[i_hi], to_uint16(np.array(cm(1.0))[None, :3])[0])
    np.testing.assert_array_equal(rgb[0], rgb[i_lo])       # below the range: clipped to the first colour
    np.testing.assert_array_equal(rgb[1000], rgb[i_hi])    # above: the last
    np.testing.assert_array_equal(rgb[1001], to_uint16(np.array([NO_VALUE]))[0])
    assert not np.array_equal(rgb[250], rgb[i_lo]) and not np.array_equal(rgb[250], rgb[i_hi])
    # a given range, and the coordinates by name
    fixed = colour_cloud(cloud, "z", value_range=(0.0, 1000.0))
    assert fixed.meta["colour"]["range"] == [0.0, 1000.0]
    np.testing.assert_array_equal(rgb_of(fixed)[0], to_uint16(np.array(colormaps["viridis"](0.0))[None, :3])[0])
    np.testing.assert_array_equal(rgb_of(fixed)[1000], to_uint16(np.array(colormaps["viridis"](1.0))[None, :3])[0])


def test_set_colours_use_the_palette_and_grey_for_no_set():
    ids = np.array([-1, 0, 1, 2, 11, 0, -3], dtype=np.int32)
    cloud = PointCloud(np.zeros((len(ids), 3)), {"set_id": ids})
    out = colour_cloud(cloud, "set")
    expect = np.array([NO_SET if i < 0 else set_colour(int(i)) for i in ids])
    np.testing.assert_array_equal(rgb_of(out), to_uint16(expect))
    assert rgb_of(out)[0].tolist() == [round(0.62 * 65535)] * 3
    assert not np.array_equal(rgb_of(out)[1], rgb_of(out)[2])
    sets = {s["id"]: s["points"] for s in out.meta["colour"]["sets"]}
    assert sets == {-1: 2, 0: 2, 1: 1, 2: 1, 11: 1}


def test_class_colours_by_asprs_name():
    from matplotlib import colormaps

    codes = np.array([2, 3, 4, 5, 6, 9, 14, 15, 1, 0, 11, 66], dtype=np.uint8)
    cloud = PointCloud(np.zeros((len(codes), 3)), {"classification": codes})
    rgb = rgb_of(colour_cloud(cloud, "class"))
    want = {2: CLASS_COLOURS["ground"], 3: CLASS_COLOURS["vegetation"], 4: CLASS_COLOURS["vegetation"],
            5: CLASS_COLOURS["vegetation"], 6: CLASS_COLOURS["building"], 9: CLASS_COLOURS["water"],
            14: CLASS_COLOURS["wire"], 15: CLASS_COLOURS["pole"], 1: NOT_CLASSIFIED, 0: NOT_CLASSIFIED,
            11: colormaps["tab10"](1), 66: colormaps["tab10"](6)}
    for code, row in zip(codes, rgb):
        np.testing.assert_array_equal(row, to_uint16(np.array([to_rgb(want[int(code)])]))[0], err_msg=str(code))
    assert class_colour(2) == to_rgb(CLASS_COLOURS["ground"])


@pytest.mark.parametrize("by, match", [
    ("intensity", "no attribute 'intensity'.*x, y, z, joint_set"),
    ("set", "set_id.*joint_set"),
    ("class", "classification.*joint_set"),
    ("", "morphology, set, class"),
])
def test_missing_attribute_errors_name_what_exists(by, match):
    cloud = PointCloud(np.zeros((3, 3)), {"joint_set": np.zeros(3, dtype=np.int16)})
    with pytest.raises(LidarfxError, match=match):
        colour_cloud(cloud, by)


def test_other_refusals():
    with pytest.raises(LidarfxError, match="no points"):
        colour_cloud(PointCloud(np.empty((0, 3))))
    cloud = PointCloud(np.zeros((3, 3)), {"v": np.arange(3.0)})
    with pytest.raises(LidarfxError, match="unknown colour map 'nope'"):
        colour_cloud(cloud, "v", cmap="nope")
    with pytest.raises(LidarfxError, match="lo < hi"):
        colour_cloud(cloud, "v", value_range=(2.0, 1.0))
    with pytest.raises(LidarfxError, match="radius"):
        colour_cloud(cloud, radius=-1.0)
    with pytest.raises(LidarfxError, match="sun altitude"):
        colour_cloud(cloud, sun_altitude=120.0)


def test_rockface_joint_sets_get_their_orientation():
    cloud = synth.rockface(density=200, seed=1)
    sets = cloud.meta["truth"]["sets"]
    # a sun from SSW lights all three sets (n·L > 0.3), so the hue is readable back from the RGB
    out = colour_cloud(cloud, sun_azimuth=200.0, sun_altitude=50.0)
    meta = out.meta["colour"]
    assert meta["normals"] == "computed" and 0.10 <= meta["radius"] < 0.5
    hsv = rgb_to_hsv(rgb_of(out) / 65535.0)
    js = np.asarray(cloud["joint_set"])
    for s in sets:
        m = js == s["id"]
        assert m.sum() > 1000
        assert abs(float(np.median(circular_diff(hsv[m, 0], s["dip_direction"] / 360.0)))) < 0.02, s
        assert float(np.median(hsv[m, 1])) == pytest.approx(s["dip"] / 90.0, abs=0.03), s
        assert float(np.median(hsv[m, 2])) == pytest.approx(
            max(0.0, float(np.array(s["normal"]) @ np.array(
                [math.cos(math.radians(50)) * math.sin(math.radians(200)),
                 math.cos(math.radians(50)) * math.cos(math.radians(200)), math.sin(math.radians(50))]))), abs=0.03)
    # the default sun (NW) leaves the SSE main face in shadow: value 0, black
    default = colour_cloud(cloud)
    main_face = js == 0
    assert np.median(rgb_of(default)[main_face].max(axis=1)) == 0


# --------------------------------------------------------------------------- pictures
def test_picture_views_and_zbuffer(tmp_path):
    from lidarfx.colour import _projection, zbuffer

    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 50, (4000, 2))
    flat = np.column_stack([xy, rng.normal(0, 0.2, 4000)])
    assert _projection(flat, "auto")["view"] == "top"
    face = synth.rockface(density=20, seed=1)
    pr = _projection(face.xyz - face.xyz.min(axis=0), "auto")
    assert pr["view"] == "elevation" and abs(circular_diff(pr["look_azimuth"] / 360.0, 350.0 / 360.0)) < 15 / 360
    # two layers over the same ground: seen from the top, only the upper one
    both = np.vstack([np.column_stack([xy, np.zeros(4000)]), np.column_stack([xy, np.ones(4000)])])
    colours = np.vstack([np.tile([1.0, 0.0, 0.0], (4000, 1)), np.tile([0.0, 0.0, 1.0], (4000, 1))])
    for view, top_colour in (("top", [0.0, 0.0, 1.0]),):
        pr = _projection(both, view)
        img, cell, nu, nv, u0, v0 = zbuffer(pr["u"], pr["v"], pr["near"], colours, 300)
        painted = img.reshape(-1, 3)[~np.all(img.reshape(-1, 3) == 1.0, axis=1)]
        assert len(painted) > 0.9 * nu * nv  # the discs leave (almost) no holes
        np.testing.assert_array_equal(np.unique(painted, axis=0), [top_colour])
    # front (from the South): the nearest is the smallest y
    xz = np.column_stack([rng.uniform(0, 10, 1000), rng.uniform(0, 5, 1000)])
    wall = np.vstack([np.column_stack([xz[:, 0], np.full(1000, 1.0), xz[:, 1]]),    # behind: blue
                      np.column_stack([xz[:, 0], np.zeros(1000), xz[:, 1]])])      # in front: red
    pr = _projection(wall, "front")
    wall_colours = np.vstack([np.tile([0.0, 0.0, 1.0], (1000, 1)), np.tile([1.0, 0.0, 0.0], (1000, 1))])
    img, *_ = zbuffer(pr["u"], pr["v"], pr["near"], wall_colours, 200)
    painted = img.reshape(-1, 3)[~np.all(img.reshape(-1, 3) == 1.0, axis=1)]
    np.testing.assert_array_equal(np.unique(painted, axis=0), [[1.0, 0.0, 0.0]])  # y = 0 rows are red
    # the PNG itself
    out = colour_cloud(face, sun_azimuth=200.0, sun_altitude=50.0)
    path = colour_picture(out, rgb_of(out), tmp_path / "face.png", title="rock face")
    from matplotlib.image import imread

    png = imread(path)
    assert png.shape[1] > 1000 and path.stat().st_size > 20_000
    with pytest.raises(LidarfxError, match="view"):
        colour_picture(out, rgb_of(out), tmp_path / "x.png", view="bottom")


# --------------------------------------------------------------------------- command line
@pytest.fixture()
def plane_laz(tmp_path):
    path = tmp_path / "plane.laz"
    cloud = plane_cloud(30.0, 90.0, n=5000, size=7.0, noise=0.003)
    cloud["classification"] = np.where(np.arange(len(cloud)) % 3 == 0, 2, 6).astype(np.uint8)
    lidarfx.write(cloud, path)
    return path


def test_cli_las_round_trip(plane_laz, tmp_path, capsys):
    out = tmp_path / "rgb.laz"
    pic = tmp_path / "rgb.png"
    assert main(["colour", str(plane_laz), str(out), "--picture", str(pic), "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == 5000 and summary["colour"]["by"] == "morphology"
    back = lidarfx.read(out)
    ref = colour_cloud(lidarfx.read(plane_laz))
    assert summary["colour"]["radius"] == pytest.approx(ref.meta["colour"]["radius"])
    for name in ("red", "green", "blue"):
        assert back[name].dtype == np.uint16
        np.testing.assert_array_equal(back[name], ref[name])
    np.testing.assert_array_equal(back["classification"], lidarfx.read(plane_laz)["classification"])
    assert pic.stat().st_size > 10_000
    # by class, with a given sun and the text summary on stderr
    out2 = tmp_path / "cls.laz"
    assert main(["colour", str(plane_laz), str(out2), "--by", "class"]) == 0
    err = capsys.readouterr().err
    assert "coloured by class" in err and "ground" in err
    back = lidarfx.read(out2)
    ground = np.asarray(back["classification"]) == 2
    np.testing.assert_array_equal(rgb_of(back)[ground], np.tile(to_uint16(np.array([to_rgb(CLASS_COLOURS["ground"])])),
                                                                 (int(ground.sum()), 1)))
    # by an attribute with a negative range bound
    out3 = tmp_path / "z.laz"
    assert main(["colour", str(plane_laz), str(out3), "--by", "z", "--range", "-5,310", "--cmap", "magma", "--json",
                 "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["colour"]["range"] == [-5.0, 310.0]


@pytest.mark.parametrize("argv, match", [
    (["--by", "planarity"], "no attribute 'planarity'"),
    (["--cmap", "nope"], "unknown colour map"),
    (["--sun-altitude", "120"], "sun altitude"),
    (["--sun-azimuth", "nan"], "sun azimuth"),
    (["--range", "5,1"], "lo < hi"),
    (["--range", "5"], "--range"),
    (["-r", "0"], "radius"),
    (["--picture", "x.jpg"], "PNG"),
    (["--by", "set"], "set_id"),
])
def test_cli_refusals_one_line(plane_laz, tmp_path, capsys, argv, match):
    out = tmp_path / "o.laz"
    assert main(["colour", str(plane_laz), str(out), *argv, "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lidarfx: error:") and err.count("\n") == 1 and match in err, err
    assert not out.exists()


def test_cli_checks_options_before_reading(tmp_path, capsys):
    missing = tmp_path / "missing.laz"
    assert main(["colour", str(missing), str(tmp_path / "o.laz"), "--cmap", "nope"]) == 2
    assert "unknown colour map" in capsys.readouterr().err  # not "file not found": the option came first
    assert main(["colour", str(missing), str(tmp_path / "o.laz")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not found" in err and "missing.laz" in err
    assert main(["colour", str(missing), str(tmp_path / "o.unknown")]) == 2
    assert capsys.readouterr().err.startswith("lidarfx: error:")


def test_cli_refuses_to_overwrite_the_input(plane_laz, capsys):
    before = plane_laz.read_bytes()
    assert main(["colour", str(plane_laz), str(plane_laz), "-q"]) == 2
    assert "input" in capsys.readouterr().err and plane_laz.read_bytes() == before


def test_cli_subprocess_exit_code(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "lidarfx", "colour", str(tmp_path / "none.laz"),
                           str(tmp_path / "o.laz"), "--by", "morphology", "--sun-altitude", "120"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("lidarfx: error: sun altitude")
    proc = subprocess.run([sys.executable, "-m", "lidarfx", "colour", "--help"], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 0 and "--sun-azimuth" in proc.stdout and "hue        = aspect / 360" in proc.stdout
