"""Synthetic ALS gable-roof house: determinism, and that the points and the roof lines follow the
closed-form geometry (roof z(v) = wall_height + (width/2 − |v|)·tan(pitch) in the house frame)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lidarfx import LidarfxError, PointCloud, synth
from lidarfx.synth import GENERATORS, HOUSE_CLASSES
from lidarfx.synth._common import rotate_z

# defaults of synth.house
L, W, H, PITCH, O, AZ, MARGIN = 12.0, 9.0, 6.0, 35.0, 0.5, 30.0, 10.0
TAN = math.tan(math.radians(PITCH))
EAVE_Z = H - O * TAN  # 5.6499 m
RIDGE_Z = H + W / 2 * TAN  # 9.1509 m
HL, HW = L / 2, W / 2
RU, RV = HL + O, HW + O
TU, TV = RU + MARGIN, RV + MARGIN


def frame(az: float) -> tuple[np.ndarray, np.ndarray]:
    a = math.radians(az)
    return np.array([math.sin(a), math.cos(a), 0.0]), np.array([-math.cos(a), math.sin(a), 0.0])


def to_uv(xyz, az: float = AZ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    u, v = frame(az)
    p = np.atleast_2d(np.asarray(xyz, float))
    return p @ u, p @ v, p[:, 2]


def roof_z(v) -> np.ndarray:
    return H + (HW - np.abs(v)) * TAN


def parts(cloud: PointCloud) -> dict[str, np.ndarray]:
    return {name: cloud["part"] == code for name, code in cloud.meta["truth"]["parts"].items()}


@pytest.fixture(scope="module")
def exact() -> PointCloud:
    return synth.house(noise=0.0, seed=2)


@pytest.fixture(scope="module")
def noisy() -> PointCloud:
    return synth.house(seed=2)


# ------------------------------------------------------------------ basics
def test_deterministic_by_seed_and_truth_is_json():
    a, b, c = synth.house(seed=5), synth.house(seed=5), synth.house(seed=6)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    assert a.names == b.names == ["classification", "part", "roof_face"]
    for name in a.names:
        np.testing.assert_array_equal(a[name], b[name])
    assert a.meta["truth"] == b.meta["truth"]
    assert a.xyz.shape != c.xyz.shape or not np.array_equal(a.xyz, c.xyz)
    truth = json.loads(json.dumps(a.meta["truth"], allow_nan=False))
    assert truth["generator"] == "house" and truth["params"]["seed"] == 5
    assert set(truth) >= {"classes", "parts", "frame", "building", "lines", "roof_planes", "tile", "counts"}
    assert GENERATORS["house"] is synth.house
    assert a["part"].dtype == np.int32 and a["roof_face"].dtype == np.int32 and a["classification"].dtype == np.uint8


def test_classes_parts_counts_and_override(exact):
    t = exact.meta["truth"]
    assert t["classes"] == HOUSE_CLASSES == {"ground": 2, "building": 6}
    p = parts(exact)
    assert set(np.unique(exact["classification"][p["ground"]])) == {2}
    assert set(np.unique(exact["classification"][p["roof"] | p["wall"]])) == {6}
    assert t["counts"] == {"ground": int(p["ground"].sum()), "building": int((p["roof"] | p["wall"]).sum())}
    # roof_face: 0 for v >= 0, 1 for v < 0, -1 off the roof
    _, v, _ = to_uv(exact.xyz)
    face = exact["roof_face"]
    assert np.all(face[~p["roof"]] == -1)
    assert np.all(face[p["roof"] & (v > 0)] == 0) and np.all(face[p["roof"] & (v < 0)] == 1)
    c = synth.house(classes={"building": 9}, noise=0.0, seed=2)
    assert set(np.unique(c["classification"])) == {2, 9} and c.meta["truth"]["classes"]["building"] == 9
    np.testing.assert_array_equal(c.xyz, exact.xyz)


def test_point_counts_follow_the_densities(exact):
    """random sampling draws round(area × density) positions per part: exact counts where no
    part is cut away; the roof's share of the tile is binomial."""
    p = parts(exact)
    u, v, z = to_uv(exact.xyz)
    in_roof = (np.abs(u) <= RU) & (np.abs(v) <= RV)
    in_foot = (np.abs(u) <= HL) & (np.abs(v) <= HW)
    first = p["roof"].sum() + (p["ground"] & ~in_roof).sum()
    assert first == round(4 * TU * TV * 20.0)  # 19 800 first returns over the tile
    n, share = first, (RU * RV) / (TU * TV)
    assert abs(p["roof"].sum() - n * share) < 5 * math.sqrt(n * share * (1 - share))
    # ground under the overhang: four strips, 22 m² at 20 × 0.5 points/m² = 220 points
    assert (p["ground"] & in_roof & ~in_foot).sum() == round((4 * RU * RV - 4 * HL * HW) * 10.0) == 220
    # long walls: 2 × 12 m × 6 m at 2 points/m²
    assert (p["wall"] & np.isclose(np.abs(v), HW)).sum() == 2 * round(L * H * 2.0) == 288
    gable = p["wall"] & np.isclose(np.abs(u), HL)
    expected = 2 * (W * RIDGE_Z * 2.0) * (W * (H + RIDGE_Z) / 2) / (W * RIDGE_Z)  # accepted share of the rectangle
    assert abs(gable.sum() - expected) < 5 * math.sqrt(expected)
    assert p["wall"].sum() == 288 + gable.sum()


# -------------------------------------------------------------------- roof
def test_roof_points_lie_on_their_plane(exact, noisy):
    t = exact.meta["truth"]
    for plane in t["roof_planes"]:
        n = np.asarray(plane["normal"])
        assert abs(np.linalg.norm(n) - 1) < 1e-12 and n[2] > 0
        assert abs(math.degrees(math.acos(n[2])) - PITCH) < 1e-9
        assert abs(plane["dip"] - PITCH) < 1e-9
        # down-dip towards +v for face 0 (azimuth of v = az − 90°), towards −v for face 1
        assert abs(plane["dip_direction"] - (AZ - 90 if plane["face"] == 0 else AZ + 90) % 360) < 1e-9
        for cloud, sigma in ((exact, 0.0), (noisy, 0.02)):
            p = cloud.xyz[cloud["roof_face"] == plane["face"]]
            assert len(p) > 1000
            r = (p - plane["point"]) @ n
            if sigma == 0:
                assert np.abs(r).max() < 1e-9
            else:
                assert abs(r.std() - sigma) < 0.1 * sigma and abs(r.mean()) < 4 * sigma / math.sqrt(len(p))
    # the same in closed form: z = wall_height + (width/2 − |v|)·tan(pitch) over the roof extent
    roof = exact["part"] == 1
    u, v, z = to_uv(exact.xyz[roof])
    np.testing.assert_allclose(z, roof_z(v), rtol=0, atol=1e-9)
    assert np.abs(u).max() <= RU and np.abs(v).max() <= RV


def test_roof_reaches_ridge_and_eave_heights(exact, noisy):
    b = exact.meta["truth"]["building"]
    assert b["eave_height"] == pytest.approx(EAVE_Z, abs=1e-12)
    assert b["ridge_height"] == pytest.approx(RIDGE_Z, abs=1e-12)
    assert b["roof_pitch"] == PITCH and b["azimuth"] == AZ and b["centre"] == [0.0, 0.0]
    dense = synth.house(density=200.0, noise=0.0, margin=0.0, seed=1)
    z = dense.xyz[dense["part"] == 1, 2]
    assert RIDGE_Z - 0.005 < z.max() <= RIDGE_Z + 1e-9
    assert EAVE_Z - 1e-9 <= z.min() < EAVE_Z + 0.005
    # the roof points within 5 cm of the eave lines sit at the eave height
    for cloud, sigma in ((exact, 0.0), (noisy, 0.02)):
        u, v, z = to_uv(cloud.xyz[cloud["part"] == 1])
        near = np.abs(v) > RV - 0.05
        assert near.sum() > 15  # expected 2 × 13 m × 0.05 m × 20 / m² = 26
        d = z[near] - (EAVE_Z + (RV - np.abs(v[near])) * TAN)
        if sigma == 0:
            assert np.abs(d).max() < 1e-9
            assert np.all((z[near] >= EAVE_Z - 1e-9) & (z[near] <= EAVE_Z + 0.05 * TAN + 1e-9))
        else:
            assert abs(d.mean()) < 4 * sigma / math.sqrt(near.sum())
            assert abs(z[near].mean() - (EAVE_Z + 0.025 * TAN)) < 0.01


def test_truth_lines_lie_on_the_roof_surface(exact):
    t = exact.meta["truth"]
    lines = t["lines"]
    kinds = [ln["kind"] for ln in lines]
    assert kinds.count("ridge") == 1 and kinds.count("eave") == 2 and kinds.count("verge") == 4
    planes = {pl["face"]: pl for pl in t["roof_planes"]}
    u_dir, _ = frame(AZ)
    for ln in lines:
        a, b = np.asarray(ln["start"]), np.asarray(ln["end"])
        ua, va, za = to_uv(np.vstack([a, b]))
        np.testing.assert_allclose(za, roof_z(va), rtol=0, atol=1e-12)  # on the surface formula
        assert np.all(np.abs(ua) <= RU + 1e-12) and np.all(np.abs(va) <= RV + 1e-12)
        for face in ln["faces"]:  # and on the plane of every face it bounds
            n, q = np.asarray(planes[face]["normal"]), np.asarray(planes[face]["point"])
            assert abs((a - q) @ n) < 1e-12 and abs((b - q) @ n) < 1e-12
        if ln["kind"] == "ridge":
            np.testing.assert_allclose(va, 0.0, atol=1e-12)
            np.testing.assert_allclose(za, RIDGE_Z, atol=1e-12)
            np.testing.assert_allclose(ua, [-RU, RU], atol=1e-12)
            np.testing.assert_allclose((b - a) / np.linalg.norm(b - a), u_dir, atol=1e-12)
            assert ln["faces"] == [0, 1]
        elif ln["kind"] == "eave":
            s = 1.0 if ln["side"] == "left" else -1.0
            np.testing.assert_allclose(va, s * RV, atol=1e-12)
            np.testing.assert_allclose(za, EAVE_Z, atol=1e-12)
            assert np.linalg.norm(b - a) == pytest.approx(L + 2 * O, abs=1e-12)
        else:  # verge: from an eave end up to a ridge end, length (width/2 + overhang) / cos(pitch)
            np.testing.assert_allclose(np.abs(ua), RU, atol=1e-12)
            assert abs(abs(va[0]) - RV) < 1e-12 and abs(va[1]) < 1e-12
            assert za[0] == pytest.approx(EAVE_Z, abs=1e-12) and za[1] == pytest.approx(RIDGE_Z, abs=1e-12)
            assert np.linalg.norm(b - a) == pytest.approx(RV / math.cos(math.radians(PITCH)), abs=1e-12)
    # footprint and roof extent: 4 corners each at (±half length, ±half width) in the house frame
    for key, (hu, hv) in (("footprint", (HL, HW)), ("roof_extent", (RU, RV))):
        c = np.column_stack([np.asarray(t["building"][key]), np.zeros(4)])
        u, v, _ = to_uv(c)
        np.testing.assert_allclose(u, [-hu, hu, hu, -hu], atol=1e-12)
        np.testing.assert_allclose(v, [-hv, -hv, hv, hv], atol=1e-12)
    assert t["tile"]["u_half"] == pytest.approx(TU) and t["tile"]["v_half"] == pytest.approx(TV)


# ------------------------------------------------------------ ground, walls
def test_no_ground_inside_the_footprint(exact, noisy):
    for cloud, sigma in ((exact, 0.0), (noisy, 0.02)):
        u, v, z = to_uv(cloud.xyz[cloud["part"] == 0])
        tol = 4 * sigma
        assert not np.any((np.abs(u) < HL - tol) & (np.abs(v) < HW - tol))
        assert np.abs(z).max() <= 5 * sigma + 1e-12  # flat ground z = 0 (17 k points: 5σ)
        assert np.abs(u).max() <= TU + tol and np.abs(v).max() <= TV + tol
    assert synth.house(ground_under_roof=0.0, noise=0.0, seed=2)["part"].tolist().count(0) == \
        exact["part"].tolist().count(0) - 220


def test_wall_points_on_the_footprint_and_below_the_roof(exact, noisy):
    for cloud, sigma in ((exact, 0.0), (noisy, 0.02)):
        u, v, z = to_uv(cloud.xyz[cloud["part"] == 2])
        tol = 4 * sigma + 1e-9
        on_long = np.abs(np.abs(v) - HW) <= tol
        on_gable = np.abs(np.abs(u) - HL) <= tol
        assert np.all(on_long | on_gable)
        assert np.all(np.abs(u) <= HL + tol) and np.all(np.abs(v) <= HW + tol)
        assert np.all((z >= -tol) & (z <= roof_z(np.minimum(np.abs(v), HW)) + tol))
        if sigma == 0:
            assert np.all(z[on_long & ~on_gable] <= H + 1e-9)
            assert H + 2.0 < z[on_gable].max() <= RIDGE_Z  # the gable triangles
        else:  # 99 % within 3σ of the boundary
            d = np.minimum(np.abs(np.abs(v) - HW), np.abs(np.abs(u) - HL))
            assert np.mean(d <= 3 * sigma) > 0.99
    assert (synth.house(wall_density=0.0, seed=2)["part"] == 2).sum() == 0


# ------------------------------------------------------------ options
@pytest.mark.parametrize("az", [0.0, 30.0, 90.0, 200.0, -45.0])
def test_azimuth_rotates_the_scene(az):
    a = synth.house(azimuth=az, noise=0.0, seed=4)
    ref = synth.house(azimuth=0.0, noise=0.0, seed=4)
    t = a.meta["truth"]
    ridge = next(ln for ln in t["lines"] if ln["kind"] == "ridge")
    d = np.subtract(ridge["end"], ridge["start"])
    r = math.radians(az)
    np.testing.assert_allclose(d / np.linalg.norm(d), [math.sin(r), math.cos(r), 0.0], atol=1e-12)
    np.testing.assert_allclose(t["frame"]["u"], [math.sin(r), math.cos(r), 0.0], atol=1e-15)
    assert t["building"]["azimuth"] == pytest.approx(az % 360.0)
    # the same draws in the house frame: the points are the azimuth-0 scene turned clockwise by az
    np.testing.assert_allclose(a.xyz, rotate_z(ref.xyz, -az), rtol=0, atol=1e-9)
    for la, lr in zip(t["lines"], ref.meta["truth"]["lines"]):
        assert la["kind"] == lr["kind"] and la["side"] == lr["side"]
        np.testing.assert_allclose(la["start"], rotate_z(lr["start"], -az), atol=1e-9)


def test_grid_sampling():
    c = synth.house(sampling="grid", noise=0.0, seed=0)
    u, v, z = to_uv(c.xyz)
    p = parts(c)
    first = p["roof"] | (p["ground"] & ~((np.abs(u) <= RU) & (np.abs(v) <= RV)))
    h = 20.0 ** -0.5
    mu, mv = round(2 * TU / h), round(2 * TV / h)  # 148 × 134 cell centres
    assert first.sum() == mu * mv == 148 * 134
    np.testing.assert_allclose(np.unique(np.round(u[first], 9)), -TU + (np.arange(mu) + 0.5) * 2 * TU / mu, atol=1e-9)
    np.testing.assert_allclose(z[p["roof"]], roof_z(v[p["roof"]]), atol=1e-9)
    assert synth.house(sampling="grid", seed=0).meta["truth"]["params"]["sampling"] == "grid"


def test_origin_shifts_points_only(exact):
    o = [500000.0, 5200000.0, 300.0]
    b = synth.house(noise=0.0, seed=2, origin=o)
    np.testing.assert_allclose(b.xyz - exact.xyz, np.broadcast_to(o, exact.xyz.shape), atol=1e-6)
    assert b.meta["truth"]["origin"] == o and b.meta["truth"]["lines"] == exact.meta["truth"]["lines"]


@pytest.mark.parametrize("bad, match", [
    ({"roof_pitch": 80}, "roof_pitch must be in"),
    ({"roof_pitch": 0}, "roof_pitch must be in"),
    ({"roof_pitch": float("nan")}, "roof_pitch must be a finite number"),
    ({"overhang": 10.0}, "eaves below ground"),  # 10 × tan 35° = 7.0 m > 6 m
    ({"overhang": -0.1}, "overhang must be >= 0"),
    ({"overhang": 1e5}, "overhang must be at most"),
    ({"density": -1}, "density must be > 0"),
    ({"density": 0}, "density must be > 0"),
    ({"density": float("nan")}, "density must be a finite number"),
    ({"length": float("nan")}, "length must be a finite number"),
    ({"width": 1e9}, "width must be at most"),
    ({"wall_height": 0}, "wall_height must be > 0"),
    ({"azimuth": float("inf")}, "azimuth must be a finite number"),
    ({"noise": -0.1}, "noise must be >= 0"),
    ({"wall_density": -1}, "wall_density must be >= 0"),
    ({"margin": -1}, "margin must be >= 0"),
    ({"ground_under_roof": 2}, "ground_under_roof is a share"),
    ({"sampling": "poisson"}, "sampling must be one of"),
    ({"classes": {"roof": 1}}, "unknown class name"),
    ({"classes": {"building": 2}}, "class codes must be distinct"),
    ({"seed": 1.5}, "seed must be an integer"),
    ({"density": 1e308}, "at most 50,000,000"),
    ({"density": 1e9, "sampling": "grid"}, "at most 50,000,000"),  # per axis fine, product not
    ({"density": 1e-300, "wall_density": 0}, "house: the scene has no points at density 1e-300; raise the density"),
])
def test_bad_parameters_raise_one_line_errors(bad, match):
    with pytest.raises(LidarfxError, match=match) as exc:
        synth.house(**bad)
    assert "\n" not in str(exc.value)


def test_eaves_just_above_ground_are_accepted():
    c = synth.house(overhang=8.5, roof_pitch=35.0, wall_height=6.0, noise=0.0, margin=1.0)  # 8.5 tan 35° = 5.95
    b = c.meta["truth"]["building"]
    assert b["eave_height"] == pytest.approx(6.0 - 8.5 * TAN) and b["eave_height"] > 0
    assert c.xyz[c["part"] == 1, 2].min() >= b["eave_height"] - 1e-9


# ----------------------------------------------------------------------- CLI
def test_cli_writes_cloud_and_truth(tmp_path, capsys):
    import lidarfx
    from lidarfx.cli import main

    out = tmp_path / "OUT.laz"
    assert main(["synth", "house", str(out), "--seed", "3"]) == 0
    assert "house" in capsys.readouterr().out
    truth = json.loads((tmp_path / "OUT.laz.truth.json").read_text())
    expected = synth.house(seed=3)
    assert truth["generator"] == "house" and truth["params"]["seed"] == 3
    assert truth["lines"] == json.loads(json.dumps(expected.meta["truth"]["lines"]))
    cloud = lidarfx.read(out)
    assert len(cloud) == len(expected)
    np.testing.assert_allclose(np.sort(cloud.xyz[:, 2]), np.sort(expected.xyz[:, 2]), atol=2e-3)
    np.testing.assert_array_equal(np.sort(np.asarray(cloud["classification"])), np.sort(expected["classification"]))
    assert main(["synth", "house", str(tmp_path / "bad.laz"), "-p", "roof_pitch=80"]) == 2
    assert not (tmp_path / "bad.laz").exists()
