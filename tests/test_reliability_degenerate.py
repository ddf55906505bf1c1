"""Degenerate clouds through every command and the main API functions (docs/reliability.md,
"Degenerate clouds").

Clouds of 0, 1 and 2 points, 50 copies of one point, a line, a flat square, a vertical wall, a
small scene at UTM coordinates (x 500 000, y 5 500 000) and the same scene near 0, and a sliver
(10 km long, 1 mm wide).  Contract: exit 0 with defined results (NaN where a value is not
computable), or exit 2 with one line ``lidarfx: error: ...`` and nothing left in the output folder;
never a traceback.  Which runs are refused, and why, is fixed in :data:`REFUSED`.  The API functions
return a result or raise :class:`~lidarfx.LidarfxError`, nothing else.
"""
from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarfx
from lidarfx import LidarfxError
from lidarfx.ground import dtm, height_above_ground

SHIFT = np.array([500_000.0, 5_500_000.0, 0.0])
"""UTM-sized offset of the ``utm`` cloud from the ``near`` cloud."""

CLOUDS = ["zero", "one", "two", "dup", "line", "flat", "wall", "near", "utm", "sliver"]


# ------------------------------------------------------------------------------ the clouds
def _write_las(path: Path, xyz: np.ndarray, cls: np.ndarray | None = None, scale: float = 0.01,
               offset=(0.0, 0.0, 0.0)) -> None:
    h = laspy.LasHeader(point_format=6, version="1.4")
    h.scales = [scale] * 3
    h.offsets = list(offset)
    las = laspy.LasData(h)
    n = len(xyz)
    if n:
        las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        # ground and building alternate: every cloud holds two classes (classify train needs them)
        las.classification = cls if cls is not None else np.where(np.arange(n) % 2, 6, 2).astype(np.uint8)
        las.return_number = np.ones(n, np.uint8)
        las.number_of_returns = np.ones(n, np.uint8)
    las.write(str(path))


def scene() -> tuple[np.ndarray, np.ndarray]:
    """A 30 m square of gently sloping, slightly rough ground (class 2, scattered about a 0.5 m grid)
    with a box house (8 m square, 5 m walls and a roof tilted along x on a 0.37 m grid; class 6),
    rounded to the centimetre.  No two points are exactly 1, 2 or 3 m apart: a neighbour on the
    sphere of a radius would be in or out by rounding."""
    rng = np.random.default_rng(0)
    g = np.mgrid[0:30:0.5, 0:30:0.5].reshape(2, -1).T + rng.uniform(-0.2, 0.2, (3600, 2))
    ground = np.column_stack([g, 0.02 * g[:, 0] + rng.normal(0, 0.02, len(g))])
    r = np.mgrid[10:18:0.37, 10:18:0.37].reshape(2, -1).T
    roof = np.column_stack([r, 5 + 0.3 * (r[:, 0] - 10)])
    t, z = (a.ravel() for a in np.meshgrid(np.arange(0, 8, 0.37), np.arange(0.37, 5, 0.37)))
    walls = [np.column_stack([np.full(t.size, 10.0), 10 + t, z]), np.column_stack([np.full(t.size, 18.0), 10 + t, z]),
             np.column_stack([10 + t, np.full(t.size, 10.0), z]), np.column_stack([10 + t, np.full(t.size, 18.0), z])]
    xyz = np.round(np.vstack([ground, roof, *walls]), 2)
    cls = np.r_[np.full(len(ground), 2), np.full(len(xyz) - len(ground), 6)].astype(np.uint8)
    return xyz, cls


def sliver_xyz() -> np.ndarray:
    """Two rows of points 1 m apart along x over 10 km, the second row 1 mm north of the first and
    shifted by half a spacing: a strip 10 km long and 1 mm wide (20 000 points)."""
    x = np.arange(0.0, 10_000.0, 1.0)
    return np.vstack([np.column_stack([x, np.zeros_like(x), np.zeros_like(x)]),
                      np.column_stack([x + 0.5, np.full_like(x, 0.001), np.zeros_like(x)])])


@pytest.fixture(scope="module")
def clouds(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("degenerate")
    _write_las(d / "zero.las", np.zeros((0, 3)))
    _write_las(d / "one.las", np.array([[1.0, 2.0, 3.0]]))
    _write_las(d / "two.las", np.array([[1.0, 2.0, 3.0], [2.0, 2.5, 3.5]]))
    _write_las(d / "dup.las", np.tile([[1.0, 2.0, 3.0]], (50, 1)))
    t = np.linspace(0.0, 20.0, 201)
    _write_las(d / "line.las", np.column_stack([t, 0.5 * t, 0.2 * t]))  # 0.11 m spacing, oblique
    g = np.mgrid[0:10:0.25, 0:10:0.25].reshape(2, -1).T
    _write_las(d / "flat.las", np.column_stack([g, np.full(len(g), 1.0)]))
    _write_las(d / "wall.las", np.column_stack([g[:, 0], np.full(len(g), 3.0), g[:, 1]]))
    xyz, cls = scene()
    _write_las(d / "near.las", xyz, cls)
    _write_las(d / "utm.las", xyz + SHIFT, cls, offset=SHIFT)
    _write_las(d / "sliver.las", sliver_xyz(), scale=0.0001)
    return d


# ------------------------------------------------------------------------ every command
def _bounds(path: Path) -> tuple[float, float, float]:
    las = laspy.read(str(path)) if path.exists() else None
    if las is None or not len(las.points):
        return 0.0, 1.0, 0.0
    x0, x1 = float(las.x.min()), float(las.x.max())
    return x0, max(x1, x0 + 1.0), float(las.y.min() + las.y.max()) / 2


SEGMENT = ["--normal-radius", "1.1", "--growing-radius", "0.85", "--max-distance", "0.11", "--min-width", "0.85"]
"""Segment parameters for these clouds (spacing 0.25 to 1 m; the defaults are for 1 cm TLS)."""


def command_lines(path: Path) -> dict[str, list[str]]:
    """Every command that reads a cloud, with its outputs in ``out/`` (relative to the cloud's folder)."""
    f = path.name
    x0, x1, ym = _bounds(path)
    return {
        "info": ["info", f, "--json"],
        "convert": ["convert", f, "out/o.ply"],
        "features": ["features", f, "out/o.laz", "-r", "1", "-q"],
        "features-all": ["features", f, "out/o.laz", "-r", "1.003", "-r", "2", "-f", "all", "-q"],
        "features-knn": ["features", f, "out/o.laz", "-n", "knn", "-k", "8", "-f", "eigen,plane,quadric,distribution",
                         "-q"],
        "features-cylinder": ["features", f, "out/o.laz", "-n", "cylinder", "-r", "1", "-f", "eigen,height,density",
                              "-q"],
        "segment": ["segment", f, "out/o.laz", *SEGMENT, "-q"],
        "select": ["select", f, "out/o.laz", "-w", "z > 0.5 and classification == 2", "-q"],
        "ground": ["ground", f, "out/o.laz", "--hag", "-q"],
        "ground-eval": ["ground-eval", f, "--json", "-q"],
        "dtm": ["dtm", f, "out/o.tif", "-q"],
        "thin": ["thin", f, "out/o.laz", "--cell", "0.5", "-q"],
        "eigenclass": ["eigenclass", f, "out/o.laz", "-r", "1.003", "-q"],
        "eigenclass-auto": ["eigenclass", f, "out/o.laz", "-q"],
        "colour": ["colour", f, "out/o.laz", "--picture", "out/o.png", "-q"],
        "render": ["render", f, "out/o.png", "--size", "320x240", "--title", "t", "-q"],
        "section": ["section", f, "out/o.laz", "--from", f"{x0},{ym}", "--to", f"{x1},{ym}", "--width", "1",
                    "--image", "out/o.png", "--by", "z", "-q"],
        "predict": ["classify", "predict", f, "out/o.laz", "--model", "default", "-q"],
        "train": ["classify", "train", f, "--model", "out/m.skops", "--classes", "2,6", "-f", "eigen,z", "-r", "1",
                  "--classifier", "rf", "--n-estimators", "5", "--terrain-augment", "0", "-q"],
        "edges": ["edges", f, "out/o.geojson", "-r", "1", "--csv", "--dxf", "out/o.dxf", "-q"],
        "breaklines": ["breaklines", f, "out/o.geojson", "--csv", "--dxf", "out/o.dxf", "--picture", "out/o.png",
                       "-q"],
        "powerlines": ["powerlines", f, "out/pl", "--load-case", "temp=80", "-q"],
        "discontinuities": ["discontinuities", f, "out/dc", "-q"],
        "parts": ["parts", f, "out/pa", "-q"],
        "members": ["members", f, "out/o.geojson", "--csv", "--dxf", "out/o.dxf", "--picture", "out/o.png", "-q"],
        "report": ["report", f, "out/rep", "-r", "1", "--no-picture", "-q"],
    }


COMMANDS = list(command_lines(Path("x.las")))

_NEEDS_RADIUS = "fewer than 2 points; give a radius"
_NO_SEGMENT = "no plane segment found"
_NO_PLANE = "no local plane at radius"
REFUSED: dict[tuple[str, str], str] = {
    **{("zero", c): m for c, m in {
        "features": "no points", "features-all": "no points", "features-knn": "no points",
        "features-cylinder": "no points", "segment": "empty", "ground": "no points", "ground-eval": "no points",
        "dtm": "no ground points", "eigenclass": "no points", "eigenclass-auto": "empty", "colour": "no points",
        "render": "no points", "section": "no point lies in the section", "predict": "empty", "train": "no usable points",
        "edges": "empty", "breaklines": "only 0 ground points", "powerlines": "no points",
        "discontinuities": "0 points; a rock face needs at least 3", "parts": "0 points; small parts need at least 3",
        "members": "empty", "report": "empty"}.items()},
    ("one", "segment"): _NO_SEGMENT, ("one", "eigenclass-auto"): _NEEDS_RADIUS, ("one", "colour"): _NEEDS_RADIUS,
    ("one", "train"): "no training points of 'building'", ("one", "breaklines"): "only 1 ground points",
    ("one", "powerlines"): "fewer than 3 ground points", ("one", "discontinuities"): "1 points; a rock face needs",
    ("one", "parts"): "1 points; small parts need at least 3",
    ("two", "segment"): _NO_SEGMENT, ("two", "breaklines"): "only 1 ground points",
    ("two", "powerlines"): "fewer than 3 ground points", ("two", "discontinuities"): "2 points; a rock face needs",
    ("two", "parts"): "2 points; small parts need at least 3",
    ("dup", "eigenclass-auto"): "the points coincide", ("dup", "colour"): "the points coincide",
    ("dup", "breaklines"): "only 25 ground points", ("dup", "discontinuities"): "the points coincide",
    ("dup", "parts"): "the points coincide", ("dup", "segment"): _NO_SEGMENT,
    ("line", "segment"): _NO_SEGMENT, ("line", "parts"): _NO_PLANE,
    ("flat", "parts"): _NO_PLANE, ("wall", "parts"): _NO_PLANE,
    ("near", "parts"): _NO_PLANE, ("utm", "parts"): _NO_PLANE,
    ("sliver", "segment"): _NO_SEGMENT, ("sliver", "parts"): _NO_PLANE,
}
"""The runs that exit 2, with a part of their one-line error; every other run exits 0."""

SLOW = {("sliver", c) for c in ("predict", "discontinuities", "parts", "train", "edges", "ground")}
"""Runs of several seconds each (the sliver's 20 000 points): marked slow."""


def _outputs(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def run_in(folder: Path, argv: list[str], run_cli) -> tuple[int, str, str]:
    import os

    cwd = os.getcwd()
    os.chdir(folder)
    try:
        return run_cli(argv)
    finally:
        os.chdir(cwd)


@pytest.mark.parametrize("cloud,command", [
    pytest.param(c, k, marks=[pytest.mark.slow] if (c, k) in SLOW else []) for c in CLOUDS for k in COMMANDS])
def test_every_command_on_every_degenerate_cloud(clouds, tmp_path, run_cli, cloud, command):
    import shutil

    src = clouds / f"{cloud}.las"
    shutil.copy(src, tmp_path / src.name)
    (tmp_path / "out").mkdir()
    argv = command_lines(tmp_path / src.name)[command]
    t0 = time.perf_counter()
    rc, out, err = run_in(tmp_path, argv, run_cli)
    took = time.perf_counter() - t0
    assert "Traceback" not in err and "Traceback" not in out
    assert (tmp_path / src.name).read_bytes() == src.read_bytes(), "the input changed"
    want = REFUSED.get((cloud, command))
    if want is None:
        assert rc == 0, (rc, err)
        assert "error" not in err
    else:
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and lines[0].startswith("lidarfx: error: "), (rc, err)
        assert want in lines[0], lines[0]
        assert _outputs(tmp_path / "out") == [], "output left behind after an error"
    assert took < 300, f"{took:.0f} s"  # generous: the first run of a kernel may compile it


# ------------------------------------------------------------------------ defined results
def _features(clouds: Path, name: str, tmp_path: Path, run_cli, *args: str) -> lidarfx.PointCloud:
    out = tmp_path / f"{name}-{len(list(tmp_path.iterdir()))}.laz"
    rc, _, err = run_cli(["features", str(clouds / f"{name}.las"), str(out), *args, "-q"])
    assert rc == 0, err
    return lidarfx.read(out)


EIGEN = ["eigenvalue1", "linearity", "planarity", "sphericity", "verticality", "normal_x", "normal_z", "slope"]


@pytest.mark.parametrize("cloud", ["one", "two"])
@pytest.mark.parametrize("how", [["-r", "1"], ["-n", "knn", "-k", "8"], ["-n", "cylinder", "-r", "1"]])
def test_fewer_than_three_points_give_nan_eigen_features(clouds, tmp_path, run_cli, cloud, how):
    f = _features(clouds, cloud, tmp_path, run_cli, *how, "-f", "eigen,plane,density,count")
    for name in EIGEN:
        assert np.isnan(f[name]).all(), name
    n = 1 if cloud == "one" else (2 if how[1] == "knn" else 1)  # the two points are 1.2 m apart
    assert (f["n_neighbours"] == n).all()


def test_coinciding_points_have_zero_eigenvalues_and_nan_ratios(clouds, tmp_path, run_cli):
    f = _features(clouds, "dup", tmp_path, run_cli, "-r", "1", "-f", "eigen,plane,density,curvature,count")
    assert (f["n_neighbours"] == 50).all()
    assert (f["eigenvalue1"] == 0).all() and (f["eigenvalue3"] == 0).all()
    for name in ("linearity", "planarity", "sphericity", "k1", "mean_curvature"):
        assert np.isnan(f[name]).all(), name
    assert (f["normal_z"] == 1).all()  # the documented arbitrary normal of coinciding points


def test_collinear_points_are_linear(clouds, tmp_path, run_cli):
    f = _features(clouds, "line", tmp_path, run_cli, "-r", "1", "-f", "eigen,eigenvectors,count")
    inner = f["n_neighbours"] >= 3
    assert inner.all()
    np.testing.assert_allclose(f["linearity"], 1.0, atol=1e-6)
    np.testing.assert_allclose(f["planarity"], 0.0, atol=1e-6)
    d = np.array([1.0, 0.5, 0.2]) / np.linalg.norm([1.0, 0.5, 0.2])
    v1 = np.column_stack([f["eigenvector1_x"], f["eigenvector1_y"], f["eigenvector1_z"]])
    np.testing.assert_allclose(v1, np.tile(d, (len(v1), 1)), atol=1e-5)  # z >= 0: along +d


@pytest.mark.parametrize("cloud,verticality", [("flat", 0.0), ("wall", 1.0)])
def test_coplanar_points_are_planar(clouds, tmp_path, run_cli, cloud, verticality):
    f = _features(clouds, cloud, tmp_path, run_cli, "-r", "1", "-f", "eigen,plane")
    np.testing.assert_allclose(f["planarity"] + f["linearity"], 1.0, atol=1e-6)
    np.testing.assert_allclose(f["sphericity"], 0.0, atol=1e-6)
    np.testing.assert_allclose(f["verticality"], verticality, atol=1e-6)
    uv = f.xyz[:, [0, 1] if cloud == "flat" else [0, 2]]  # the plane's own coordinates
    inner = np.all((uv > 1.5) & (uv < 8), axis=1)
    np.testing.assert_allclose(f["planarity"][inner], 1.0, atol=1e-6)  # a full disc: λ1 = λ2
    if cloud == "wall":  # a horizontal normal: x >= 0, then y >= 0 (the wall faces +y)
        np.testing.assert_allclose(f["normal_y"], 1.0, atol=1e-6)
        assert np.isfinite(f["aspect"]).all() and np.allclose(f["aspect"], 0.0, atol=1e-3)
    else:
        np.testing.assert_allclose(f["normal_z"], 1.0, atol=1e-6)
        assert np.isnan(f["aspect"]).all()  # no aspect on flat ground


def test_the_sliver_has_finite_line_features(clouds, tmp_path, run_cli):
    f = _features(clouds, "sliver", tmp_path, run_cli, "-r", "1.5", "-f", "eigen,plane,density,count")
    enough = f["n_neighbours"] >= 3
    assert enough.mean() > 0.99
    for name in ("eigenvalue1", "linearity", "planarity", "verticality"):
        assert np.isfinite(f[name][enough]).all(), name
    assert np.nanmin(f["linearity"]) > 0.99  # 1 mm wide and 3 m long: a line


# --------------------------------------------------------------------- translation invariance
def _pair(clouds: Path, tmp_path: Path, run_cli, argv: list[str], out: str) -> tuple[Path, Path]:
    """Run ``argv`` (with IN / OUT placeholders) on the near and the UTM cloud."""
    paths = []
    for name in ("near", "utm"):
        o = tmp_path / name / out
        o.parent.mkdir(parents=True, exist_ok=True)
        a = [str(clouds / f"{name}.las") if x == "IN" else str(o) if x == "OUT" else x for x in argv]
        rc, _, err = run_cli(a)
        assert rc == 0, err
        paths.append(o)
    return paths[0], paths[1]


AMBIGUOUS = {"eigenvector1_x", "eigenvector1_y", "eigenvector1_z"}
"""Arbitrary where λ1 = λ2 (a symmetric neighbourhood on a wall): compared only where λ1 > λ2."""


def test_utm_coordinates_give_the_features_of_the_cloud_near_zero(clouds, tmp_path, run_cli):
    a, b = _pair(clouds, tmp_path, run_cli, ["features", "IN", "OUT", "-r", "1.003", "-f", "all,-msac", "-q"], "f.laz")
    ca, cb = lidarfx.read(a), lidarfx.read(b)
    np.testing.assert_allclose(cb.xyz - SHIFT, ca.xyz, atol=1e-6)
    names = [n for n in ca.names if n not in lidarfx.read(clouds / "near.las").names]
    assert len(names) > 50
    distinct = np.asarray(ca["eigenvalue1"]) > np.asarray(ca["eigenvalue2"]) * (1 + 1e-4)
    for n in names:
        x, y = np.asarray(ca[n], float), np.asarray(cb[n], float)
        if n in AMBIGUOUS:
            x, y = x[distinct], y[distinct]
        np.testing.assert_array_equal(np.isnan(x), np.isnan(y), err_msg=n)
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=2e-5, err_msg=n)
    # the walls of the house: horizontal normals with one orientation on both
    wall = np.abs(np.asarray(ca["normal_z"])) < 1e-3
    assert wall.sum() > 100


def test_utm_coordinates_give_the_ground_segments_and_labels_of_the_cloud_near_zero(clouds, tmp_path, run_cli):
    a, b = _pair(clouds, tmp_path, run_cli, ["ground", "IN", "OUT", "--hag", "-q"], "g.laz")
    ga, gb = lidarfx.read(a), lidarfx.read(b)
    np.testing.assert_array_equal(ga["classification"], gb["classification"])
    ground = np.asarray(ga["classification"]) == 2
    assert ground[:3600].mean() > 0.97 and not ground[ga.xyz[:, 2] > 4].any()  # the terrain, not the roof
    np.testing.assert_allclose(ga["height_above_ground"], gb["height_above_ground"], atol=1e-4)

    a, b = _pair(clouds, tmp_path, run_cli, ["segment", "IN", "OUT", *SEGMENT, "-q"], "s.laz")
    sa, sb = lidarfx.read(a), lidarfx.read(b)
    np.testing.assert_array_equal(sa["segment_id"], sb["segment_id"])
    assert len(np.unique(sa["segment_id"][sa["segment_id"] >= 0])) >= 5  # ground, roof, four walls

    a, b = _pair(clouds, tmp_path, run_cli, ["eigenclass", "IN", "OUT", "-r", "1.003", "-q"], "e.laz")
    np.testing.assert_array_equal(lidarfx.read(a)["structure"], lidarfx.read(b)["structure"])

    a, b = _pair(clouds, tmp_path, run_cli, ["classify", "predict", "IN", "OUT", "--model", "default", "-q"], "p.laz")
    np.testing.assert_array_equal(lidarfx.read(a)["classification"], lidarfx.read(b)["classification"])

    # the cells are anchored at the origin: the same cells when the shift is a multiple of the cell
    # (--keep centre: points on a grid are often as near the centre as another; rounding decides)
    a, b = _pair(clouds, tmp_path, run_cli, ["thin", "IN", "OUT", "--cell", "0.5", "--keep", "first", "-q"], "t.laz")
    ta, tb = (np.round(lidarfx.read(p).xyz - s, 2) for p, s in ((a, 0.0), (b, SHIFT)))
    assert 0 < len(ta) < len(lidarfx.read(clouds / "near.las"))
    np.testing.assert_array_equal(np.unique(tb, axis=0), np.unique(ta, axis=0))  # in another order

    a, b = _pair(clouds, tmp_path, run_cli, ["colour", "IN", "OUT", "-r", "1.003", "-q"], "c.laz")
    for band in ("red", "green", "blue"):
        np.testing.assert_array_equal(lidarfx.read(a)[band], lidarfx.read(b)[band])


def test_utm_coordinates_give_the_dtm_and_lines_of_the_cloud_near_zero(clouds, tmp_path, run_cli):
    ra, rb = dtm(lidarfx.read(clouds / "near.las"), 1.0), dtm(lidarfx.read(clouds / "utm.las"), 1.0)
    np.testing.assert_allclose(ra.array, rb.array, atol=1e-4)
    assert np.allclose(np.subtract(rb.origin, ra.origin), SHIFT[:2])

    a, b = _pair(clouds, tmp_path, run_cli, ["edges", "IN", "OUT", "-r", "1.003", "-q"], "e.geojson")
    fa, fb = (json.loads(p.read_text())["features"] for p in (a, b))
    assert len(fa) == len(fb) >= 4
    for x, y in zip(fa, fb):
        pa, pb = np.asarray(x["geometry"]["coordinates"]), np.asarray(y["geometry"]["coordinates"])
        np.testing.assert_allclose(pb - SHIFT[: pb.shape[-1]], pa, atol=1e-3)


def test_the_sliver_is_triangulated_without_premerging(clouds, monkeypatch):
    """20 000 points in two straight rows 1 mm apart: Qhull's default facet merging is quadratic on
    such a strip (minutes); lidarfx triangulates a thin set with option Q0 (a second)."""
    import sys

    tin = sys.modules["lidarfx.surface.tin"]
    calls = []
    real = tin.Delaunay
    monkeypatch.setattr(tin, "Delaunay", lambda xy, **kw: calls.append((len(xy), kw.get("qhull_options"))) or real(xy, **kw))
    sliver = lidarfx.read(clouds / "sliver.las")
    sliver["classification"] = np.full(len(sliver), 2, np.uint8)
    sliver["classification"][::7] = 1  # some points above the TIN, not on it
    t0 = time.perf_counter()
    hag = height_above_ground(sliver)
    raster = dtm(sliver, 1.0)
    took = time.perf_counter() - t0
    assert calls and all("Q0" in (o or "") for _, o in calls), calls
    np.testing.assert_allclose(hag, 0.0, atol=1e-6)  # a flat strip: everything is on the ground
    assert raster.array.shape == (1, 10_000) and np.all(raster.array == 0)
    assert took < 300  # about a second; the default options took minutes
    # the square (not thin) keeps Qhull's default options
    calls.clear()
    height_above_ground(lidarfx.read(clouds / "flat.las"))
    assert calls and all(o is None for _, o in calls), calls


# ------------------------------------------------------------------------------- the API
API = {
    "compute_features": lambda c: lidarfx.compute_features(c, "all", radius=1.0, progress=False),
    "compute_features_knn": lambda c: lidarfx.compute_features(c, "eigen,plane", neighbourhood="knn", k=8,
                                                               progress=False),
    "classify_ground": lambda c: lidarfx.classify_ground(c, progress=False),
    "segment_planes": lambda c: lidarfx.segment_planes(c, normal_radius=1.1, growing_radius=0.85, max_distance=0.11,
                                                       min_width=0.85, progress=False),
    "extract_edges": lambda c: lidarfx.extract_edges(c, 1.0, progress=False),
    "extract_powerlines": lambda c: lidarfx.extract_powerlines(c, progress=False),
    "analyse_discontinuities": lambda c: lidarfx.analyse_discontinuities(c, progress=False),
    "extract_breaklines": lambda c: lidarfx.extract_breaklines(c, progress=False),
    "dtm": lambda c: dtm(c, 1.0),
    "height_above_ground": lambda c: height_above_ground(c),
}


@pytest.mark.parametrize("bare", [False, True], ids=["las", "xyz-only"])
@pytest.mark.parametrize("cloud", CLOUDS)
def test_the_api_gives_a_result_or_a_lidarfx_error(clouds, cloud, bare):
    """Every function on every cloud, read from its file or as bare coordinates (no classes)."""
    outcomes = {}
    for name, call in API.items():
        c = lidarfx.read(clouds / f"{cloud}.las")
        if bare:
            c = lidarfx.PointCloud(c.xyz)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                result = call(c)
            except LidarfxError as exc:
                assert str(exc) and "\n" not in str(exc)
                outcomes[name] = "error"
            else:
                assert result is not None
                outcomes[name] = "ok"
    if cloud == "zero":  # an empty mask and (with classes) an empty array; every other function refuses
        want_ok = {"classify_ground"} if bare else {"classify_ground", "height_above_ground"}
        assert {k for k, v in outcomes.items() if v == "ok"} == want_ok
    if cloud in ("near", "utm", "flat", "wall", "line", "sliver"):
        want_error = {"dtm", "height_above_ground"} if bare else set()  # no classes: no ground to use
        assert {k for k, v in outcomes.items() if v == "error"} == want_error
