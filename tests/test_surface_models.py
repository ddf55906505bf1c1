"""DSM and CHM rasters (lidarfx.surface.dsm / chm, lidarfx dsm / chm): exact highest returns on
real files, a pit-free CHM of a synthetic forest with known tree heights, bad input."""
from __future__ import annotations

import json
import math
import re
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

import lidarfx
from lidarfx import PointCloud
from lidarfx.cli import main
from lidarfx.errors import LidarfxError
from lidarfx.ground import dtm
from lidarfx.surface import Raster, chm, dsm
from lidarfx.surface.grid import GridSpec
from lidarfx.surface.models import MAX_CELLS, MAX_GAP, fill_gaps

REAL = Path(__file__).resolve().parents[2] / "shared/data/real"


def _real(name: str) -> PointCloud:
    f = REAL / name
    if not f.exists():
        pytest.skip(f"real data file missing: {f} (the shared data folder is not mounted)")
    return lidarfx.read(f)


def _layout(xyz: np.ndarray, r: float) -> tuple[float, float, int, int]:
    """The documented cells, from scratch: (x0, y0) = the minimum snapped down to a multiple of r;
    columns and rows (from the south) up to the cell of the maximum."""
    x0 = math.floor(xyz[:, 0].min() / r) * r
    y0 = math.floor(xyz[:, 1].min() / r) * r
    cols = int(np.floor((xyz[:, 0].max() - x0) / r)) + 1
    rows = int(np.floor((xyz[:, 1].max() - y0) / r)) + 1
    return x0, y0, rows, cols


def _highest_per_cell(xyz: np.ndarray, r: float, x0: float, y0: float, rows: int, cols: int) -> np.ndarray:
    """The largest z per cell (column floor((x - x0) / r), row floor((y - y0) / r) from the south),
    by sorting (cell, z): a (rows, cols) grid with row 0 = north, NaN where empty."""
    col = np.floor((xyz[:, 0] - x0) / r).astype(np.int64)
    row = np.floor((xyz[:, 1] - y0) / r).astype(np.int64)
    assert col.min() >= 0 and row.min() >= 0 and col.max() < cols and row.max() < rows
    cell = row * cols + col
    order = np.lexsort((xyz[:, 2], cell))  # by cell, then z: the last of each cell is its highest
    last = np.r_[cell[order][1:] != cell[order][:-1], True]
    grid = np.full(rows * cols, np.nan)
    grid[cell[order][last]] = xyz[order[last], 2]
    return grid.reshape(rows, cols)[::-1]


# ---------------------------------------------------------------------------- DSM on real files
@pytest.mark.parametrize("name, res, first", [
    ("MixedConifer.laz", 1.0, False),
    ("MixedConifer.laz", 0.7, False),
    ("samp11-utm.laz", 2.0, False),
    ("12AN2_20.laz", 0.5, False),
    ("autzen_trim.laz", 1.0, True),  # US feet: 1 m cells in feet, first returns only
])
def test_dsm_is_the_highest_point_of_every_cell(name, res, first):
    c = _real(name)
    u = lidarfx.crs.unit_to_metre(c)
    d = dsm(c, res, first_returns=first)
    r = res / u
    assert d.resolution == r
    keep = np.ones(len(c), bool)
    if "classification" in c:
        keep &= ~np.isin(c["classification"], [7, 18])
    if first:
        keep &= c["return_number"] == 1
        assert (~keep).sum() > 1000  # the file has later returns to leave out
    # the grid spans every point (also those left out); its cells are the documented ones
    x0, y0, rows, cols = _layout(c.xyz, r)
    assert d.shape == (rows, cols) and d.origin == (x0, y0 + rows * r)
    top = _highest_per_cell(c.xyz[keep], r, x0, y0, rows, cols)
    occupied = np.isfinite(top)
    assert occupied.sum() == d.meta["cells_with_points"] > 0
    # every cell with points holds exactly the largest z of its points (float32 raster)
    assert np.array_equal(d.array[occupied], top[occupied].astype(np.float32))
    # empty cells: a hole with 8 occupied neighbours is filled; cells in wide gaps are no data
    gap = max(MAX_GAP, 2 * res) / u
    dist = ndimage.distance_transform_edt(~occupied) * r
    surrounded = ~occupied & (ndimage.convolve(occupied.astype(int), np.ones((3, 3), int), mode="constant") == 8)
    assert np.isfinite(d.array[surrounded]).all()
    assert np.isnan(d.array[dist > gap / 2]).all()
    filled = ~occupied & np.isfinite(d.array)
    assert filled.sum() == d.meta["filled_cells"]
    if filled.any():  # linear interpolation: within the heights of the cells with points
        assert np.nanmin(top) <= np.min(d.array[filled]) and np.max(d.array[filled]) <= np.nanmax(top)
    assert d.crs == lidarfx.crs.cloud_crs(c)
    if "classification" in c and (c["classification"] == 2).any() and name != "12AN2_20.laz":
        t = dtm(c, res)  # the DTM of the same cloud and resolution has the same cells
        assert t.origin == d.origin and t.shape == d.shape and t.resolution == d.resolution


def test_dsm_without_filling_and_fill_everything():
    c = _real("samp11-utm.laz")
    none = dsm(c, 1.0, max_gap=0)
    assert none.meta["filled_cells"] == 0 and np.isnan(none.array).sum() == none.meta["nodata_cells"] > 0
    full = dsm(c, 1.0, max_gap=math.inf)
    assert np.isfinite(full.array).all()
    known = np.isfinite(none.array)
    assert np.array_equal(full.array[known], none.array[known])


# ---------------------------------------------------------------------------- gap filling
def test_fill_gaps_fills_narrow_gaps_only():
    g = np.full((30, 40), 5.0)
    g[5, 5] = np.nan  # one empty cell
    g[10:13, 10:13] = np.nan  # 3 x 3
    g[15:30, 20:40] = np.nan  # a wide gap at the corner
    spec = GridSpec(np.zeros((0, 2)), 0.5)
    spec.nx, spec.ny = 40, 30
    one = fill_gaps(g, spec, 1.0)  # 2 cells: the single cell; of the 3 x 3 hole, the corners only
    assert one[5, 5] == 5.0 and np.isnan(one[16:, 21:]).all()  # a disk cannot reach the gap's corner cell
    cross = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)  # the disk of radius 1 cell about its centre
    assert np.isnan(one[10:13, 10:13][cross]).all() and np.allclose(one[10:13, 10:13][~cross], 5.0)
    three = fill_gaps(g, spec, 2.0)  # 4 cells: the 3 x 3 hole too
    assert np.allclose(three[10:13, 10:13], 5.0)
    # a gap wider than max_gap stays empty up to its rim, but for the cells in its corner that the
    # disks of radius max_gap / 2 (2 cells) cannot reach
    assert np.isnan(three[15, 23:]).all() and np.isnan(three[18:, 20]).all() and np.isnan(three[16:, 21:]).all()
    assert np.isfinite(three[15, 20])
    assert np.array_equal(fill_gaps(g, spec, 0.0), g, equal_nan=True)
    assert np.isfinite(fill_gaps(g, spec, math.inf)).all()
    known = np.isfinite(g)
    assert np.array_equal(three[known], g[known])


# ---------------------------------------------------------------------------- CHM of a synthetic forest
SLOPE = (0.25, -0.1)
SHIFT = np.array([600000.0, 5000000.0, 0.0])


def _forest(seed: int = 0, size: float = 80.0, density: float = 10.0, penetrate: float = 0.3):
    """Paraboloid crowns (radius 2.5-4.5 m, height 8-28 m, at least 2 m apart) on a plane sloping
    25 % and 10 %.  First returns fall on the crown surface, or ``penetrate`` of them 3 m below it
    down to the ground; 60 % of the others have a last return on the ground.  Class 2 = ground,
    5 = vegetation.  Returns the cloud and the trees (x, y, radius, height)."""
    rng = np.random.default_rng(seed)
    trees = []
    for cx in np.arange(8.0, size - 7.9, 13.0):
        for cy in np.arange(8.0, size - 7.9, 13.0):
            trees.append((cx + rng.uniform(-1.5, 1.5), cy + rng.uniform(-1.5, 1.5), rng.uniform(2.5, 4.5),
                          rng.uniform(8.0, 28.0)))
    trees = np.array(trees)
    n = rng.poisson(density * size * size)
    xy = rng.uniform(0, size, (n, 2))
    zg = 300.0 + SLOPE[0] * xy[:, 0] + SLOPE[1] * xy[:, 1]
    d = np.full(n, np.inf)
    k = np.full(n, -1)
    for t, (x, y, rad, _) in enumerate(trees):
        dd = np.hypot(xy[:, 0] - x, xy[:, 1] - y)
        m = (dd < rad) & (dd < d)
        d[m], k[m] = dd[m], t
    crown = k >= 0
    surf = np.zeros(n)
    surf[crown] = trees[k[crown], 3] * (1 - 0.5 * (d[crown] / trees[k[crown], 2]) ** 2)
    pen = crown & (rng.random(n) < penetrate)
    depth = np.zeros(n)
    depth[pen] = np.minimum(3.0 + rng.random(pen.sum()) * (surf[pen] - 3.0), surf[pen])
    z1 = zg + surf - depth + rng.normal(0, 0.03, n)
    last = crown & ~pen & (rng.random(n) < 0.6)
    xyz = np.vstack([np.column_stack([xy, z1]), np.column_stack([xy[last], zg[last] + rng.normal(0, 0.03, last.sum())])])
    nl = int(last.sum())
    rn = np.r_[np.ones(n, np.uint8), np.full(nl, 2, np.uint8)]
    nr = np.r_[np.where(last, 2, 1).astype(np.uint8), np.full(nl, 2, np.uint8)]
    ground = np.r_[~crown | (pen & (depth >= surf - 1e-9)), np.ones(nl, bool)]
    cls = np.where(ground, 2, 5).astype(np.uint8)
    trees[:, :2] += SHIFT[:2]
    return PointCloud(xyz + SHIFT, {"return_number": rn, "number_of_returns": nr, "classification": cls}), trees


@pytest.fixture(scope="module")
def forest():
    return _forest()


def _crowns(r: Raster, trees: np.ndarray):
    """Per cell: the nearest tree (by distance / radius), that relative distance, and the
    distance (m) to the nearest crown edge."""
    cx, cy = r.cell_centres()
    X, Y = np.meshgrid(cx, cy)
    rel = np.full(r.shape, np.inf)
    which = np.full(r.shape, -1)
    edge = np.full(r.shape, np.inf)
    for t, (x, y, rad, _) in enumerate(trees):
        dd = np.hypot(X - x, Y - y)
        m = dd / rad < rel
        rel[m], which[m] = dd[m] / rad, t
        edge = np.minimum(edge, dd - rad)
    return which, rel, edge


def _pit_share(a: np.ndarray, inner: np.ndarray, depth: float = 5.0) -> float:
    """Share of the ``inner`` cells more than ``depth`` below the median of their 8 neighbours."""
    med = ndimage.generic_filter(a.astype(float), lambda v: np.median(np.r_[v[:4], v[5:]]), size=3, mode="nearest")
    return float((a[inner] < med[inner] - depth).mean())


def _check_heights(r: Raster, trees: np.ndarray, tol: float = 0.3, ground_tol: float = 0.1) -> None:
    which, rel, edge = _crowns(r, trees)
    a = r.array
    for t, (_, _, _, height) in enumerate(trees):
        top = float(np.nanmax(a[(which == t) & (rel < 1)]))
        assert abs(top - height) < tol, (t, top, height)  # the crown's highest cell: the tree height
    open_ground = edge > 1.5  # 1.5 m and more from every crown
    assert np.isfinite(a[open_ground]).all() and np.abs(a[open_ground]).max() < ground_tol
    assert np.nanmin(a) >= 0


def test_chm_recovers_tree_heights_without_pits(forest):
    cloud, trees = forest
    plain = chm(cloud, 0.5, pit_free=False)
    free = chm(cloud, 0.5)
    assert free.meta["ground"] == plain.meta["ground"] == "class 2"
    assert free.meta["thresholds_m"][:5] == [0, 2, 5, 10, 15] and free.meta["thresholds_m"][-1] <= 28
    for r in (plain, free):
        _check_heights(r, trees)
    _, rel, _ = _crowns(free, trees)
    inner = rel < 0.7
    plain_pits, free_pits = _pit_share(plain.array, inner), _pit_share(free.array, inner)
    assert plain_pits > 0.03, plain_pits  # returns deep in the crowns leave pits in the plain CHM
    assert free_pits < 0.003, free_pits  # and (almost) none in the pit-free one
    # the pit-free CHM only raises cells: the plain CHM's cells with points are lower or equal
    assert np.all(free.array >= plain.array - 1e-6)
    # one grid for DSM, CHM and DTM
    d, t = dsm(cloud, 0.5), dtm(cloud, 0.5)
    assert d.origin == free.origin == t.origin and d.shape == free.shape == t.shape


def test_chm_with_the_ground_filter(forest):
    cloud, trees = forest
    bare = PointCloud(cloud.xyz, {k: cloud[k] for k in ("return_number", "number_of_returns")})
    r = chm(bare, 0.5)  # no classes: the ground filter finds the ground
    assert r.meta["ground"] == "smrf" and r.meta["ground_points"] > 0
    _check_heights(r, trees, tol=0.5)  # SMRF takes low returns in the crowns (within 0.4 m) as ground
    _, rel, _ = _crowns(r, trees)
    assert _pit_share(r.array, rel < 0.7) < 0.003
    # a DTM raster as the ground gives the same tree heights
    ground = dtm(cloud, 0.5)
    _check_heights(chm(cloud, 0.5, ground=ground), trees, ground_tol=0.2)  # bilinear in 0.5 m cells


def test_chm_plain_is_the_highest_first_return_height(forest):
    """Without pit-free filling and gap filling, a cell is the largest height above the ground TIN
    of its first returns, clipped to 0."""
    cloud, _ = forest
    r = chm(cloud, 0.5, pit_free=False, max_gap=0)
    first = cloud["return_number"] == 1
    hag = lidarfx.ground.height_above_ground(cloud).astype(np.float64)
    pts = np.column_stack([cloud.xyz[first, :2], hag[first]])
    x0, y0, rows, cols = _layout(cloud.xyz, r.resolution)
    top = _highest_per_cell(pts, r.resolution, x0, y0, rows, cols)
    assert np.array_equal(np.isfinite(r.array), np.isfinite(top))
    ok = np.isfinite(top)
    assert np.allclose(r.array[ok], np.maximum(top[ok], 0), atol=1e-5)


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("res", [0, -1, float("nan"), float("inf"), "a", 2e9])
def test_bad_resolution(forest, res):
    cloud, _ = forest
    with pytest.raises(LidarfxError, match="resolution"):
        dsm(cloud, res)
    with pytest.raises(LidarfxError, match="resolution"):
        chm(cloud, res)


def test_grid_above_the_cell_limit_is_refused_before_allocation(forest):
    cloud, _ = forest
    for res in (1e-3, 1e-300):
        t0 = time.perf_counter()
        for f in (dsm, chm):
            with pytest.raises(LidarfxError, match=f"at most {MAX_CELLS:,} cells"):
                f(cloud, res)
        assert time.perf_counter() - t0 < 5
    assert dsm(cloud, 1e6).shape == (1, 1)  # a huge cell is one cell


def test_empty_and_no_ground():
    for f in (dsm, chm):
        with pytest.raises(LidarfxError, match="no points"):
            f(PointCloud(np.zeros((0, 3))), 1.0)
        with pytest.raises(LidarfxError, match="no points"):
            f(PointCloud(np.full((5, 3), np.nan)), 1.0)
    rng = np.random.default_rng(1)
    xyz = rng.uniform(0, 20, (500, 3))
    noise = PointCloud(xyz, {"classification": np.full(500, 7, np.uint8)})
    with pytest.raises(LidarfxError, match="no points left for the DSM .classes 7,18 left out"):
        dsm(noise, 1.0)
    assert dsm(noise, 1.0, exclude_classes=None).meta["points"] == 500
    no_ground = PointCloud(xyz, {"classification": np.full(500, 5, np.uint8)})
    with pytest.raises(LidarfxError, match=r"no ground points \(class 2\)"):
        chm(no_ground, 1.0, ground="class")
    with pytest.raises(LidarfxError, match="no ground points in the ground mask"):
        chm(no_ground, 1.0, ground=np.zeros(500, bool))
    with pytest.raises(LidarfxError, match="ground must be"):
        chm(no_ground, 1.0, ground="lowest")
    with pytest.raises(LidarfxError, match="bare array"):
        chm(xyz, 1.0)


@pytest.mark.parametrize("kwargs, message", [
    ({"max_gap": -1}, "max_gap must be a number >= 0"),
    ({"freeze_distance": 0}, "freeze_distance must be a positive number"),
    ({"thresholds": [0, -2]}, "thresholds must be heights >= 0"),
    ({"thresholds": []}, "thresholds must be heights >= 0"),
    ({"exclude_classes": [300]}, "exclude_classes must be class codes"),
])
def test_bad_options(forest, kwargs, message):
    cloud, _ = forest
    with pytest.raises(LidarfxError, match=message):
        chm(cloud, 1.0, **kwargs)


# ---------------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def forest_file(forest, tmp_path_factory):
    path = tmp_path_factory.mktemp("forest") / "forest.laz"
    lidarfx.write(forest[0], path)
    return path


def test_cli_dsm_and_chm(forest_file, tmp_path, capsys):
    out = tmp_path / "dsm.tif"
    assert main(["dsm", str(forest_file), str(out), "-r", "0.5", "--first-returns", "--json", "-q"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["product"] == "dsm" and s["first_returns"] and s["cell_map_units"] == 0.5 and out.exists()
    assert s["cells_with_points"] + s["filled_cells"] + s["nodata_cells"] == s["cells"] == s["shape"][0] * s["shape"][1]
    asc = tmp_path / "chm.asc"
    assert main(["chm", str(forest_file), str(asc), "-r", "0.5", "--json", "-q"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["product"] == "chm" and s["method"] == "pit-free" and s["ground"] == "class 2"
    head = asc.read_text().split("\n", 6)
    assert head[0] == f"ncols {s['shape'][1]}" and head[4] == "cellsize 0.5"
    assert main(["chm", str(forest_file), str(tmp_path / "plain.tif"), "--no-pit-free", "-q"]) == 0
    assert capsys.readouterr() == ("", "")
    assert main(["chm", str(forest_file), str(tmp_path / "c.tif"), "--ground", "smrf", "-r", "2"]) == 0
    assert re.match(r"CHM \d+x\d+ cells of 2 m -> .*c.tif \(.*ground smrf\)$", capsys.readouterr().err.strip())


def test_cli_crs_from_the_las_header(tmp_path, capsys):
    if not (REAL / "MixedConifer.laz").exists():
        pytest.skip(f"real data file missing: {REAL / 'MixedConifer.laz'}")
    out = tmp_path / "chm.asc"
    assert main(["chm", str(REAL / "MixedConifer.laz"), str(out), "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["epsg"] == 26912
    assert "UTM" in out.with_suffix(".prj").read_text() or "26912" in out.with_suffix(".prj").read_text()


def test_cli_errors_are_one_line_before_any_work(forest_file, tmp_path, capsys):
    existing = tmp_path / "old.tif"
    existing.write_bytes(b"keep")
    bad = [
        (["dsm", str(forest_file), str(existing)], "exists; give --force"),
        (["chm", str(forest_file), str(tmp_path / "c.png")], "give a path ending in .tif"),
        (["dsm", str(forest_file), str(tmp_path / "no" / "d.tif")], "output folder does not exist"),
        (["chm", str(forest_file), str(tmp_path / "c.tif"), "-r", "0"], "resolution must be a positive number"),
        (["chm", str(forest_file), str(tmp_path / "c.tif"), "-r", "1e-300"], "is too large"),
        (["chm", str(forest_file), str(tmp_path / "c.tif"), "--thresholds", "0,-1"], "thresholds must be"),
        (["dsm", str(forest_file), str(tmp_path / "d.tif"), "--max-gap", "-2"], "max_gap must be"),
        (["dsm", str(forest_file), str(forest_file)], "is the input file"),
    ]
    for argv, message in bad:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("lidarfx: error: ") and message in err[0], (argv, err)
    assert existing.read_bytes() == b"keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.tif"]
    # with --force the existing output is replaced
    assert main(["dsm", str(forest_file), str(existing), "-r", "2", "-q", "--force"]) == 0
    assert existing.read_bytes()[:4] == b"II*\x00"


def test_cli_chm_without_ground_class(tmp_path, capsys):
    rng = np.random.default_rng(3)
    path = tmp_path / "trees.laz"
    lidarfx.write(PointCloud(rng.uniform(0, 30, (300, 3)), {"classification": np.full(300, 5, np.uint8)}), path)
    assert main(["chm", str(path), str(tmp_path / "c.tif"), "--ground", "class"]) == 2
    assert "no ground points (class 2)" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["dsm", "chm"])
def test_cli_help_has_examples(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    out = capsys.readouterr().out
    assert exc.value.code == 0 and "examples:" in out and f"lidarfx {command} tile.laz" in out
    assert "Lengths are metres" in out and "docs/surfaces.md" in out
