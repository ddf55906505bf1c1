"""Synthetic scenes: determinism, and that the points really follow the stated truth."""
from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarfx import PointCloud, LidarfxError
from lidarfx import synth
from lidarfx.synth import GENERATORS, analytic_eigenvalues, catenary_z

PI2 = math.pi**2

# λ/R² of a uniform sample inside a sphere of radius R (docs/conventions.md), plus the corner and
# the line end derived the same way
SPEC_EIGENVALUES = {
    "line": (1 / 3, 0.0, 0.0),
    "plane": (1 / 4, 1 / 4, 0.0),
    "plane_border": (1 / 4, 1 / 4 - 16 / (9 * PI2), 0.0),
    "edge": (1 / 4, 1 / 8, 1 / 8 - 8 / (9 * PI2)),
    "volume": (1 / 5, 1 / 5, 1 / 5),
    "corner": (1 / 6 - 1 / (6 * math.pi), 1 / 6 - 1 / (6 * math.pi), 1 / 6 + 1 / (3 * math.pi) - 64 / (27 * PI2)),
    "line_end": (1 / 12, 0.0, 0.0),
}
DENSE = {"line": 2000.0, "line_end": 2000.0, "volume": 20000.0}  # others: surfaces
SMALL = {  # fast parameters per generator for the generic tests
    "facade": {"density": 100.0},
    "rockface": {"density": 20.0},
    "powerline": {"density": 0.5, "n_spans": 2},
    "tower": {"density": 200.0},
    "terrain": {"density": 1.0},
}


def eigen_in_sphere(xyz: np.ndarray, radius: float, centre=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, int]:
    p = xyz[np.linalg.norm(xyz - np.asarray(centre), axis=1) <= radius]
    q = p - p.mean(axis=0)
    return np.linalg.eigvalsh(q.T @ q / len(p))[::-1] / radius**2, len(p)


def pca_normal(p: np.ndarray) -> np.ndarray:
    q = p - p.mean(axis=0)
    return np.linalg.eigh(q.T @ q)[1][:, 0]


def angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.acos(min(1.0, abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b))))


# ------------------------------------------------------------------ generic
@pytest.mark.parametrize("kind", list(GENERATORS))
def test_deterministic_by_seed_and_truth_is_json(kind):
    kw = SMALL.get(kind, {})
    a = GENERATORS[kind](seed=5, **kw)
    b = GENERATORS[kind](seed=5, **kw)
    c = GENERATORS[kind](seed=6, **kw)
    assert isinstance(a, PointCloud) and len(a) > 0
    assert a.xyz.dtype == np.float64
    np.testing.assert_array_equal(a.xyz, b.xyz)
    assert a.names == b.names
    for name in a.names:
        np.testing.assert_array_equal(a[name], b[name])
    assert a.meta["truth"] == b.meta["truth"]
    assert a.xyz.shape != c.xyz.shape or not np.array_equal(a.xyz, c.xyz)
    truth = json.loads(json.dumps(a.meta["truth"], allow_nan=False))
    assert truth["generator"] == kind
    assert truth["params"]["seed"] == 5
    for k, v in kw.items():
        assert truth["params"][k] == v


@pytest.mark.parametrize("kind", ["plane", "powerline", "terrain"])
def test_origin_shifts_points_only(kind):
    kw = SMALL.get(kind, {})
    o = [500000.0, 5200000.0, 300.0]
    a = GENERATORS[kind](seed=1, **kw)
    b = GENERATORS[kind](seed=1, origin=o, **kw)
    np.testing.assert_allclose(b.xyz - a.xyz, np.broadcast_to(o, a.xyz.shape), atol=1e-6)
    assert b.meta["truth"]["origin"] == o


@pytest.mark.parametrize("kind", list(GENERATORS))
@pytest.mark.parametrize("origin", [(1e308, 0, 0), (1e23, 0, 0), (0, -1.0000001e9, 0), (0, 0, 2e9)])
def test_origin_beyond_1e9_is_refused(kind, origin):
    """At 1e23 every point of a scene had the same x (float64 steps of 2^24 m): refused, one line."""
    with pytest.raises(LidarfxError, match=r"origin coordinates must be at most 1e\+09 in absolute value"):
        GENERATORS[kind](origin=origin)


def test_origin_at_1e9_keeps_sub_mm_resolution():
    o = (1e9, -1e9, 1e9)
    a, b = synth.plane(seed=2), synth.plane(seed=2, origin=o)
    np.testing.assert_allclose(b.xyz - np.array(o), a.xyz, rtol=0, atol=1e-6)  # float64 steps 1.2e-7 m
    with pytest.raises(LidarfxError, match="scanner coordinates must be at most"):
        synth.facade(scanner=(1e12, 0.0, 1.6))


@pytest.mark.parametrize("value", [float("inf"), float("nan"), 1e308, 1e200, 2.0])
def test_rotation_with_entries_outside_minus_1_1_is_one_error(value):
    """inf / 1e308 entries printed a numpy RuntimeWarning (overflow in matmul) before the error."""
    import warnings

    m = np.eye(3)
    m[0, 0] = value
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(LidarfxError, match="rotation must be a proper 3x3 rotation matrix"):
            synth.plane(rotation=m)


@pytest.mark.parametrize("kind, kw", [("terrain", {}), ("facade", {}), ("rockface", {}),
                                      ("plane", {"query_point": False}), ("terrain", {"sampling": "random"})])
def test_density_that_gives_no_points_is_refused(kind, kw):
    """terrain at density 1e-300 wrote a 0-point file without a word (rockface: a numpy traceback)."""
    with pytest.raises(LidarfxError) as exc:
        GENERATORS[kind](density=1e-300, **kw)
    assert str(exc.value) == f"{kind}: the scene has no points at density 1e-300; raise the density"


def test_generate_rejects_unknown_kind_and_bad_parameters():
    with pytest.raises(LidarfxError, match="unknown synthetic scene"):
        synth.generate("castle")
    with pytest.raises(LidarfxError, match="does not take"):
        synth.generate("facade", radius=1.0)
    for bad in ({"density": -1}, {"density": "abc"}, {"sampling": "poisson"}, {"rotation": np.ones((3, 3))},
                {"noise": -0.1}, {"origin": [1, 2]}, {"seed": 1.5}):
        with pytest.raises(LidarfxError):
            synth.generate("plane", **bad)
    # sizes that overflow to infinitely many points: a one-line error (an OverflowError before)
    for bad in ({"density": 1e308}, {"radius": 1e308}, {"radius": 1e308, "sampling": "grid"},
                {"density": 1e308, "sampling": "grid"}):
        with pytest.raises(LidarfxError, match="at most 50,000,000"):
            synth.generate("plane", **bad)
    # scene parameters out of range: one-line errors (tracebacks, hours of work or PiB allocations before)
    for kind, bad in [("facade", {"n_floors": -1}), ("facade", {"glass_fraction": 2}), ("facade", {"noise_fraction": 1e9}),
                      ("facade", {"range_falloff": float("nan")}), ("facade", {"windows_per_floor": 1.5}),
                      ("rockface", {"width": 1e9}), ("rockface", {"overhang": -1}), ("rockface", {"scanner_height": float("nan")}),
                      ("rockface", {"overhang_x": (1.0,)}), ("rockface", {"cell_width": 1e-5}),
                      ("powerline", {"n_trees": 10**9}), ("powerline", {"noise_fraction": -0.1}),
                      ("powerline", {"catenary_a": (900.0, float("inf"))}), ("powerline", {"pylon_height": 0}),
                      ("tower", {"bolt_radius": 0}), ("tower", {"bolt_points": 10**9}), ("tower", {"bolts_per_joint": -1}),
                      ("tower", {"base_width": -1}), ("terrain", {"ditch_radius": 1e9}), ("terrain", {"dike_offset": float("nan")})]:
        with pytest.raises(LidarfxError):
            synth.generate(kind, **bad)
    assert len(synth.generate("facade", n_floors=1, windows_per_floor=0, glass_fraction=0, range_falloff=False)) > 0
    with pytest.raises(LidarfxError):
        synth.edge(angle=0)
    with pytest.raises(LidarfxError):
        synth.facade(classes={"roof": 6})  # same code as the wall
    with pytest.raises(LidarfxError):
        synth.rockface(sets=[{"dip": 80, "dip_direction": 170}])


# --------------------------------------------------------------- structures
@pytest.mark.parametrize("kind", list(SPEC_EIGENVALUES))
def test_analytic_eigenvalues_match_spec_formulas(kind):
    np.testing.assert_allclose(analytic_eigenvalues(kind), SPEC_EIGENVALUES[kind], atol=1e-12)


def test_edge_other_angles_flatten_towards_a_plane():
    np.testing.assert_allclose(analytic_eigenvalues("edge", 180.0), SPEC_EIGENVALUES["plane"], atol=1e-12)
    lam3 = [analytic_eigenvalues("edge", a)[2] for a in (90.0, 120.0, 150.0, 180.0)]
    assert lam3[0] > lam3[1] > lam3[2] > lam3[3] == 0.0
    # the general-angle closed form agrees with the sampled points
    cloud = synth.edge(0.5, angle=135.0, density=16000.0, sampling="grid", seed=0)
    ev, _ = eigen_in_sphere(cloud.xyz, 0.5)
    np.testing.assert_allclose(ev, analytic_eigenvalues("edge", 135.0), rtol=0.01)


@pytest.mark.parametrize("kind", list(SPEC_EIGENVALUES))
def test_grid_structure_eigenvalues_within_1_percent(kind):
    r = 0.5
    density = DENSE.get(kind, 4000.0) / (r if kind in ("line", "line_end") else r * r if kind != "volume" else r**3)
    extent = 1.1 * r if kind == "volume" else None
    cloud = GENERATORS[kind](r, density=density, sampling="grid", rotation="random", extent=extent, seed=11)
    ev, n = eigen_in_sphere(cloud.xyz, r)
    expected = np.array(SPEC_EIGENVALUES[kind])
    np.testing.assert_allclose(ev, expected, rtol=0.01, atol=1e-9, err_msg=f"{kind}: n={n}")
    # the stored truth agrees and the query point sits at the origin
    np.testing.assert_allclose(cloud.meta["truth"]["analytic_eigenvalues"], expected, atol=1e-12)
    np.testing.assert_array_equal(cloud.xyz[0], 0.0)


@pytest.mark.parametrize("kind", ["plane", "plane_border", "edge", "corner", "line", "volume"])
def test_random_structure_eigenvalues_within_2_percent(kind):
    density = {"line": 20000.0, "volume": 40000.0}.get(kind, 40000.0)
    extent = 1.05 if kind == "volume" else 1.5
    cloud = GENERATORS[kind](1.0, density=density, rotation="random", extent=extent, seed=3)
    ev, n = eigen_in_sphere(cloud.xyz, 1.0)
    expected = np.array(SPEC_EIGENVALUES[kind])
    assert n > 15000
    np.testing.assert_allclose(ev, expected, atol=0.02 * expected[0], err_msg=f"{kind}: n={n}")


def test_structure_rotation_noise_and_faces():
    rot = synth.plane(rotation="random", seed=4).meta["truth"]["rotation"]
    cloud = synth.plane(density=20000.0, noise=0.02, rotation=rot, extent=1.2, seed=4)
    normal = np.array(cloud.meta["truth"]["faces"][0]["normal"])
    np.testing.assert_allclose(normal, np.asarray(rot) @ [0, 0, 1], atol=1e-12)
    sel = cloud.xyz[np.linalg.norm(cloud.xyz, axis=1) <= 1.0]
    d = sel @ normal
    assert abs(np.std(d[1:]) - 0.02) < 0.002  # the noise σ across the plane
    ev, _ = eigen_in_sphere(cloud.xyz, 1.0)
    assert abs(ev[2] - 0.02**2) < 0.2 * 0.02**2

    e = synth.edge(angle=120.0, sampling="grid", seed=0)
    assert set(np.unique(e["face"])) == {-1, 0, 1}
    for f in e.meta["truth"]["faces"]:
        pts = e.xyz[e["face"] == f["face"]]
        np.testing.assert_allclose(pts @ np.asarray(f["normal"]), 0.0, atol=1e-12)
    assert angle_deg(*[f["normal"] for f in e.meta["truth"]["faces"]]) == pytest.approx(60.0)
    c = synth.corner(sampling="grid", seed=0)
    assert set(np.unique(c["face"])) == {-1, 0, 1, 2}
    assert np.all(c.xyz >= -1e-12)


# ----------------------------------------------------------------- powerline
def _wire_residuals(cloud):
    out = []
    for w in cloud.meta["truth"]["wires"]:
        p = cloud.xyz[cloud["wire_id"] == w["id"]]
        rel = p[:, :2] - np.asarray(w["start_xy"])
        u = np.asarray(w["direction"])
        s = rel @ u
        across = rel @ np.array([-u[1], u[0]])
        dz = p[:, 2] - catenary_z(s, w["a"], w["s0"], w["c"])
        out.append((w, p, s, across, dz))
    return out


def test_powerline_wires_lie_on_their_catenaries():
    cloud = synth.powerline(noise=0.0, seed=2)
    truth = cloud.meta["truth"]
    assert len(truth["wires"]) == 9 and len(truth["spans"]) == 3 and len(truth["pylons"]) == 4
    for w, p, s, across, dz in _wire_residuals(cloud):
        assert len(p) > 300
        assert np.max(np.abs(dz)) < 1e-6 and np.max(np.abs(across)) < 1e-6
        assert s.min() >= 0 and s.max() <= w["horizontal_length"]
        assert np.all(cloud["span_id"][cloud["wire_id"] == w["id"]] == w["span_id"])
        # the curve passes through both attachment points
        za = catenary_z(0.0, w["a"], w["s0"], w["c"])
        zb = catenary_z(w["horizontal_length"], w["a"], w["s0"], w["c"])
        assert za == pytest.approx(w["attachment_start"][2], abs=1e-6)
        assert zb == pytest.approx(w["attachment_end"][2], abs=1e-6)
        assert 0.5 < w["sag"] < 15.0 and w["ground_clearance"] > 5.0
    assert np.all(cloud["wire_id"][cloud["classification"] != 14] == -1)


def test_powerline_noisy_wire_residual_matches_noise():
    cloud = synth.powerline(noise=0.05, seed=3)
    dz = np.concatenate([r[4] for r in _wire_residuals(cloud)])
    assert 0.04 < np.std(dz) < 0.065 and abs(np.mean(dz)) < 0.01


def test_powerline_classes_trees_and_attachments():
    cloud = synth.powerline(seed=1)
    truth = cloud.meta["truth"]
    for name, count in truth["counts"].items():
        assert count > 0, name
        assert np.count_nonzero(cloud["classification"] == truth["classes"][name]) == count
    near = [t for t in truth["trees"] if t["near_wire"]]
    far = [t for t in truth["trees"] if not t["near_wire"]]
    assert near and far
    assert all(1.5 < t["clearance"] < 5.0 for t in near)
    assert all(t["clearance"] > 3.5 for t in far)
    # each wire starts at the lower end of an insulator of its first pylon
    ins = cloud.xyz[cloud["classification"] == truth["classes"]["insulator"]]
    tree = cKDTree(ins)
    for w in truth["wires"]:
        d, _ = tree.query(w["attachment_start"])
        assert d < 0.5


# ------------------------------------------------------------------ rockface
def test_rockface_facet_normals_match_joint_sets():
    cloud = synth.rockface(seed=4)
    truth = cloud.meta["truth"]
    sets = truth["sets"]
    assert {f["joint_set"] for f in truth["facets"]} == {0, 1, 2}
    for f in truth["facets"]:
        p = cloud.xyz[cloud["facet_id"] == f["id"]]
        assert np.all(cloud["joint_set"][cloud["facet_id"] == f["id"]] == f["joint_set"])
        n = pca_normal(p)
        n = n if n[2] >= 0 else -n  # flipped up, as for dip / dip direction
        dip = math.degrees(math.acos(n[2]))
        ddir = math.degrees(math.atan2(n[0], n[1])) % 360.0
        s = sets[f["joint_set"]]
        assert abs(dip - s["dip"]) < 1.0, f
        assert abs((ddir - s["dip_direction"] + 180.0) % 360.0 - 180.0) < 1.0, f
    assert np.count_nonzero(cloud["joint_set"] == -1) > 0
    assert np.all(cloud["facet_id"][cloud["joint_set"] == -1] == -1)


def test_rockface_overhang_faces_point_down():
    cloud = synth.rockface(seed=4)
    truth = cloud.meta["truth"]
    scanners = np.asarray(truth["scanners"])
    horizon = truth["reference_horizon"]["z"]
    over = [f for f in truth["facets"] if f["overhang"]]
    assert over and set(truth["overhang"]["facet_ids"]) == {f["id"] for f in over}
    for f in truth["facets"]:
        mask = cloud["facet_id"] == f["id"]
        p = cloud.xyz[mask]
        n = pca_normal(p)
        assert angle_deg(n, f["normal"]) < 1.0
        n = n if n @ f["normal"] > 0 else -n  # the outward side ...
        assert np.max((scanners - p.mean(axis=0)) @ n) > 0  # ... is the one a scanner sees
        assert np.all(cloud["overhang"][mask] == int(f["overhang"]))
        if f["overhang"]:
            assert n[2] < -0.5 and f["normal"][2] < 0
            assert p[:, 2].min() > horizon  # an overhang above the reference horizon
        else:
            assert n[2] > 0


def test_rockface_scatter_keeps_each_facet_planar():
    cloud = synth.rockface(scatter=5.0, density=30.0, seed=8)
    truth = cloud.meta["truth"]
    devs = []
    for f in truth["facets"]:
        n = pca_normal(cloud.xyz[cloud["facet_id"] == f["id"]])
        assert angle_deg(n, f["normal"]) < 1.0
        devs.append(angle_deg(f["normal"], truth["sets"][f["joint_set"]]["normal"]))
    assert 2.0 < np.median(devs) < 10.0


# ------------------------------------------------------------------- terrain
def _profile(tree, xyz, xy, normal, offsets, half_bin=0.25, half_length=2.0):
    """Mean height across a line: strips |across - d| < half_bin, |along| < half_length."""
    idx = tree.query_ball_point(xy, float(np.max(np.abs(offsets))) + half_bin + half_length)
    rel = xyz[idx, :2] - xy
    across, along = rel @ normal, rel @ np.array([normal[1], -normal[0]])
    z = xyz[idx, 2]
    out = []
    for d in offsets:
        sel = (np.abs(across - d) < half_bin) & (np.abs(along) < half_length)
        out.append(z[sel].mean() if sel.any() else np.nan)
    return np.array(out)


def test_terrain_dike_crest_is_local_maximum_across_the_dike():
    cloud = synth.terrain(seed=3)
    truth = cloud.meta["truth"]
    tree = cKDTree(cloud.xyz[:, :2])
    half = truth["tile"]["max"][0]
    offsets = np.arange(-12.0, 12.01, 0.5)
    crests = [b for b in truth["breaklines"] if b["kind"] == "dike_crest"]
    assert len(crests) == 2
    checked = 0
    for b in crests:
        pts = np.asarray(b["points"])
        for i in range(1, len(pts) - 1, 5):
            if np.any(np.abs(pts[i, :2]) > half - 15):
                continue
            t = pts[i + 1, :2] - pts[i - 1, :2]
            n = np.array([-t[1], t[0]]) / np.linalg.norm(t)
            h = _profile(tree, cloud.xyz, pts[i, :2], n, offsets)
            centre = h[offsets == 0.0][0]
            assert centre == pytest.approx(pts[i, 2], abs=0.15)
            assert centre >= np.nanmax(h) - 0.15  # nothing across the dike is higher
            assert centre > h[offsets == -6.0][0] + 1.0 and centre > h[offsets == 6.0][0] + 1.0
            checked += 1
    assert checked > 10


def test_terrain_breakline_heights_and_kinds():
    cloud = synth.terrain(density=20.0, noise=0.0, seed=1)
    truth = cloud.meta["truth"]
    kinds = {(b["kind"], b["side"]) for b in truth["breaklines"]}
    assert {k for k, _ in kinds} == {"dike_crest", "dike_toe", "ditch_edge", "ditch_bottom"}
    assert len(kinds) == 8
    tree, z = cKDTree(cloud.xyz[:, :2]), cloud.xyz[:, 2]
    for b in truth["breaklines"]:
        pts = np.asarray(b["points"])
        assert np.all(np.abs(pts[:, :2]) <= truth["tile"]["max"][0] + 1e-9)
        # the nearest point's height differs by at most (steepest slope 0.8 + base) × distance
        d, idx = tree.query(pts[:, :2])
        assert np.all(np.abs(z[idx] - pts[:, 2]) <= 0.85 * d + 1e-6), b["kind"]
        assert np.median(d) < 0.15
    by = {(b["kind"], b["side"]): np.asarray(b["points"]) for b in truth["breaklines"]}
    dh = truth["dike"]["height"]
    crest, toe = by[("dike_crest", "left")], by[("dike_toe", "left")]
    n = min(len(crest), len(toe))
    assert np.median(crest[:n, 2] - toe[:n, 2]) == pytest.approx(dh, abs=0.3)
    lf = cloud["landform"]
    assert np.all(np.isin(lf, list(truth["landforms"].values())))
    assert z[lf == 1].mean() > z[lf == 0].mean() + 2.0 and z[lf == 4].mean() < z[lf == 0].mean()
    assert np.all(cloud["classification"] == 2)


# -------------------------------------------------------------------- facade
def test_facade_every_class_present_with_documented_codes():
    cloud = synth.facade(seed=1)
    truth = cloud.meta["truth"]
    assert truth["classes"] == {"ground": 2, "vegetation": 5, "wall": 6, "noise": 7, "roof": 64,
                                "window": 65, "clutter": 66}
    cls = cloud["classification"]
    for name, code in truth["classes"].items():
        assert np.count_nonzero(cls == code) > 100, name
        assert truth["counts"][name] == np.count_nonzero(cls == code)
    assert set(np.unique(cls)) == set(truth["classes"].values())
    assert len(truth["scanner"]) == 3
    # geometry matches the labels: wall on y = 0, windows behind it, ground at z = 0
    wall = cloud.xyz[cls == 6]
    assert np.all(np.abs(wall[:, 1]) < 0.05)
    win = cloud.xyz[cls == 65]
    assert np.all((win[:, 1] > -0.05) & (win[:, 1] < 0.3))
    assert np.all(np.abs(cloud.xyz[cls == 2][:, 2]) < 0.05)
    # noise points are isolated outliers
    noise = cls == 7
    d, _ = cKDTree(cloud.xyz[~noise]).query(cloud.xyz[noise])
    assert d.min() > 0.25


def test_facade_class_override():
    cloud = synth.facade(density=60.0, classes={"clutter": 1, "roof": 20}, seed=0)
    assert cloud.meta["truth"]["classes"]["clutter"] == 1
    assert np.count_nonzero(cloud["classification"] == 20) > 0


# --------------------------------------------------------------------- tower
def _segment_distance(p, a, b):
    a, b = np.asarray(a), np.asarray(b)
    d = b - a
    t = np.clip((p - a) @ d / (d @ d), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * d), axis=1)


def test_tower_points_on_members_and_bolts():
    cloud = synth.tower(density=400.0, seed=2)
    truth = cloud.meta["truth"]
    parts = truth["parts"]
    for name, code in parts.items():
        assert np.count_nonzero(cloud["part"] == code) > 0, name
    for m in truth["members"]:
        p = cloud.xyz[cloud["member_id"] == m["id"]]
        assert len(p) > 10
        assert np.all(cloud["part"][cloud["member_id"] == m["id"]] == parts[m["part"]])
        assert _segment_distance(p, m["start"], m["end"]).max() < m["width"] * 1.5
    bolt = cloud["part"] == parts["bolt"]
    assert np.all(cloud["member_id"][bolt] == -1)
    for b in truth["bolts"][::17]:
        p = cloud.xyz[cloud["bolt_id"] == b["id"]]
        assert len(p) == cloud.meta["truth"]["params"]["bolt_points"]
        assert np.linalg.norm(p - b["centre"], axis=1).max() < 0.03
    legs = [m for m in truth["members"] if m["part"] == "leg"]
    assert len(legs) == 8  # 4 legs + 4 peak members
    assert len([m for m in truth["members"] if m["part"] == "arm"]) == 16


# ----------------------------------------------------------------------- CLI
def _cli(argv):
    from lidarfx.cli import synth as cli_synth

    parser = argparse.ArgumentParser(prog="lidarfx")
    cli_synth.register(parser.add_subparsers())
    args = parser.parse_args(["synth", *argv])
    return args.func(args)


def test_cli_writes_cloud_and_truth(tmp_path, capsys):
    import lidarfx

    out = tmp_path / "edge.laz"
    assert _cli(["edge", str(out), "--seed", "3", "--radius", "0.5", "--angle", "120", "--sampling", "grid",
                 "--origin", "1000,2000,30", "-p", "query_point=false"]) == 0
    truth = json.loads((tmp_path / "edge.laz.truth.json").read_text())
    assert truth["params"]["angle"] == 120.0 and truth["params"]["query_point"] is False
    assert truth["origin"] == [1000.0, 2000.0, 30.0]
    cloud = lidarfx.read(out)
    expected = synth.edge(0.5, angle=120.0, sampling="grid", origin=[1000, 2000, 30], query_point=False, seed=3)
    assert len(cloud) == len(expected)
    np.testing.assert_allclose(np.sort(cloud.xyz[:, 2]), np.sort(expected.xyz[:, 2]), atol=2e-3)
    assert "edge" in capsys.readouterr().out


def test_cli_list_and_errors(tmp_path, capsys):
    assert _cli(["--list"]) == 0
    listed = capsys.readouterr().out
    for name in GENERATORS:
        assert name in listed
    with pytest.raises(LidarfxError, match="unknown synthetic scene"):
        _cli(["castle", str(tmp_path / "x.laz")])
    with pytest.raises(LidarfxError, match="does not take"):
        _cli(["facade", str(tmp_path / "x.laz"), "--radius", "1"])
    with pytest.raises(LidarfxError):
        _cli(["plane", str(tmp_path / "x.laz"), "--origin", "1,2"])
    assert not list(tmp_path.iterdir())
