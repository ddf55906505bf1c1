"""synth.powerline options for testing wire extractors: bundled conductors, the earth wire, cranes.

Every check measures the points (not only the truth records), and the defaults must give exactly
the scene of the generator before these options existed.
"""
from __future__ import annotations

import hashlib
import itertools
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarfx import LidarfxError, synth
from lidarfx.synth import catenary_through, catenary_z
from lidarfx.synth.powerline import bundle_offsets

WIRE, CRANE, PYLON = 14, 26, 15

# synth.powerline(n_spans=1, density=0.5, seed=5): xyz rounded to mm and the four attributes of
# the generator before bundles / earth wire / cranes, computed with that generator (17 834 points)
DEFAULT_DIGEST = "5c41cd5e8e216219a1b63df41cbb787c008b3fc79bddb6da5d37d5ca818cecaa"
OLD_ATTRIBUTES = ("classification", "wire_id", "span_id", "pylon_id")


def _digest(cloud) -> str:
    h = hashlib.sha256()
    h.update(np.round(cloud.xyz * 1000.0).astype("<i8").tobytes())
    for name in OLD_ATTRIBUTES:
        h.update(name.encode())
        h.update(np.asarray(cloud[name]).astype("<i4").tobytes())
    return h.hexdigest()


def _frame(start_xy, direction, pts):
    """(s, across) of points in a span-local frame: along the chord, and to its right."""
    u = np.asarray(direction, float)
    rel = pts[:, :2] - np.asarray(start_xy, float)
    return rel @ u, rel @ np.array([u[1], -u[0]])


def _phase_curve(phase):
    """Chord frame and catenary (s0, c) of a phase centre (the bundle axis)."""
    A, B = np.asarray(phase["attachment_start"]), np.asarray(phase["attachment_end"])
    d = B[:2] - A[:2]
    L = float(np.linalg.norm(d))
    s0, c = catenary_through(A[2], B[2], L, phase["a"])
    return A[:2], d / L, L, s0, c


# ------------------------------------------------------------------ defaults
def test_defaults_give_the_scene_of_the_plain_generator():
    a = synth.powerline(n_spans=1, density=0.5, seed=5)
    assert len(a) == 17834 and _digest(a) == DEFAULT_DIGEST
    b = synth.powerline(n_spans=1, density=0.5, seed=5, bundle=1, bundle_spacing=0.4, earth_wire=False, n_cranes=0)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    for name in a.names:
        np.testing.assert_array_equal(a[name], b[name])
    # the new attributes: phase_id = wire_id with one conductor per phase; no crane
    np.testing.assert_array_equal(a["phase_id"], a["wire_id"])
    assert np.all(a["crane_id"] == -1)
    truth = a.meta["truth"]
    assert "crane" not in truth["counts"] and truth["classes"]["crane"] == CRANE
    assert truth["cranes"] == [] and truth["n_phases"] == 3
    assert {w["kind"] for w in truth["wires"]} == {"phase"}


def test_options_keep_the_rest_of_the_scene():
    """Without noise, ground, pylons and insulators are the same points whatever the new options
    (the main random stream is untouched) and each phase keeps its catenary parameter; with the
    earth wire and cranes (which leave the phase conductors alone) the trees stay the same too."""
    plain = synth.powerline(n_spans=2, density=0.5, noise=0.0, seed=8)
    n = int(np.count_nonzero(np.isin(plain["classification"], [2, 15, 16])))
    plain_a = [w["a"] for w in plain.meta["truth"]["wires"]]
    for opts in ({"bundle": 3}, {"earth_wire": True, "n_cranes": 1}):
        rich = synth.powerline(n_spans=2, density=0.5, noise=0.0, seed=8, **opts)
        np.testing.assert_array_equal(plain.xyz[:n], rich.xyz[:n])
        np.testing.assert_array_equal(plain["classification"][:n], rich["classification"][:n])
        assert plain.meta["truth"]["pylons"] == rich.meta["truth"]["pylons"]
        assert [p["a"] for s in rich.meta["truth"]["spans"] for p in s["phases"] if p["kind"] == "phase"] == plain_a
    assert plain.meta["truth"]["trees"] == rich.meta["truth"]["trees"]


# ------------------------------------------------------------------- bundles
def test_bundle_offsets_shapes():
    np.testing.assert_array_equal(bundle_offsets(1, 0.4), [[0.0, 0.0]])
    np.testing.assert_allclose(bundle_offsets(2, 0.4), [[-0.2, 0.0], [0.2, 0.0]])
    tri = bundle_offsets(3, 0.5)
    sides = [np.linalg.norm(tri[i] - tri[(i + 1) % 3]) for i in range(3)]
    np.testing.assert_allclose(sides, 0.5)
    np.testing.assert_allclose(tri.mean(axis=0), 0.0, atol=1e-12)
    assert tri[2, 1] > 0 > tri[0, 1] == tri[1, 1]  # two below, one above
    np.testing.assert_allclose(bundle_offsets(4, 0.4), [[-0.2, -0.2], [0.2, -0.2], [0.2, 0.2], [-0.2, 0.2]])


def test_twin_bundle_two_catenaries_per_phase_spacing_at_mid_span():
    spacing, sigma = 0.4, 0.03
    cloud = synth.powerline(n_spans=2, density=0.5, bundle=2, bundle_spacing=spacing, noise=sigma, seed=11)
    truth = cloud.meta["truth"]
    wires = {w["id"]: w for w in truth["wires"]}
    assert len(wires) == 2 * 3 * 2 and truth["n_phases"] == 3
    ids = cloud["wire_id"]
    assert set(np.unique(ids[ids >= 0])) == set(wires)
    for span in truth["spans"]:
        assert len(span["phases"]) == 3
        for phase in span["phases"]:
            subs = [wires[i] for i in phase["wire_ids"]]
            assert [w["bundle_index"] for w in subs] == [0, 1]
            assert all(w["phase_id"] == phase["phase_id"] == span["id"] * 3 + phase["phase"] for w in subs)
            assert subs[0]["a"] == subs[1]["a"] == phase["a"]
            start, u, L, _, _ = _phase_curve(phase)
            mid = []
            for w in subs:
                mask = ids == w["id"]
                p = cloud.xyz[mask]
                assert np.all(cloud["phase_id"][mask] == phase["phase_id"])
                assert np.all(cloud["span_id"][mask] == span["id"])
                assert len(p) == round(w["horizontal_length"] * 3.0)  # wire_density per sub-conductor
                # on its own curve: residuals are the noise
                s, across = _frame(w["start_xy"], w["direction"], p)
                dz = p[:, 2] - catenary_z(s, w["a"], w["s0"], w["c"])
                assert sigma * 0.7 < np.std(dz) < sigma * 1.3 and abs(np.mean(dz)) < 0.01
                assert sigma * 0.7 < np.std(across) < sigma * 1.3 and abs(np.mean(across)) < 0.01
                # across and height relative to the bundle axis, 10 m around mid-span
                s_c, across_c = _frame(start, u, p)
                near = np.abs(s_c - L / 2) < 5.0
                assert near.sum() > 15
                mid.append((across_c[near].mean(), p[near, 2].mean()))
            (x0, z0), (x1, z1) = mid
            assert x1 - x0 == pytest.approx(spacing, abs=0.02)  # side by side ...
            assert z1 - z0 == pytest.approx(0.0, abs=0.03)  # ... at the same height
            assert (x0 + x1) / 2 == pytest.approx(0.0, abs=0.02)  # centred on the phase


@pytest.mark.parametrize("bundle", [3, 4])
def test_bundle_sub_conductors_sit_at_their_offsets(bundle):
    spacing = 0.5
    cloud = synth.powerline(n_spans=1, density=0.5, bundle=bundle, bundle_spacing=spacing, noise=0.02, seed=4)
    truth = cloud.meta["truth"]
    wires = {w["id"]: w for w in truth["wires"]}
    expected = bundle_offsets(bundle, spacing)
    np.testing.assert_allclose(truth["bundle"]["offsets"], expected)
    for phase in truth["spans"][0]["phases"]:
        assert len(phase["wire_ids"]) == bundle
        start, u, _, s0, c = _phase_curve(phase)
        centres = []
        for w in (wires[i] for i in phase["wire_ids"]):
            p = cloud.xyz[cloud["wire_id"] == w["id"]]
            s, across = _frame(start, u, p)
            up = p[:, 2] - catenary_z(s, phase["a"], s0, c)  # the bundle axis is the phase's catenary
            centres.append((across.mean(), up.mean()))
            # attachment points: the phase point plus the offset
            off = np.asarray(w["attachment_start"]) - np.asarray(phase["attachment_start"])
            assert np.hypot(off[0], off[1]) == pytest.approx(abs(w["bundle_offset"][0]), abs=1e-9)
            assert off[2] == pytest.approx(w["bundle_offset"][1], abs=1e-9)
        np.testing.assert_allclose(centres, expected, atol=0.01)
        centres = np.array(centres)
        d = sorted(np.linalg.norm(centres[i] - centres[j]) for i in range(bundle) for j in range(i + 1, bundle))
        if bundle == 4:  # a square: four sides and two diagonals
            np.testing.assert_allclose(d[:4], spacing, atol=0.02)
            np.testing.assert_allclose(d[4:], spacing * math.sqrt(2), atol=0.02)
        else:  # an equilateral triangle, apex up
            np.testing.assert_allclose(d, spacing, atol=0.02)
            assert centres[2, 1] > centres[0, 1] + 0.3 * spacing


# ---------------------------------------------------------------- earth wire
def test_earth_wire_on_the_pylon_peaks_above_all_phases():
    cloud = synth.powerline(n_spans=2, density=0.5, earth_wire=True, noise=0.02, seed=6)
    truth = cloud.meta["truth"]
    assert truth["n_phases"] == 4
    earth = [w for w in truth["wires"] if w["kind"] == "earth"]
    assert len(earth) == 2 and all(w["phase"] == 3 for w in earth)
    ids = cloud["wire_id"]
    for w in earth:
        k = w["span_id"]
        assert w["phase_id"] == 4 * k + 3 and w["id"] == truth["spans"][k]["wire_ids"][-1]
        p = cloud.xyz[ids == w["id"]]
        assert np.all(cloud["classification"][ids == w["id"]] == WIRE)
        assert np.all(cloud["phase_id"][ids == w["id"]] == w["phase_id"])
        assert len(p) == round(w["horizontal_length"] * 1.5)  # half the wire density
        s, across = _frame(w["start_xy"], w["direction"], p)
        dz = p[:, 2] - catenary_z(s, w["a"], w["s0"], w["c"])
        assert np.std(dz) < 0.03 and np.std(across) < 0.03
        # attached at the peaks: the highest pylon points of both pylons
        for pid, end in ((k, "attachment_start"), (k + 1, "attachment_end")):
            pyl = cloud.xyz[(cloud["pylon_id"] == pid) & (cloud["classification"] == PYLON)]
            top = pyl[np.argmax(pyl[:, 2])]
            assert np.linalg.norm(top - np.asarray(w[end])) < 0.3
            np.testing.assert_allclose(w[end], truth["pylons"][pid]["peak"])
        # above every phase conductor of its span, near the pylons and all along the span
        phases = np.isin(ids, [v["id"] for v in truth["wires"] if v["span_id"] == k and v["kind"] == "phase"])
        q = cloud.xyz[phases]
        sq, _ = _frame(w["start_xy"], w["direction"], q)
        L = w["horizontal_length"]
        for lo, hi in ((0.0, 5.0), (L - 5.0, L), (0.0, L)):
            e, f = p[(s >= lo) & (s <= hi)], q[(sq >= lo) & (sq <= hi)]
            assert len(e) and len(f)
            assert e[:, 2].min() > f[:, 2].max() - (0.0 if hi - lo < L else 10.0)
        bins = np.linspace(0.0, L, 21)
        for b0, b1 in itertools.pairwise(bins):
            e, f = p[(s >= b0) & (s < b1)], q[(sq >= b0) & (sq < b1)]
            if len(e) and len(f):
                assert e[:, 2].min() > f[:, 2].max() + 2.0
        # stacked above the line axis, between the phases in plan
        _, across_q = _frame(w["start_xy"], w["direction"], q)
        assert across_q.min() < across.mean() < across_q.max()


# -------------------------------------------------------------------- cranes
@pytest.fixture(scope="module")
def crane_scene():
    return synth.powerline(n_spans=2, density=1.0, n_cranes=3, bundle=2, earth_wire=True, seed=9)


def test_crane_points_class_and_clearance(crane_scene):
    cloud, truth = crane_scene, crane_scene.meta["truth"]
    cls, cid = cloud["classification"], cloud["crane_id"]
    assert truth["classes"]["crane"] == CRANE and len(truth["cranes"]) == 3
    np.testing.assert_array_equal(cls == CRANE, cid >= 0)
    assert truth["counts"]["crane"] == np.count_nonzero(cls == CRANE)
    for crane in truth["cranes"]:
        assert crane["n_points"] == np.count_nonzero(cid == crane["id"]) > 1000
    assert np.all(cloud["wire_id"][cls == CRANE] == -1) and np.all(cloud["phase_id"][cls == CRANE] == -1)
    # no crane point within 8 m in plan of any wire or pylon point
    crane_xy = cloud.xyz[cls == CRANE, :2]
    for code in (WIRE, PYLON):
        d, _ = cKDTree(cloud.xyz[cls == code, :2]).query(crane_xy)
        assert d.min() >= 8.0, code


def test_crane_mast_and_jib_geometry(crane_scene):
    cloud, truth = crane_scene, crane_scene.meta["truth"]
    pylons = truth["pylons"]
    wire_xy = cloud.xyz[cloud["classification"] == WIRE, :2]
    for crane in truth["cranes"]:
        p = cloud.xyz[cloud["crane_id"] == crane["id"]]
        base = np.asarray(crane["base"])
        top = base[2] + crane["mast_height"]
        assert 20.0 <= crane["mast_height"] <= 30.0
        # the mast: a vertical 1.6 m square lattice standing on the ground
        mast = p[p[:, 2] < top - 2.5]
        r = np.linalg.norm(mast[:, :2] - base[:2], axis=1)
        assert r.max() < 0.8 * math.sqrt(2) + 0.2
        assert mast[:, 2].min() == pytest.approx(base[2], abs=0.2)
        assert np.ptp(mast[:, 2]) > crane["mast_height"] - 3.0
        az = math.radians(crane["jib_azimuth"])
        jx, jy = np.array([math.sin(az), math.cos(az)]), np.array([-math.cos(az), math.sin(az)])
        for sx in (-1, 1):  # four corner chords: points near each corner of the section (sides along the jib)
            for sy in (-1, 1):
                corner = base[:2] + 0.8 * (sx * jx + sy * jy)
                assert np.count_nonzero(np.linalg.norm(mast[:, :2] - corner, axis=1) < 0.15) > 50
        ground = cloud.xyz[cloud["classification"] == 2]
        near_ground = ground[np.linalg.norm(ground[:, :2] - base[:2], axis=1) < 4.0]
        if len(near_ground) > 5:
            assert base[2] == pytest.approx(np.median(near_ground[:, 2]), abs=0.3)
        # beside the line: the mast 12-20 m (at least) beside the outermost wire
        d, _ = cKDTree(wire_xy).query(base[:2])
        assert d >= 12.0 - 0.5
        # the jib (with the counter-jib): a long, straight, horizontal truss at the mast top
        jib = p[p[:, 2] > top - 0.15]
        centre = jib.mean(axis=0)
        _, vecs = np.linalg.eigh(np.cov((jib - centre).T))
        e = vecs[:, -1]
        assert abs(e[2]) < 0.05
        along = (jib - base) @ e
        off = np.linalg.norm((jib - centre) - np.outer((jib - centre) @ e, e), axis=1)
        assert off.max() < 1.6  # within the 1.2 m section (and the 2 m counterweight)
        reach = max(along.max(), -along.min())  # the jib side of the mast
        assert reach >= 35.0 and reach == pytest.approx(crane["jib_length"], abs=0.6)
        assert min(along.max(), -along.min()) == pytest.approx(crane["counter_jib_length"], abs=0.6)
        assert np.ptp(jib[:, 2]) < 1.2 + 0.3  # flat: the triangular section's depth (1.04 m)
        # roughly parallel to its span: within +-20 degrees
        a, b = np.asarray(pylons[crane["span_id"]]["base"]), np.asarray(pylons[crane["span_id"] + 1]["base"])
        u = (b - a)[:2] / np.linalg.norm((b - a)[:2])
        h = e[:2] / np.linalg.norm(e[:2])
        angle = math.degrees(math.acos(min(1.0, abs(float(h @ u)))))
        assert angle <= 20.0 + 0.5
        assert angle == pytest.approx(abs(crane["jib_angle_to_line"]), abs=0.5)
        tip = np.asarray(crane["jib_end"])
        assert np.min(np.linalg.norm(jib - tip, axis=1)) < 0.9  # the truth tip is where the points end


def test_cranes_do_not_touch_each_other_or_trees(crane_scene):
    cloud = crane_scene
    cid = cloud["crane_id"]
    for i in range(3):
        for j in range(i + 1, 3):
            d, _ = cKDTree(cloud.xyz[cid == i]).query(cloud.xyz[cid == j])
            assert d.min() > 3.5
    crane = cloud.xyz[cid >= 0]
    veg = cloud.xyz[cloud["classification"] == 5]
    d, _ = cKDTree(veg).query(crane)
    assert d.min() > 1.0


def test_crane_determinism_and_too_many_cranes():
    a = synth.powerline(n_spans=1, density=0.5, n_cranes=2, seed=3)
    b = synth.powerline(n_spans=1, density=0.5, n_cranes=2, seed=3)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_array_equal(a["crane_id"], b["crane_id"])
    assert a.meta["truth"]["cranes"] == b.meta["truth"]["cranes"]
    with pytest.raises(LidarfxError, match="could not place crane"):
        synth.powerline(n_spans=1, density=0.5, n_cranes=10, seed=3)


@pytest.mark.parametrize("bad, message", [
    ({"bundle": 0}, "bundle must be in 1 .. 4"), ({"bundle": 5}, "bundle must be in 1 .. 4"),
    ({"bundle": 1.5}, "bundle must be a whole number"), ({"bundle_spacing": 0}, "bundle_spacing must be > 0"),
    ({"bundle_spacing": 2.5}, "bundle_spacing must be at most 2"), ({"n_cranes": 11}, "n_cranes must be in 0 .. 10"),
    ({"n_cranes": -1}, "n_cranes must be in 0 .. 10"), ({"earth_wire": "yes"}, "earth_wire must be true or false"),
])
def test_new_parameters_are_checked(bad, message):
    with pytest.raises(LidarfxError, match=message):
        synth.powerline(n_spans=1, density=0.5, **bad)
