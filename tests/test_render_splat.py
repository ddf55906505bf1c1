"""``lidarfx.render.splat`` and ``lidarfx render``: z-buffered splats, eye-dome lighting, pictures."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import lidarfx
from lidarfx import LidarfxError, PointCloud
from lidarfx.cli import main
from lidarfx.render.splat import (
    eye_dome,
    fit_frame,
    parse_size,
    render_picture,
    render_points,
    scale_bar_length,
    splat,
)

RED, BLUE = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)


def _sheet(rng, n, fixed_axis, value, lo=0.0, hi=10.0):
    """n random points of a square sheet with coordinate ``fixed_axis`` = ``value``."""
    xyz = rng.uniform(lo, hi, (n, 3))
    xyz[:, fixed_axis] = value
    return xyz


def _shown_colours(img):
    return np.unique(img.rgb[img.index >= 0].reshape(-1, 3), axis=0)


# --------------------------------------------------------------------------- the z-buffer
@pytest.mark.parametrize("view, axis, near_value, far_value", [
    ("top", 2, 1.0, 0.0),     # the highest point wins
    ("front", 1, 0.0, 1.0),   # seen from the South: the smallest y wins
    ("side", 0, 1.0, 0.0),    # seen from the East: the largest x wins
])
def test_the_nearer_sheet_hides_the_farther_one(view, axis, near_value, far_value):
    rng = np.random.default_rng(0)
    g = np.arange(-1.0, 11.0001, 0.1)  # the nearer sheet: a 0.1 m grid, wider than the farther one
    a, b = (m.ravel() for m in np.meshgrid(g, g))
    near = np.zeros((len(a), 3))
    near[:, [i for i in range(3) if i != axis]] = np.column_stack([a, b])
    near[:, axis] = near_value
    far = _sheet(rng, 3000, axis, far_value)
    xyz = np.vstack([far, near])
    colours = np.vstack([np.tile(BLUE, (3000, 1)), np.tile(RED, (len(near), 1))])
    forward = np.arange(len(xyz))
    for order in (forward, forward[::-1]):  # the answer does not depend on the order
        # 12 m on 150 pixels: the grid is 1.25 pixels apart, discs of 2 pixels leave no hole
        img = render_points(xyz[order], colours[order], view=view, size=(200, 150), shading="none", point_size=2)
        assert img.covered > 0.7  # the square fills 150 x 150 of 200 x 150 pixels, without holes
        np.testing.assert_array_equal(_shown_colours(img), [[255, 0, 0]])
        shown = img.index >= 0
        np.testing.assert_allclose(img.depth[shown], near_value)
        assert np.all(np.isnan(img.depth[~shown]))
        assert np.all(img.rgb[~shown] == 255)  # white background


def test_a_point_lands_on_its_pixel_and_the_data_keep_their_aspect():
    rng = np.random.default_rng(1)
    xyz = np.column_stack([rng.uniform(500_000, 500_040, 2000), rng.uniform(6e6, 6e6 + 10, 2000),
                           rng.uniform(0, 1, 2000)])
    probe = np.array([[500_012.34, 6e6 + 7.89, 5.0]])  # above the others: nothing hides it
    xyz = np.vstack([xyz, probe])
    img = render_points(xyz, None, view="top", size=(400, 300), point_size=0, shading="none")
    f = img.frame
    # 40 m x 10 m into 400 x 300: the width sets the scale (0.1 m per pixel), centred vertically
    assert f.cell == pytest.approx(np.ptp(xyz[:, 0]) / 400, rel=1e-6)
    assert f.left == pytest.approx(xyz[:, 0].min(), abs=1e-6)
    assert f.top - 150 * f.cell == pytest.approx((xyz[:, 1].min() + xyz[:, 1].max()) / 2, abs=1e-6)
    col = math.floor((probe[0, 0] - f.left) / f.cell)
    row = math.floor((f.top - probe[0, 1]) / f.cell)
    assert img.index[row, col] == len(xyz) - 1
    assert img.depth[row, col] == 5.0
    r, c = f.pixel(probe)
    assert (int(r[0]), int(c[0])) == (row, col)
    # only the middle band holds points; the rest is padding
    rows = np.flatnonzero((img.index >= 0).any(axis=1))
    assert 95 <= rows.min() <= 105 and 195 <= rows.max() <= 205


def test_splat_discs_and_ties():
    from lidarfx.render.splat import Frame

    frame = Frame(9, 9, 0.0, 0.0, 1.0)
    u, v, near = np.array([4.5, 4.5]), np.array([4.5, 4.5]), np.array([1.0, 1.0])
    win, _ = splat(u, v, near, frame, 2.0)
    assert (win >= 0).sum() == 13  # a disc of radius 2 pixels: 13 pixels
    assert np.all(win[win >= 0] == 1)  # a tie goes to the later point
    win, _ = splat(u, v, near, frame, 0.0)
    assert (win >= 0).sum() == 1 and win[4, 4] == 1


def test_a_top_view_of_a_north_rising_plane_is_high_at_the_top():
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 20, (20_000, 2))
    z = 0.5 * xy[:, 1]  # rises towards North
    cloud = PointCloud(np.column_stack([xy, z]))
    from lidarfx.colour import by_attribute

    rgb, _ = by_attribute(cloud, "z", "viridis", None)
    img = render_points(cloud.xyz, rgb, view="top", size=(200, 200), shading="none")
    shown = img.index >= 0
    assert shown.mean() > 0.97
    rows = np.nanmean(np.where(shown, z[np.maximum(img.index, 0)], np.nan), axis=1)
    assert np.all(np.diff(rows[2:-2]) < 0)  # row 0 is North: z falls down the picture
    top, bottom = img.rgb[5, 100].astype(float), img.rgb[-5, 100].astype(float)
    assert top[0] + top[1] > bottom[0] + bottom[1] + 200  # viridis: yellow (high) at the top, purple below


# --------------------------------------------------------------------------- shading
def test_eye_dome_lighting_darkens_the_far_side_of_a_step_only():
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 20, (40_000, 2))
    z = np.where(xy[:, 0] >= 10.0, 2.0, 0.0)  # a 2 m step at x = 10 m; the low side is farther from above
    img = render_points(np.column_stack([xy, z]), None, view="top", size=(200, 200), shading="edl")
    rows = slice(20, -20)
    high = img.depth[rows] == 2.0
    low = img.depth[rows] == 0.0
    assert np.all(img.shade[rows][high] == 1.0)  # nothing nearer beside the high side: unshaded
    edge = high.argmax(axis=1)  # first high pixel of every row, the step
    cols = np.arange(img.shade.shape[1])[None, :]
    far_low = low & (cols < edge[:, None] - 4) & (cols > 20)
    assert far_low.sum() > 1000 and np.all(img.shade[rows][far_low] == 1.0)  # flat low ground: unshaded
    beside = img.shade[rows][np.arange(len(edge)), edge - 1]  # the last low pixel of every row
    beside = beside[img.depth[rows][np.arange(len(edge)), edge - 1] == 0.0]  # (a rare pixel is a hole)
    assert len(beside) > 150 and np.median(beside) < 0.3
    grey = img.rgb[rows][far_low][:, 0]
    assert np.median(img.rgb[rows][np.arange(len(edge)), edge - 1, 0]) < 0.3 * grey.min()
    # a plane facing the viewer has no shading at all; an empty buffer neither
    np.testing.assert_array_equal(eye_dome(np.zeros((50, 60)), 0.1), 1.0)
    np.testing.assert_array_equal(eye_dome(np.full((5, 5), np.nan), 0.1), 1.0)


def test_hillshade_keeps_flat_ground_and_lights_the_slope_facing_the_sun():
    rng = np.random.default_rng(4)
    xy = rng.uniform(-10, 10, (40_000, 2))
    z = np.where(xy[:, 0] < 0, 0.0, -xy[:, 0])  # flat West half, East half falling East (faces away from a NW sun)
    img = render_points(np.column_stack([xy, z]), None, view="top", size=(200, 200), shading="hillshade")
    w = img.shade.shape[1]
    assert np.median(img.shade[20:-20, 20:w // 2 - 10]) == pytest.approx(1.0, abs=1e-3)
    assert np.median(img.shade[20:-20, w // 2 + 10:-20]) < 0.6


# --------------------------------------------------------------------------- pictures
def _classified(rng, n=6000):
    xyz = rng.uniform(0, 30, (n, 3))
    xyz[:, 2] *= 0.1
    cls = np.where(xyz[:, 0] < 10, 2, np.where(xyz[:, 0] < 20, 6, 9)).astype(np.uint8)
    return PointCloud(xyz, {"classification": cls, "intensity": rng.uniform(0, 1000, n)})


def test_class_picture_lists_exactly_the_classes_present(tmp_path, monkeypatch):
    from lidarfx import render

    figures = []
    real_save = render.save_figure

    def keep(fig, path, dpi):
        figures.append([t.get_text() for a in fig.axes if a.get_legend() for t in a.get_legend().get_texts()])
        return real_save(fig, path, dpi)

    monkeypatch.setattr(render, "save_figure", keep)
    cloud = _classified(np.random.default_rng(5))
    path, summary = render_picture(cloud, tmp_path / "cls.png", by="class", size=(480, 360), shading="none")
    assert [c["code"] for c in summary["colour"]["classes"]] == [2, 6, 9]
    assert sum(c["points"] for c in summary["colour"]["classes"]) == len(cloud)
    assert len(figures) == 1 and len(figures[0]) == 3
    assert figures[0][0].startswith("2 ground") and figures[0][1].startswith("6 building")
    assert figures[0][2].startswith("9 water")
    # the picture shows the class colours where the classes are
    from matplotlib.image import imread

    from lidarfx.colour import class_colour

    png = imread(path)
    assert png.shape[:2] == (360, 480)
    colours = {tuple(np.round(np.asarray(class_colour(c)) * 255).astype(int)) for c in (2, 6, 9)}
    found = {tuple(p) for p in np.round(png[..., :3].reshape(-1, 3) * 255).astype(int)}
    assert colours <= found


def test_the_png_holds_the_rendered_pixels_one_to_one(tmp_path):
    from matplotlib.image import imread

    from lidarfx.colour import by_attribute

    rng = np.random.default_rng(8)
    cloud = PointCloud(rng.uniform(0, 10, (20_000, 3)), {"intensity": rng.uniform(0, 1, 20_000)})
    path, s = render_picture(cloud, tmp_path / "i.png", by="intensity", size=(777, 555))
    png = np.round(imread(path)[..., :3] * 255).astype(int)
    assert png.shape == (555, 777, 3)
    w, h = s["frame"]["width"], s["frame"]["height"]
    img = render_points(cloud.xyz, by_attribute(cloud, "intensity", "viridis", None)[0], size=(w, h))
    c0, r0 = s["picture_offset"]
    crop = png[r0:r0 + h, c0:c0 + w]
    inner = (slice(h // 6, -h // 6), slice(w // 6, -w // 6))  # inside the scale bar and the north arrow
    np.testing.assert_array_equal(crop[inner], img.rgb[inner])


def test_rgb_8_and_16_bit_give_one_picture_and_morphology_uses_the_normals(tmp_path):
    rng = np.random.default_rng(6)
    xyz = rng.uniform(0, 10, (5000, 3))
    c8 = rng.integers(0, 256, (5000, 3))
    a = PointCloud(xyz, {"red": c8[:, 0].astype(np.uint16), "green": c8[:, 1].astype(np.uint16),
                         "blue": c8[:, 2].astype(np.uint16)})
    b = PointCloud(xyz, {k: (a[k].astype(np.uint32) * 257).astype(np.uint16) for k in ("red", "green", "blue")})
    _, sa = render_picture(a, tmp_path / "a.png", by="rgb", size=(320, 240), shading="none")
    _, sb = render_picture(b, tmp_path / "b.png", by="rgb", size=(320, 240), shading="none")
    assert sa["colour"]["scale"] == 255 and sb["colour"]["scale"] == 65535
    from matplotlib.image import imread

    np.testing.assert_array_equal(imread(tmp_path / "a.png"), imread(tmp_path / "b.png"))
    # morphology: a plane whose normals are given keeps one colour, morphology_rgb of that normal
    from lidarfx.colour import morphology_rgb

    n = np.array([0.3, -0.4, 0.866])
    plane = PointCloud(xyz * [1, 1, 0], {"normal_x": np.full(5000, n[0]), "normal_y": np.full(5000, n[1]),
                                         "normal_z": np.full(5000, n[2])})
    _, sm = render_picture(plane, tmp_path / "m.png", by="morphology", size=(320, 240), shading="none")
    assert sm["colour"]["normals"] == "attributes"
    img = render_points(plane.xyz, morphology_rgb(plane.xyz * 0 + n), size=(64, 48), shading="none")
    np.testing.assert_array_equal(_shown_colours(img), np.round(morphology_rgb(n[None]) * 255).astype(int))


def test_checks_and_helpers():
    assert parse_size("1600x1200") == (1600, 1200) and parse_size((40, 30)) == (40, 30)
    for bad in ("0x5", "abc", "10x", "1.5x3", (0, 5), "99999x10"):
        with pytest.raises(LidarfxError, match="size"):
            parse_size(bad)
    assert [scale_bar_length(s) for s in (1000.0, 37.0, 0.9, 10.0)] == [200.0, 5.0, 0.1, 2.0]
    f = fit_frame(0.0, 0.0, 5.0, 5.0, 101, 81)  # one point: a frame all the same, the point in the middle
    assert f.cell > 0 and f.pixel([[0.0, 5.0, 0.0]]) == (np.array([40]), np.array([50]))
    with pytest.raises(LidarfxError, match="view"):
        render_points(np.zeros((3, 3)), view="bottom")
    with pytest.raises(LidarfxError, match="finite"):
        render_points(np.full((3, 3), np.nan))
    with pytest.raises(LidarfxError, match="no points"):
        render_picture(PointCloud(np.zeros((0, 3))), "x.png")


# --------------------------------------------------------------------------- command line
@pytest.fixture()
def cloud_file(tmp_path):
    path = tmp_path / "scene.npz"
    lidarfx.write(_classified(np.random.default_rng(7)), path)
    return path


def test_cli_writes_a_picture_of_the_requested_size(cloud_file, tmp_path, capsys):
    from matplotlib.image import imread

    out = tmp_path / "z.png"
    rc = main(["render", str(cloud_file), str(out), "--by", "intensity", "--size", "500x320", "--range", "0,1000",
               "--view", "front", "--json", "-q"])
    assert rc == 0
    s = json.loads(capsys.readouterr().out)
    assert imread(out).shape[:2] == (320, 500)
    assert s["size"] == [500, 320] and s["view"] == "front" and s["by"] == "intensity"
    assert s["points"] == s["drawn"] == 6000 and s["shading"] == "edl"
    assert s["colour"]["range"] == [0.0, 1000.0] and s["colour"]["range_source"] == "given"
    assert s["frame"]["right"] == "x" and s["frame"]["up"] == "z" and s["frame"]["metres_per_pixel"] > 0
    assert s["point_size"] > 0 and s["point_size_source"] == "auto" and 0 < s["covered"] <= 1
    assert set(s["seconds"]) == {"read", "colour", "render", "picture"}
    # the text summary goes to stderr
    assert main(["render", str(cloud_file), str(tmp_path / "c.png"), "--by", "class", "--size", "400x300",
                 "--shading", "hillshade", "--point-size", "2"]) == 0
    err = capsys.readouterr().err
    assert "2 ground" in err and "top view" in err


@pytest.mark.parametrize("extra, output, message", [
    (["--by", "nope"], "out.png", "no attribute 'nope'"),
    (["--size", "0x5"], "out.png", "size"),
    (["--size", "abc"], "out.png", "size"),
    (["--range", "5,1"], "out.png", "range"),
    (["--cmap", "nocmap"], "out.png", "colour map"),
    ([], "missing/out.png", "does not exist"),
    ([], "out.jpg", "PNG"),
    (["--by", "rgb"], "out.png", "red, green and blue"),
])
def test_cli_refuses_bad_input_in_one_line(cloud_file, tmp_path, capsys, extra, output, message):
    rc = main(["render", str(cloud_file), str(tmp_path / output), *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("lidarfx: error:") and message in err[0], err
    assert not list(tmp_path.rglob("*.png")) and not list(tmp_path.rglob("*.jpg"))


def test_cli_refuses_an_empty_cloud(tmp_path, capsys):
    empty = tmp_path / "empty.npz"
    lidarfx.write(PointCloud(np.zeros((0, 3))), empty)
    rc = main(["render", str(empty), str(tmp_path / "e.png")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "no points" in err[0]
    assert not (tmp_path / "e.png").exists()
