"""Stereonet, rose and joint-set pictures: projection, bins and rasters checked behind the PNGs."""
import struct

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import mplstereonet  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from lidarfx.errors import LidarfxError  # noqa: E402
from lidarfx.geometry import dip_from_normal, normal_from_dip, plane_basis  # noqa: E402
from lidarfx.render.palette import NO_SET, set_colour  # noqa: E402
from lidarfx.render.stereonet import (  # noqa: E402
    _draw_rose,
    _draw_stereonet,
    _fill_holes,
    _orientations,
    _rose_heights,
    _set_label,
    _set_raster,
    _set_records,
    orientation_summary_view,
    rose_view,
    set_view,
    stereonet_view,
)

SETS = [(80.0, 170.0, 80.0, 600), (65.0, 245.0, 50.0, 400), (30.0, 20.0, 40.0, 250)]  # dip, dip dir, κ, n


def _fisher(mean, kappa, n, rng):
    """``n`` unit vectors Fisher-distributed around ``mean`` (exact inverse-CDF sampling)."""
    mu = np.asarray(mean, float) / np.linalg.norm(mean)
    u = rng.uniform(size=n)
    w = 1.0 + np.log(u + (1.0 - u) * np.exp(-2.0 * kappa)) / kappa  # cos of the angle to the mean
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    e1, e2, _ = plane_basis(mu)
    s = np.sqrt(np.clip(1.0 - w**2, 0.0, None))
    return w[:, None] * mu + s[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)


def _three_sets(seed=1):
    rng = np.random.default_rng(seed)
    normals = np.vstack([_fisher(normal_from_dip(d, a), k, n, rng) for d, a, k, n in SETS])
    ids = np.concatenate([np.full(n, i) for i, (*_, n) in enumerate(SETS)])
    dip, ddir = dip_from_normal(normals)
    recs = [{"id": i, "dip": d, "dip_direction": a, "kappa": k, "alpha95": 140.0 / np.sqrt(k * n),
             "share": n / len(ids)} for i, (d, a, k, n) in enumerate(SETS)]
    return dip, ddir, ids, recs


def _png_size(path):
    data = open(path, "rb").read(32)
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def _pole_vector(plunge, bearing):
    """Downward unit vector of a line of given plunge and bearing (x East, y North, z up)."""
    p, b = np.radians(plunge), np.radians(bearing)
    return np.stack([np.cos(p) * np.sin(b), np.cos(p) * np.cos(b), -np.sin(p)], axis=-1)


def _angle_deg(a, b):
    """Axial angle between unit vectors (0–90°)."""
    return np.degrees(np.arccos(np.clip(np.abs(np.sum(a * b, axis=-1)), 0.0, 1.0)))


@pytest.fixture
def stereo_ax():
    fig = plt.figure(figsize=(4, 4))
    ax = fig.add_subplot(111, projection="equal_area_stereonet")
    yield ax
    plt.close(fig)


# ----------------------------------------------------------------------------- files


def test_pictures_are_written_as_pngs_of_the_expected_size(tmp_path):
    dip, ddir, ids, recs = _three_sets()
    p1 = stereonet_view(dip, ddir, tmp_path / "net.png", set_ids=ids, sets=recs, dpi=50)
    p2 = rose_view(ddir - 90, tmp_path / "rose.png", set_ids=ids, dpi=50)
    p3 = orientation_summary_view(dip, ddir, ids, recs, tmp_path / "sum.png", dpi=50)
    assert p1 == tmp_path / "net.png" and p2.exists() and p3.exists()
    w1, h1 = _png_size(p1)
    assert w1 == 330 and abs(h1 - (6.4 + 0.17 * 3) * 50) <= 1  # figure size × dpi
    assert _png_size(p2) == (320, 280)
    w3, h3 = _png_size(p3)
    assert w3 == 600 and w3 > h3 > 300
    assert not list(tmp_path.glob("*.tmp*")), "temporary files left behind"


# ----------------------------------------------------------------------------- projection


@pytest.mark.parametrize(("dip", "ddir"), [(0.0, 0.0), (90.0, 90.0), (45.0, 180.0), (60.0, 30.0), (20.0, 300.0)])
def test_pole_is_drawn_at_its_equal_area_position(stereo_ax, dip, ddir):
    o = _orientations([dip], [ddir], None, None)
    out = _draw_stereonet(stereo_ax, o, [], method="exponential_kamb", sigma=3, max_poles=10)
    lon, lat = mplstereonet.pole(ddir - 90.0, dip)  # mplstereonet: strike by the right-hand rule
    assert np.allclose(out["poles"].get_offsets(), np.c_[lon, lat])
    # independent Schmidt net (primitive radius 1): r = √2 sin(θ/2), θ = angle of the pole from vertical
    plunge, trend = 90.0 - dip, ddir + 180.0
    r = np.sqrt(2.0) * np.sin(np.radians(90.0 - plunge) / 2.0)
    expected = r * np.array([np.sin(np.radians(trend)), np.cos(np.radians(trend))])
    xy = stereo_ax.transProjection.transform(out["poles"].get_offsets()) / np.sqrt(2.0)  # mplstereonet: primitive at √2
    assert np.allclose(xy[0], expected, atol=1e-9)


def test_horizontal_plane_pole_at_centre_and_vertical_north_south_plane_pole_at_west(stereo_ax):
    o = _orientations([0.0, 90.0], [0.0, 90.0], None, None)
    out = _draw_stereonet(stereo_ax, o, [], method="exponential_kamb", sigma=3, max_poles=10)
    xy = stereo_ax.transProjection.transform(out["poles"].get_offsets()) / np.sqrt(2.0)
    assert np.allclose(xy[0], [0.0, 0.0], atol=1e-12)
    assert np.allclose(xy[1], [-1.0, 0.0], atol=1e-12)  # on the primitive, azimuth 270°


def test_set_great_circle_mean_pole_and_cone(stereo_ax):
    recs = _set_records([{"id": 2, "dip": 30.0, "dip_direction": 20.0, "alpha95": 5.0},
                         {"id": 0, "dip": 80.0, "dip_direction": 170.0}])
    o = _orientations([], [], None, None)
    out = _draw_stereonet(stereo_ax, o, recs, method="exponential_kamb", sigma=3, max_poles=10)
    gc = out["great_circles"][0]
    assert np.allclose(matplotlib.colors.to_rgb(gc.get_color()), set_colour(2))
    # every vertex of the great circle lies in the plane 30/020 (right-hand-rule strike 290°)
    plunge, bearing = mplstereonet.geographic2plunge_bearing(*gc.get_data())
    assert np.max(_angle_deg(_pole_vector(plunge, bearing), normal_from_dip(30.0, 20.0)[None])) > 89.9
    # mean pole: plunge 60° towards 200°
    p, b = mplstereonet.geographic2plunge_bearing(*out["mean_poles"][0])
    assert abs(p[0] - 60.0) < 1e-6 and abs(b[0] - 200.0) < 1e-6
    # α95 cone: a small circle 5° around the mean pole (its lower-hemisphere half)
    verts = out["cones"][0].get_paths()[0].vertices
    cp, cb = mplstereonet.geographic2plunge_bearing(verts[:, 0], verts[:, 1])
    assert np.allclose(_angle_deg(_pole_vector(cp, cb), _pole_vector(60.0, 200.0)[None]), 5.0, atol=0.05)
    assert out["cones"][1] is None  # no alpha95 given


def test_density_peaks_at_the_main_set_and_follows_the_weights(stereo_ax):
    dip, ddir, ids, _ = _three_sets()
    o = _orientations(dip, ddir, None, ids)
    out = _draw_stereonet(stereo_ax, o, [], method="exponential_kamb", sigma=3, max_poles=20000)
    glon, glat, z = out["grid"]
    k = np.argmax(z)
    pk = _pole_vector(*[v[0] for v in mplstereonet.geographic2plunge_bearing(glon.ravel()[k], glat.ravel()[k])])
    assert _angle_deg(pk, normal_from_dip(80.0, 170.0)) < 6.0  # set 0 has the most and tightest poles
    # weighting set 2 × 20 moves the peak to set 2
    w = np.where(ids == 2, 20.0, 1.0)
    o2 = _orientations(dip, ddir, w, ids)
    out2 = _draw_stereonet(stereo_ax, o2, [], method="exponential_kamb", sigma=3, max_poles=20000, colorbar=False)
    glon, glat, z2 = out2["grid"]
    k2 = np.argmax(z2)
    pk2 = _pole_vector(*[v[0] for v in mplstereonet.geographic2plunge_bearing(glon.ravel()[k2], glat.ravel()[k2])])
    assert _angle_deg(pk2, normal_from_dip(30.0, 20.0)) < 8.0
    assert np.array_equal(w, np.where(ids == 2, 20.0, 1.0)), "caller's weights were changed"


def test_poles_are_coloured_by_set_and_subsampled(stereo_ax):
    dip, ddir, ids, _ = _three_sets()
    ids = ids.copy()
    ids[:10] = -1
    o = _orientations(dip, ddir, None, ids)
    out = _draw_stereonet(stereo_ax, o, [], method="schmidt", sigma=3, max_poles=500)
    assert len(out["index"]) == 500 and len(np.unique(out["index"])) == 500
    fc = out["poles"].get_facecolors()[:, :3]
    want = np.array([set_colour(int(i)) for i in ids[out["index"]]])
    assert np.allclose(fc, want)
    again = _draw_stereonet(stereo_ax, o, [], method="schmidt", sigma=3, max_poles=500, colorbar=False)
    assert np.array_equal(again["index"], out["index"])  # fixed seed
    assert np.allclose(set_colour(-1), NO_SET)


def test_set_legend_text():
    r = _set_records([{"id": 0, "dip": 80.2, "dip_direction": 170.4, "kappa": 120.3, "alpha95": 1.23, "share": 0.45}])
    assert _set_label(r[0]) == "set 0: 80/170, κ 120, α95 1.2°, 45 %"
    assert _set_label(_set_records([{"id": 3, "dip": 5, "dip_direction": 20}])[0]) == "set 3: 05/020"


# ----------------------------------------------------------------------------- rose


def test_rose_counts_each_strike_at_both_ends():
    r = _rose_heights(np.full(7, 30.0), None, None, 10.0)
    h = r["heights"][0]
    assert r["edges"][3] == 30 and r["edges"][21] == 210 and len(h) == 36
    assert h[3] == 7 and h[21] == 7 and h.sum() == 14


def test_rose_weights_sets_and_wrapping(tmp_path):
    strike = np.array([30.0, 35.0, 359.0, -1.0, 185.0, 30.0])
    w = np.array([1.0, 2.0, 0.5, 0.25, 4.0, 8.0])
    ids = np.array([0, 0, 1, 1, -1, -3])
    r = _rose_heights(strike, w, ids, 10.0)
    assert r["groups"] == [0, 1, -1]
    h = r["heights"]
    assert h[0, 3] == 3.0 and h[0, 21] == 3.0  # 30 and 35 → 30–40 and 210–220
    assert h[1, 35] == 0.75 and h[1, 17] == 0.75  # 359 and −1 (= 359) → 350–360 and 170–180
    assert h[2, 18] == 4.0 and h[2, 0] == 4.0 and h[2, 3] == 8.0 and h[2, 21] == 8.0  # ids < 0 together
    assert np.isclose(h.sum(), 2 * w.sum())
    fig = plt.figure()
    ax = fig.add_subplot(111, projection="polar")
    drawn = _draw_rose(ax, strike, w, ids, 10.0)
    assert drawn["unit"] == "weight" and any("weight" in t.get_text() for t in ax.get_yticklabels())
    assert np.allclose([b.get_facecolor()[:3] for b in drawn["bars"][1]][35], set_colour(1))
    assert ax.get_theta_direction() == -1 and np.isclose(ax.get_theta_offset(), np.pi / 2)  # N up, clockwise
    stacked = drawn["bars"][2][3]  # "no set" bar of bin 30–40 sits on the set bars below it
    assert np.isclose(stacked.get_y(), h[0, 3] + h[1, 3])
    plt.close(fig)
    assert rose_view(strike, tmp_path / "r.png", weights=w, set_ids=ids, bin_width=15, dpi=40).exists()


# ----------------------------------------------------------------------------- set view


def _wall(n=40_000, seed=3, tilt=0.0):
    """A 10 m × 5 m wall in the plane y = 0 (tilted back by ``tilt``°, facing South and up):
    set 0 on its western half, set 1 on its eastern half."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 10.0, n)
    s = rng.uniform(0.0, 5.0, n)
    t = np.radians(tilt)
    xyz = np.c_[x, s * np.sin(t), s * np.cos(t)] + [500_000.0, 6_000_000.0, 300.0]
    return xyz, (x >= 5.0).astype(np.int64)


def _share(img, colour):
    return float(np.mean(np.all(np.isclose(img, colour), axis=-1)))


def test_set_view_wall_from_the_front_has_set_0_left_and_set_1_right():
    xyz, ids = _wall()
    r = _set_raster(xyz, ids, view_normal=(0.0, -1.0, 0.0), pixels=100)
    img = r["image"]
    assert np.allclose(r["right"], [1, 0, 0]) and np.allclose(r["up"], [0, 0, 1])
    nv, nu = img.shape[:2]
    assert nu == 100 and 45 <= nv <= 55
    left, right = img[:, : nu // 2 - 2], img[:, nu // 2 + 2:]
    assert _share(left, set_colour(0)) > 0.97 and _share(right, set_colour(1)) > 0.97
    assert _share(left, set_colour(1)) == 0.0 and _share(right, set_colour(0)) == 0.0


def test_set_view_default_normal_looks_at_the_face_from_the_front():
    xyz, ids = _wall(tilt=10.0)  # dips 80° towards South: the upward normal leaves the rock
    r = _set_raster(xyz, ids, pixels=80)
    assert r["normal"][1] < -0.9 and r["normal"][2] > 0.1
    assert r["right"][0] > 0.99  # East to the right: not mirrored
    nu = r["image"].shape[1]
    assert _share(r["image"][:, : nu // 2 - 2], set_colour(0)) > 0.97
    # from behind (north), West is on the right
    back = _set_raster(xyz, ids, view_normal=(0.0, 1.0, 0.0), pixels=80)
    assert _share(back["image"][:, : nu // 2 - 2], set_colour(1)) > 0.97


def test_set_view_keeps_the_point_nearest_to_the_viewer():
    xyz, ids = _wall(n=30_000)
    rng = np.random.default_rng(4)
    front = np.c_[rng.uniform(0, 3, 8000), np.full(8000, -1.0), rng.uniform(0, 5, 8000)] + [500_000.0, 6_000_000.0, 300]
    pts = np.vstack([xyz, front])
    sid = np.r_[ids, np.full(8000, 2)]
    for order in (np.arange(len(pts)), np.arange(len(pts))[::-1]):  # the result does not depend on the order
        r = _set_raster(pts[order], sid[order], view_normal=(0.0, -1.0, 0.0), pixels=100)
        nu = r["image"].shape[1]
        assert _share(r["image"][:, 2:25], set_colour(2)) > 0.97  # x < 3 m: the nearer set-2 sheet hides set 0
        assert _share(r["image"][:, 35:45], set_colour(0)) > 0.97
        assert r["image"].shape[1] == nu


def test_fill_holes_closes_pin_holes_but_not_the_outline():
    win = np.full((6, 6), -1, np.int64)
    win[1:5, 1:5] = np.arange(16).reshape(4, 4)
    win[2, 2] = -1  # a pin hole
    depth = np.arange(16, dtype=float)
    out, filled = _fill_holes(win, depth)
    assert filled == 1
    assert out[2, 2] == 10  # the neighbour nearest to the viewer (largest depth) of 0, 1, 2, 4, 6, 8, 9, 10
    assert np.all(out[0] == -1) and np.all(out[:, 0] == -1) and np.all(out[5] == -1)


def test_set_view_png_and_legend(tmp_path):
    xyz, ids = _wall(n=5000)
    ids[:50] = -1
    p = set_view(xyz, ids, tmp_path / "sets.png", view_normal=(0, -1, 0), pixels=200, dpi=40)
    w, h = _png_size(p)
    assert w == 320 and 100 < h < 320


# ----------------------------------------------------------------------------- bad input


def one_line(excinfo):
    msg = str(excinfo.value)
    assert msg and "\n" not in msg
    return msg


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda p: stereonet_view([10, 20], [30], p), "one value per dip"),
        (lambda p: stereonet_view([10, 20], [30, 40], p, set_ids=[0]), "set_ids"),
        (lambda p: stereonet_view([10, 20], [30, 40], p, weights=[1, -1]), "non-negative"),
        (lambda p: stereonet_view([10, 20], [30, 40], p, weights=[0, 0]), "not all be zero"),
        (lambda p: stereonet_view([], [], p), "nothing to draw"),
        (lambda p: stereonet_view([np.nan], [10.0], p), "nothing to draw"),
        (lambda p: stereonet_view([95.0], [10.0], p), "0 to 90"),
        (lambda p: stereonet_view([10.0], [10.0], p, method="gauss"), "unknown density method"),
        (lambda p: stereonet_view([10.0], [10.0], p, sets=[{"id": 0, "dip": 10}]), "dip_direction"),
        (lambda p: rose_view([], p), "nothing to draw"),
        (lambda p: rose_view([10.0, 20.0], p, bin_width=7), "bin_width"),
        (lambda p: rose_view([10.0, 20.0], p, weights=[1.0]), "one value per strike"),
        (lambda p: set_view(np.zeros((5, 2)), np.zeros(5, int), p), "(n, 3)"),
        (lambda p: set_view(np.zeros((5, 3)), np.zeros(4, int), p), "one value per point"),
        (lambda p: set_view(np.zeros((0, 3)), np.zeros(0, int), p), "nothing to draw"),
        (lambda p: set_view(np.ones((5, 3)), np.zeros(5), p, view_normal=(0, 0, 0)), "view_normal"),
        (lambda p: set_view(np.ones((5, 3)), np.full(5, 0.5), p), "integers"),
        (lambda p: orientation_summary_view([1.0, 2.0], [3.0], None, [], p), "one value per dip"),
    ],
)
def test_bad_input_gives_a_one_line_error(tmp_path, call, needle):
    with pytest.raises(LidarfxError) as e:
        call(tmp_path / "x.png")
    assert needle in one_line(e)
    assert not (tmp_path / "x.png").exists()


def test_nan_orientations_are_dropped(tmp_path):
    dip = np.array([10.0, np.nan, 45.0, 60.0, 80.0])
    ddir = np.array([0.0, 10.0, np.inf, 200.0, 370.0])
    ids = np.array([0, 1, 2, 0, 1])
    o = _orientations(dip, ddir, np.arange(1.0, 6.0), ids)
    assert o["dropped"] == 2
    assert np.allclose(o["dip"], [10, 60, 80]) and np.allclose(o["dip_direction"], [0, 200, 10])
    assert np.allclose(o["strike"], [270, 110, 280]) and np.array_equal(o["set_ids"], [0, 0, 1])
    assert np.allclose(o["weights"], [1, 4, 5])
    assert stereonet_view(dip, ddir, tmp_path / "n.png", set_ids=ids, dpi=40).exists()
    # sets alone (no pole left) are still drawn
    assert stereonet_view([np.nan], [0.0], tmp_path / "s.png", sets=[{"id": 0, "dip": 50, "dip_direction": 90}],
                          dpi=40).exists()


# ----------------------------------------------------------------------------- realistic


def test_rockface_truth_stereonet_and_set_view(tmp_path):
    from lidarfx.synth import rockface

    cloud = rockface(density=100, seed=2)
    truth = cloud.meta["truth"]
    facets = {f["id"]: f for f in truth["facets"]}
    fid = np.asarray(cloud["facet_id"])
    dip = np.array([facets[i]["dip"] if i >= 0 else np.nan for i in fid])
    ddir = np.array([facets[i]["dip_direction"] if i >= 0 else np.nan for i in fid])
    ids = np.asarray(cloud["joint_set"]).astype(np.int64)
    counts = np.bincount(ids[ids >= 0])
    sets = [{"id": s["id"], "dip": s["dip"], "dip_direction": s["dip_direction"], "share": counts[s["id"]] / len(ids)}
            for s in truth["sets"]]
    net = stereonet_view(dip, ddir, tmp_path / "rock_net.png", set_ids=ids, sets=sets, max_poles=4000, dpi=60)
    view = set_view(cloud.xyz, ids, tmp_path / "rock_sets.png", pixels=400, dpi=60)
    both = orientation_summary_view(dip, ddir, ids, sets, tmp_path / "rock_sum.png", dpi=40)
    for p in (net, view, both):
        assert p.exists() and _png_size(p)[0] > 200
    # the facets' poles sit on their set's mean pole (scatter 0 in this scene)
    o = _orientations(dip, ddir, None, ids)
    for s in truth["sets"]:
        m = o["set_ids"] == s["id"]
        assert _angle_deg(normal_from_dip(o["dip"][m], o["dip_direction"][m]),
                          np.asarray(s["normal"])[None]).max() < 1e-3
    # the face is seen from the scanners' side (South) and is mostly set 0
    r = _set_raster(cloud.xyz, ids, pixels=400)
    assert r["normal"][1] < -0.8
    assert _share(r["image"], set_colour(0)) > 0.6
