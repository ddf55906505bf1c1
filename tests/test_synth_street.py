"""The synthetic mobile-mapping street (lidarfx.synth.street, issue 31 item 3): classes, the
geometry of wires and poles against the truth, MLS sampling, reproducibility, parameter checks."""
from __future__ import annotations

import json

import numpy as np
import pytest

import lidarfx
from lidarfx import synth
from lidarfx.cli import main
from lidarfx.errors import LidarfxError
from lidarfx.synth import GENERATORS, STREET_CLASSES, catenary_z


@pytest.fixture(scope="module")
def exact():
    """A scene without noise (every point on its surface), with two cross wires."""
    return synth.street(seed=4, noise=0.0, noise_fraction=0.0, cross_wires=2)


@pytest.fixture(scope="module")
def noisy():
    return synth.street(seed=4)


def _of(cloud, oid):
    return cloud.xyz[np.asarray(cloud["object_id"]) == oid] - np.asarray(cloud.meta["truth"]["origin"])


def test_every_class_is_present_with_its_code(noisy):
    cls = np.asarray(noisy["classification"])
    truth = noisy.meta["truth"]
    assert truth["classes"] == STREET_CLASSES
    assert GENERATORS["street"] is synth.street
    for name, code in STREET_CLASSES.items():
        assert (cls == code).sum() == truth["counts"][name] > 0, name
    assert set(np.unique(cls)) == set(STREET_CLASSES.values())
    # thin classes are thin but there: a few per cent of the points
    assert 0.005 < truth["counts"]["wire"] / len(cls) < 0.1 and 0.005 < truth["counts"]["pole"] / len(cls) < 0.1
    kinds = {p["kind"] for p in truth["poles"]}
    assert kinds == {"lamp", "utility", "sign"}
    assert {w["kind"] for w in truth["wires"]} == {"along", "across"}
    # an MLS profile scanner records no return numbers (nor intensity, nor GPS time)
    assert set(noisy.names) == {"classification", "object_id"}
    # no cars: no car class
    none = synth.street(seed=4, n_cars=0)
    assert "car" not in none.meta["truth"]["counts"] and not (np.asarray(none["classification"]) == 65).any()


def test_wire_points_lie_on_the_surface_of_their_catenaries(exact):
    truth = exact.meta["truth"]
    assert len(truth["wires"]) >= 4
    for w in truth["wires"]:
        pts = _of(exact, w["object_id"])
        assert len(pts) > 50, w["id"]
        d, u = np.asarray(w["start_xy"]), np.asarray(w["direction"])
        a, s0, c = w["a"], w["s0"], w["c"]
        # the curve passes through both attachment points
        for s, att in ((0.0, w["attachment_start"]), (w["horizontal_length"], w["attachment_end"])):
            assert abs(catenary_z(s, a, s0, c) - att[2]) < 1e-9
            np.testing.assert_allclose(d + s * u, att[:2], atol=1e-9)
        # every point is one wire radius from the curve (nearest point of a 2 mm sampling)
        ss = np.linspace(-0.05, w["horizontal_length"] + 0.05, int(w["horizontal_length"] * 500) + 2)
        curve = np.column_stack([d + ss[:, None] * u, catenary_z(ss, a, s0, c)])
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(curve).query(pts)
        assert np.all(np.abs(dist - w["radius"]) < 2e-3), (w["id"], np.abs(dist - w["radius"]).max())
        along = (pts[:, :2] - d) @ u
        assert along.min() >= -w["radius"] - 1e-6 and along.max() <= w["horizontal_length"] + w["radius"] + 1e-6
        assert w["sag"] > 0 and 150.0 <= a <= 400.0
    # along-street wires hang from the utility poles' attachment points, span by span
    util = [p for p in truth["poles"] if p["kind"] == "utility"]
    for w in truth["wires"]:
        if w["kind"] == "along":
            assert w["attachment_start"] == util[w["span"]]["attachments"][w["phase"]]
            assert w["attachment_end"] == util[w["span"] + 1]["attachments"][w["phase"]]
        else:  # across: from facade to facade
            facades = sorted(b["facade_y"] for b in truth["buildings"])
            assert w["attachment_start"][1] in facades and w["attachment_end"][1] in facades


def test_noise_shows_as_sigma_around_the_wires(noisy):
    w = noisy.meta["truth"]["wires"][0]
    pts = _of(noisy, w["object_id"])
    s = (pts[:, :2] - w["start_xy"]) @ np.asarray(w["direction"])
    dz = pts[:, 2] - catenary_z(s, w["a"], w["s0"], w["c"])
    assert 0.005 < np.std(dz) < 0.02  # σ = 1 cm and the 1 cm radius


def test_pole_points_lie_on_their_shafts(exact):
    truth = exact.meta["truth"]
    g = truth["ground"]
    for p in truth["poles"]:
        pts = _of(exact, p["object_id"])
        base = np.asarray(p["base"])
        assert len(pts) > 30, p
        # the base stands on the sidewalk: z of the ground profile there
        ay = abs(base[1])
        z0 = truth["trajectory"]["grade"] * base[0] - g["camber"] * g["road_half_width"] + g["curb_height"] \
            + g["sidewalk_slope"] * (ay - g["road_half_width"])
        assert abs(base[2] - z0) < 1e-9
        shaft = pts[pts[:, 2] < base[2] + p["height"] - 0.8]  # below arms, cross arms, lamps and plates
        r = np.hypot(shaft[:, 0] - base[0], shaft[:, 1] - base[1])
        np.testing.assert_allclose(r, p["radius"], atol=1e-9)
        assert pts[:, 2].min() >= base[2] - 1e-9 and pts[:, 2].max() <= base[2] + p["height"] + 1e-9
        # MLS sees the side facing the driving line, not the back
        facing = (shaft[:, 1] - base[1]) * np.sign(-base[1])
        assert (facing > -0.5 * p["radius"]).mean() > 0.9
    # trees keep their distance from poles and wires
    curve = np.vstack([_of(exact, w["object_id"]) for w in truth["wires"]])
    from scipy.spatial import cKDTree

    tree = cKDTree(curve)
    for t in truth["trees"]:
        pts = _of(exact, t["object_id"])
        assert tree.query(pts)[0].min() > 0.95  # 1 m to every wire (the surface sample's tolerance)
        for p in truth["poles"]:
            if p["side"] == t["side"]:
                assert abs(p["base"][0] - t["position"][0]) >= 2.5


def test_mls_sampling_density_falls_with_range(exact):
    """Ground points per m²: full density near the driving line, about ref_range / r farther out."""
    truth = exact.meta["truth"]
    cls = np.asarray(exact["classification"])
    g = exact.xyz[cls == 2]
    L = exact.meta["truth"]["params"]["length"]
    near = (np.abs(g[:, 1]) < 1.0).sum() / (2.0 * L)
    far = ((np.abs(g[:, 1]) > 7.0) & (np.abs(g[:, 1]) < 8.0)).sum() / (2.0 * L)
    assert 0.85 * 100 < near <= 1.05 * 100  # density 100 pts/m² within ref_range (5 m)
    assert far < 0.35 * near
    # facades: the upper floors are sparser than the lower ones
    b = exact.xyz[cls == 6]
    low, high = (b[:, 2] < 4).sum(), ((b[:, 2] > 6) & (b[:, 2] < 10)).sum()
    assert high < low
    assert truth["trajectory"]["scanner_height"] == 2.3


def test_same_seed_same_scene_other_seed_other_scene():
    a, b, c = synth.street(seed=7), synth.street(seed=7), synth.street(seed=8)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_array_equal(a["classification"], b["classification"])
    assert a.meta["truth"] == b.meta["truth"]
    assert len(a) != len(c) or not np.array_equal(a.xyz, c.xyz)
    assert json.loads(json.dumps(a.meta["truth"], allow_nan=False))["generator"] == "street"
    o = [500000.0, 5200000.0, 100.0]
    d = synth.street(seed=7, origin=o)
    np.testing.assert_allclose(d.xyz - a.xyz, np.broadcast_to(o, a.xyz.shape), atol=1e-6)


@pytest.mark.parametrize("kw, message", [
    ({"facade_offset": (5.0, 6.0)}, "sidewalk of at least 2 m"),
    ({"n_wires": 4}, "n_wires must be in 0 .. 3"),
    ({"density": -1}, "density must be > 0"),
    ({"catenary_a": (400, 100)}, "catenary_a must be (min, max)"),
    ({"grade": 0.5}, "grade is a rise per metre"),
    ({"building_height": (2.0, 5.0)}, "at least 4 m"),
    ({"density": 1e-300, "wire_density": 1e-300}, "street: the scene has no points at density 1e-300"),
])
def test_bad_parameters_are_refused(kw, message):
    with pytest.raises(LidarfxError, match=message.replace("(", r"\(").replace(")", r"\)")):
        synth.street(**kw)


def test_cli_writes_the_street_and_its_truth(tmp_path, capsys):
    out = tmp_path / "street.laz"
    assert main(["synth", "street", str(out), "--seed", "3", "-p", "length=30", "-p", "n_cars=1"]) == 0
    cloud = lidarfx.read(out)
    truth = json.loads((tmp_path / "street.laz.truth.json").read_text())
    assert truth["generator"] == "street" and truth["params"]["length"] == 30
    assert len(cloud) == sum(truth["counts"].values())
    assert set(np.unique(cloud["classification"])) <= set(STREET_CLASSES.values())
    # written as LAS: the return fields exist and hold 0 (what classify train's defaults detect)
    assert not np.asarray(cloud["return_number"]).any()
