"""Ground filter, DTM, segmentation, selection and I/O: the rules of the docs, checked against
closed forms on hand-built scenes, and the CLI options that must reach them.

Every expected value is computed here, independently of the code under test:

* SMRF (docs/ground.md §1): on scenes with one point at every cell centre the minimum surface is
  known exactly, so the final test ``|z − DTM| <= threshold + scalar · g`` and the progressive
  opening's rule (a plateau of width 2k + 1 cells and height h is removed at radius k + 1 when
  ``h > slope · (k + 1) · cell``, kept by the step check only when ``h > edge_step``) give the
  ground mask exactly;
* the CLI options of ``ground``, ``ground-eval`` and ``dtm`` are checked by their effect on such a
  scene (``--slope``, ``--window``, ``--edge-step``, ``--edge-share``, ``--threshold``,
  ``--scalar``, ``--ignore-classes``, ``--all-returns``, ``-r``);
* the DTM grid: origin snapped to the resolution, every point inside, row 0 north;
* segmentation: the minimum segment size is inclusive, dip directions lie in [0, 360), CLI options
  are passed on;
* selection: Python's modulo, x/y/z before attributes, float32 constants and NaN on either side;
* I/O: text writer options (precision, header, digits), ``.npy`` column order, ``.npz``
  compression, no temporary file left, int64 extra bytes, the ``;`` delimiter rule,
  ``convert --precision``.

Two tests guard bugs of ``geometry.dip_from_normal`` (the dip direction of ``segments_table``)
found on the way and fixed: a horizontal normal pointing down got dip direction 180° instead of 0°
(flipping made -0.0, and atan2(-0.0, -0.0) = -180°), and a north-dipping plane with n_x = -1e-17
got 360.0 (a tiny negative angle mod 360).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx import PointCloud
from lidarfx.cli import main
from lidarfx.ground import classify_ground, dtm

E, N, H0 = 500_000.0, 5_400_000.0, 100.0  # UTM-sized offset of the hand-built scenes


# ---------------------------------------------------------------------------------------------
# SMRF: scenes with one point at every cell centre
# ---------------------------------------------------------------------------------------------
def _centres(nx: int, ny: int, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """x, y (local, m) of the cell centres of an nx × ny grid and their column / row."""
    jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
    return (jj.ravel() + 0.5) * cell, (ii.ravel() + 0.5) * cell, jj.ravel(), ii.ravel()


def _anchor(z: float) -> np.ndarray:
    """A point at the grid's south-west corner, far above the surface: it makes the filter's local
    origin (the minimum of the points) the corner of cell (0, 0), so the other points sit exactly at
    cell centres, and it is never the lowest point of its cell."""
    return np.array([[0.0, 0.0, z]])


def _plateau_scene(h: float, width: int = 9, n: int = 40, first_row: int = 15):
    """Flat ground z = 0 with a plateau of height ``h`` that fills rows ``first_row`` ...
    ``first_row + width - 1`` of an n × n grid of 1 m cells, from edge to edge (no ends: the opening
    acts across it only).  One point per cell centre, plus the anchor.  Returns world xyz and the
    plateau mask."""
    x, y, _, row = _centres(n, n, 1.0)
    on = (row >= first_row) & (row < first_row + width)
    xyz = np.vstack([np.column_stack([x, y, np.where(on, h, 0.0)]), _anchor(h + 5.0)])
    return xyz + [E, N, H0], np.r_[on, False]


def _plateau_is_object(h: float, width: int, *, cell=1.0, slope=0.2, window=21.0, edge_step=1.0, edge_share=0.15):
    """SMRF's answer for the plateau, from the rules of docs/ground.md §1 (steps 3 and 4).

    A disk of radius r (cells) fits across the plateau while 2r + 1 <= width, and the opening keeps
    the plateau; at r0 = width // 2 + 1 it is opened down to the ground and is an object when
    h > slope · r0 · cell (later radii compare opened ground with opened ground: no more objects).
    The radii run 1 … round(window / cell).  The step check keeps the region only when at least
    edge_share of its boundary pairs drop by more than edge_step: here all pairs drop by h."""
    r0 = width // 2 + 1
    radius = max(1, round(window / cell))
    opened = r0 <= radius and h > slope * r0 * cell
    stays = edge_share <= 0 or (h > edge_step)
    return opened and stays


@pytest.mark.parametrize(
    "h, params",
    [
        (1.2, dict(slope=0.2, window=5.0, edge_share=0.0)),  # r0 = 5: 1.2 > 0.2·5 → object
        (1.2, dict(slope=0.2, window=4.0, edge_share=0.0)),  # radii 1..4: the plateau is never opened away
        (0.8, dict(slope=0.2, window=5.0, edge_share=0.0)),  # 0.8 <= 0.2·5: terrain (slope · r, not slope)
        (1.2, dict(slope=0.25, window=5.0, edge_share=0.0)),  # 1.2 <= 0.25·5
        (1.2, dict(slope=0.2, window=5.0, edge_step=1.0, edge_share=0.15)),  # steps of 1.2 > 1.0: object
        (1.2, dict(slope=0.2, window=5.0, edge_step=1.5, edge_share=0.15)),  # no step > 1.5: back to terrain
        (3.0, dict(slope=0.2, window=21.0)),  # the defaults
    ],
)
def test_smrf_plateau_is_removed_exactly_by_the_opening_rule(h, params):
    width = 9
    xyz, on = _plateau_scene(h, width)
    want_object = _plateau_is_object(h, width, **params)
    mask = classify_ground(xyz, cell=1.0, threshold=0.3, scalar=0.0, **params)
    # an object's points lie h above the terrain under them (> threshold): not ground; a kept
    # plateau is part of the terrain: every point exactly on it
    assert mask[on].all() == (not want_object) and mask[on].any() == (not want_object), (h, params)
    assert mask[~on][:-1].all()  # the ground, always
    assert not mask[-1]  # the anchor, 5 m above


TILT_A, TILT_B, TILT_CELL = 0.12, -0.07, 2.0


def _tilted_scene(threshold: float, scalar: float, margin: float = 0.002):
    """A tilted plane z = a·x + b·y with one point per 2 m cell centre, 5000 random points
    0.25–1.5 m above it, three points 20 m below it (low outliers: more than 5 · 1 · cell below
    their neighbours) and the anchor.  Returns world xyz, the heights above the plane of the random
    points, their slice, the slice of the deep points and threshold + scalar · |∇plane|
    (docs/ground.md §1 step 6).

    The heights are at least 0.25 m, so that no random point is the lowest of its cell (the plane
    varies by at most 0.19 m between a cell's centre and its edge); none lies within ``margin`` of
    the bound (the inpainting moves cell centres by up to 1/2000 cell)."""
    a, b, cell, nx, ny = TILT_A, TILT_B, TILT_CELL, 30, 25
    x, y, _, _ = _centres(nx, ny, cell)
    centres = np.column_stack([x, y, a * x + b * y])
    rng = np.random.default_rng(0)
    px = rng.uniform(0.5 * cell, (nx - 0.5) * cell, 5000)
    py = rng.uniform(0.5 * cell, (ny - 0.5) * cell, 5000)
    d = rng.uniform(0.25, 1.5, 5000)
    bound = threshold + scalar * math.hypot(a, b)
    keep = np.abs(d - bound) > margin
    px, py, d = px[keep], py[keep], d[keep]
    above = np.column_stack([px, py, a * px + b * py + d])
    low_xy = np.array([[15.1, 13.3], [41.0, 30.9], [27.7, 44.2]])  # interior cells far apart
    low = np.column_stack([low_xy, a * low_xy[:, 0] + b * low_xy[:, 1] - 20.0])
    xyz = np.vstack([centres, above, low, _anchor(8.0)]) + [E, N, H0]
    k = len(centres)
    return xyz, d, slice(k, k + len(above)), slice(k + len(above), k + len(above) + 3), bound


@pytest.mark.parametrize("threshold, scalar", [(0.3, 2.0), (0.5, 0.5)])
def test_smrf_final_test_is_threshold_plus_scalar_times_gradient(threshold, scalar):
    """docs/ground.md §1 step 6 on a tilted plane: ground ⇔ |z − DTM| <= threshold + scalar · g,
    DTM = the plane (bilinear between cell centres is exact on a plane), g = |∇plane| (rise/run).
    Points deep below the surface count by their absolute distance (and are low outliers)."""
    xyz, d, above, low, bound = _tilted_scene(threshold, scalar)
    mask = classify_ground(xyz, cell=TILT_CELL, threshold=threshold, scalar=scalar)
    assert mask[: above.start].all()  # the points at the cell centres
    want = d <= bound
    assert 0.05 < want.mean() < 0.5  # both sides of the bound are well populated
    got = mask[above]
    assert np.array_equal(got, want), np.sort(d[got != want])[:10]
    assert not mask[low].any()  # 20 m below: never ground
    assert not mask[-1]


def test_cli_ground_threshold_and_scalar_reach_the_final_test(tmp_path, capsys):
    """The same closed form through ``lidarfx ground`` (LAS stores mm: a 3 mm margin)."""
    threshold, scalar = 0.3, 2.0
    xyz, d, above, low, bound = _tilted_scene(threshold, scalar, margin=0.003)
    src = tmp_path / "tilt.las"
    lidarfx.write(PointCloud(xyz), src)
    out = tmp_path / "tilt_out.las"
    argv = ["ground", str(src), str(out), "--cell", "2", "--threshold", str(threshold), "--scalar", str(scalar), "-q"]
    assert main(argv) == 0
    cls = lidarfx.read(out)["classification"]
    assert np.array_equal(cls[above] == 2, d <= bound)
    assert np.all(cls[: above.start] == 2) and np.all(cls[low] == 1)


def test_non_finite_points_are_never_candidates():
    xyz, on = _plateau_scene(0.0)
    xyz = np.vstack([xyz, [[E + 3.0, N + 3.0, np.nan], [np.inf, N + 3.0, H0]]])
    mask = classify_ground(xyz, cell=1.0)
    assert not mask[-2:].any()
    assert mask[:-3].all()  # the flat ground (the anchor, 5 m above, is not ground)


# ---------------------------------------------------------------------------------------------
# CLI: ground / ground-eval / dtm pass their options on
# ---------------------------------------------------------------------------------------------
def _plateau_file(tmp_path: Path, h: float = 1.2) -> tuple[Path, np.ndarray]:
    """The plateau scene as LAS (class 1), plus 4 class-7 points and 4 first-of-two returns lying
    exactly on the ground (z = 0, inside cells: never lower than the cell's centre point).  Returns
    the path and the kind of every point: 0 ground, 1 plateau, 9 anchor, 7 noise, 3 first returns."""
    xyz, on = _plateau_scene(h)
    extra = np.array([[3.3, 3.3], [30.2, 6.6], [8.8, 34.1], [36.6, 37.7]])
    noise = np.column_stack([extra, np.zeros(4)]) + [E, N, H0]
    first = np.column_stack([extra + 0.2, np.zeros(4)]) + [E, N, H0]
    all_xyz = np.vstack([xyz, noise, first])
    n = len(all_xyz)
    cls = np.ones(n, np.uint8)
    cls[len(xyz) : len(xyz) + 4] = 7
    rn = np.ones(n, np.uint8)
    nr = np.ones(n, np.uint8)
    nr[-4:] = 2  # return 1 of 2: not a last return
    path = tmp_path / "plateau.las"
    lidarfx.write(PointCloud(all_xyz, {"classification": cls, "return_number": rn, "number_of_returns": nr}), path)
    kind = np.r_[np.where(on, 1, 0)[:-1], 9, np.full(4, 7), np.full(4, 3)]
    return path, kind


def _ground_cli(tmp_path: Path, src: Path, *opts: str) -> np.ndarray:
    """``lidarfx ground`` with ``opts``; the classes written."""
    out = tmp_path / "out.las"
    assert main(["ground", str(src), str(out), "--json", "-q", "--force", *opts]) == 0  # one output, run after run
    return lidarfx.read(out)["classification"]


@pytest.mark.parametrize(
    "opts, plateau_ground",
    [
        ((), False),  # defaults: h = 1.2 > 0.2 · 5, steps of 1.2 m > 1.0 m
        (("--edge-step", "1.5"), True),  # the step check returns the plateau to the terrain
        (("--edge-step", "1.5", "--edge-share", "0"), False),  # ... unless it is off
        (("--slope", "0.25"), True),  # 1.2 <= 0.25 · 5
        (("--window", "4"), True),  # radii 1..4 never open it away
        (("--threshold", "1.3"), True),  # an object, but within the threshold
    ],
)
def test_cli_ground_passes_the_smrf_options(tmp_path, capsys, opts, plateau_ground):
    src, kind = _plateau_file(tmp_path)
    cls = _ground_cli(tmp_path, src, "--cell", "1", "--scalar", "0", *opts)
    summary = json.loads(capsys.readouterr().out)
    assert np.all((cls[kind == 1] == 2) == plateau_ground), opts
    assert np.all(cls[kind == 0] == 2)
    params = summary["parameters"]
    for flag, value in zip(opts[::2], opts[1::2]):
        assert params[flag[2:].replace("-", "_")] == float(value)


def test_cli_ground_ignore_classes_and_all_returns(tmp_path, capsys):
    src, kind = _plateau_file(tmp_path)
    cls = _ground_cli(tmp_path, src, "--cell", "1")
    assert np.all(cls[kind == 7] == 7)  # ignored by default: neither used nor made ground, class kept
    assert np.all(cls[kind == 3] == 1)  # not last returns: never ground
    assert json.loads(capsys.readouterr().out)["parameters"]["ignore_classes"] == [7, 18, 66]
    cls = _ground_cli(tmp_path, src, "--cell", "1", "--ignore-classes", "none", "--all-returns")
    assert np.all(cls[kind == 7] == 2) and np.all(cls[kind == 3] == 2)  # on the ground surface: ground
    capsys.readouterr()
    cls = _ground_cli(tmp_path, src, "--cell", "1", "--ignore-classes", "1")
    # class 1 ignored: the ground and the plateau keep class 1, the class-7 points are the only ground
    assert np.all(cls[kind == 7] == 2) and np.all(cls[np.isin(kind, [0, 1, 3])] == 1)


def test_cli_dtm_and_ground_dtm_use_the_resolution(tmp_path, capsys):
    src, kind = _plateau_file(tmp_path)
    # ground --dtm with -r 2: the plateau scene spans x, y in [0, 40) m (+ offsets) → 20 × 20 cells
    out = tmp_path / "g.las"
    asc = tmp_path / "g.asc"
    assert main(["ground", str(src), str(out), "--cell", "1", "--dtm", str(asc), "-r", "2", "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["dtm"]["resolution"] == 2.0 and summary["dtm"]["shape"] == [20, 20]
    head = dict(line.split() for line in asc.read_text().splitlines()[:6])
    assert (head["ncols"], head["nrows"], float(head["cellsize"])) == ("20", "20", 2.0)
    assert float(head["xllcorner"]) == E and float(head["yllcorner"]) == N
    # dtm --classify passes the SMRF options on: with --window 4 the plateau stays in the terrain
    # with class 1 ignored only the four class-7 points (z = 0) are candidates: a flat DTM
    for opts, top in (((), H0), (("--window", "4"), H0 + 1.2), (("--window", "4", "--ignore-classes", "1"), H0)):
        d = tmp_path / "d.asc"
        assert main(["dtm", str(src), str(d), "--classify", "--cell", "1", "-r", "2", "-q", "--force", *opts]) == 0
        grid = np.loadtxt(d, skiprows=6)
        # row 0 = north; the plateau's points have y = 15.5 … 23.5 m: DTM rows centred at y = 17, 19, 21
        yc = N + 40 - (np.arange(20) + 0.5) * 2
        inner = (yc > N + 16) & (yc < N + 23)
        assert np.allclose(grid[inner], top, atol=1e-3), opts
        assert np.allclose(grid[(yc < N + 13) | (yc > N + 26)], H0, atol=1e-3)


def test_cli_ground_eval_counts_on_the_plateau_scene(tmp_path, capsys):
    """Reference: ground cells 2, plateau and anchor 6, first-of-two returns on the ground 5,
    noise 7.  The filter gets every candidate right, so the errors are exactly the ones the options
    create: the four first returns are object points accepted as ground when every return is used."""
    src, kind = _plateau_file(tmp_path)
    c = lidarfx.read(src)
    c["classification"] = np.select([kind == 0, kind == 7, kind == 3], [2, 7, 5], 6).astype(np.uint8)
    labelled = tmp_path / "labelled.las"
    lidarfx.write(c, labelled)
    n_ground, n_object = int((kind == 0).sum()), int(np.isin(kind, [1, 9, 3]).sum())
    for opts, n_type_ii in (((), 0), (("--all-returns",), 4)):
        assert main(["ground-eval", str(labelled), "--cell", "1", "--json", "-q", *opts]) == 0
        row = json.loads(capsys.readouterr().out)["files"][0]
        assert (row["ignored_points"], row["n_ground"], row["n_object"]) == (4, n_ground, n_object)
        assert (row["n_type_i"], row["n_type_ii"]) == (0, n_type_ii), opts
        assert row["table"] == [[n_ground, 0], [n_type_ii, n_object - n_type_ii]]
        assert row["type_ii"] == pytest.approx(n_type_ii / n_object)
        assert row["total"] == pytest.approx(n_type_ii / (n_ground + n_object))


def test_apply_ground_classification_keeps_the_class_dtype():
    """docs/ground.md §3: 2 for ground, 1 for the rest, ignored classes kept, the dtype kept."""
    from lidarfx.ground import apply_ground_classification

    xyz, on = _plateau_scene(1.2)
    cls = np.full(len(xyz), 300, np.int16)  # e.g. read from a text file with user classes
    cls[:3] = 66
    out = apply_ground_classification(PointCloud(xyz, {"classification": cls}), cell=1.0, window=5.0)
    got = out["classification"]
    assert got.dtype == np.int16
    assert got[:3].tolist() == [66, 66, 66]
    assert np.all(got[3:][~on[3:]][:-1] == 2) and np.all(got[on] == 1) and got[-1] == 1


# ---------------------------------------------------------------------------------------------
# DTM grid geometry
# ---------------------------------------------------------------------------------------------
def test_dtm_grid_is_snapped_and_holds_every_point():
    rng = np.random.default_rng(3)
    lo = np.array([652_003.3, 4_300_001.7])
    hi = np.array([652_047.9, 4_300_031.2])
    xy = rng.uniform(lo, hi, (400, 2))
    xy[:2] = [lo, hi]  # the extremes
    z = 0.3 * (xy[:, 0] - lo[0]) - 0.2 * (xy[:, 1] - lo[1]) + 50.0
    r = dtm(np.column_stack([xy, z]), resolution=2.0)
    # docs/ground.md §6: origin on multiples of the resolution, north-west corner, row 0 north
    x0, y0 = 652_002.0, 4_300_000.0  # floor(min / 2) · 2
    cols = math.floor((hi[0] - x0) / 2.0) + 1  # 23: the east-most point's column included
    rows = math.floor((hi[1] - y0) / 2.0) + 1  # 16
    assert r.shape == (rows, cols)
    assert r.origin == (x0, y0 + rows * 2.0)
    xmin, ymin, xmax, ymax = r.bounds
    assert np.all((xy[:, 0] >= xmin) & (xy[:, 0] < xmax) & (xy[:, 1] >= ymin) & (xy[:, 1] < ymax))
    # the northern-most point's cell is in row 0, the southern-most in the last row
    row, col = r.cell_of(xy[:, 0], xy[:, 1])
    assert row[1] == 0 and row[0] == rows - 1 and col[0] == 0 and col[1] == cols - 1
    # bounds= covers exactly that box
    rb = dtm(np.column_stack([xy, z]), resolution=2.0, bounds=(652_010.0, 4_300_010.0, 652_019.0, 4_300_013.5))
    assert rb.shape == (2, 5) and rb.origin == (652_010.0, 4_300_014.0)


# ---------------------------------------------------------------------------------------------
# Segmentation: exact grids (no noise), so every point has a normal and the answers are exact
# ---------------------------------------------------------------------------------------------
def _grid(nu: int, nv: int, spacing: float, origin, e1, e2) -> np.ndarray:
    """nu × nv points, ``spacing`` apart along the unit vectors e1, e2 from ``origin``."""
    u, v = np.meshgrid(np.arange(nu) * spacing, np.arange(nv) * spacing)
    return np.asarray(origin, float) + u.reshape(-1, 1) * np.asarray(e1, float) + v.reshape(-1, 1) * np.asarray(e2, float)


X, Y = (1, 0, 0), (0, 1, 0)


def _patch36() -> np.ndarray:
    """6 × 6 points 5 cm apart: every point has ≥ 3 neighbours within the LIS normal radius."""
    return _grid(6, 6, 0.05, (0, 0, 0), X, Y)


def _parallel() -> np.ndarray:
    """Two horizontal 40 × 40 grids (5 cm), 0.3 m apart."""
    return np.vstack([_grid(40, 40, 0.05, (0, 0, 0), X, Y), _grid(40, 40, 0.05, (0, 0, 0.3), X, Y)])


def _bent_roof() -> np.ndarray:
    """Two faces rising 10° from a ridge line along x, sloping to either side: their normals are 20°
    apart; the far edges (2 m out) lie 0.35 m off the other face's plane."""
    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    a = _grid(40, 41, 0.05, (0, 0, 0), X, (0, c, s))
    b = _grid(40, 40, 0.05, (0, -0.05 * c, 0.05 * s), X, (0, -c, s))
    return np.vstack([a, b])


def _wide_and_strip() -> np.ndarray:
    """A 2 m × 1 m grid and a 3 m long strip of 5 rows 2 cm apart.  The strip's equivalent width
    √(12 λ2) (docs/segmentation.md §3) is √(12 · 0.0008) = 0.0980 m (λ2 = mean of 0, ±0.02², ±0.04²)."""
    return np.vstack([_grid(80, 40, 0.025, (0, 0, 0), X, Y), _grid(150, 5, 0.02, (0, 3, 0), X, Y)])


STRIP_WIDTH = math.sqrt(12 * (2 * 0.04**2 + 2 * 0.02**2) / 5)


def test_min_size_is_inclusive_and_min_width_is_the_equivalent_width():
    from lidarfx.segment import segment_planes

    patch = PointCloud(_patch36())
    kept = segment_planes(patch, min_size=36)
    assert kept.meta["segmentation"]["no_normal_points"] == 0
    assert kept["segment_id"].tolist() == [0] * 36 and kept["segment_size"].tolist() == [36] * 36
    released = segment_planes(patch, min_size=37)  # "fewer than min_size points": 36 < 37
    assert released["segment_id"].tolist() == [-1] * 36 and released["segment_size"].tolist() == [0] * 36
    ws = PointCloud(_wide_and_strip())
    for min_width, strip_kept in ((STRIP_WIDTH - 0.001, True), (STRIP_WIDTH + 0.001, False)):
        sid = segment_planes(ws, min_width=min_width)["segment_id"]
        assert np.all(sid[:3200] == 0)
        assert np.all(sid[3200:] == (1 if strip_kept else -1)), min_width


@pytest.mark.parametrize(
    "scene, opts, sizes",
    [
        ("parallel", (), [1600, 1600]),
        ("parallel", ("--growing-radius", "0.5"), [1600, 1600]),  # 0.3 m apart > max distance 0.10
        ("parallel", ("--growing-radius", "0.5", "--max-distance", "0.5"), [3200]),  # within both: one plane
        ("roof", ("--max-distance", "1.0"), [1640, 1600]),  # normals 20° apart > 15°
        ("roof", ("--max-distance", "1.0", "--max-angle", "25"), [3240]),
        ("patch", ("--min-size", "36"), [36]),
        ("patch", ("--min-size", "37"), []),
        ("patch", ("--min-size", "10", "--normal-radius", "0.04"), []),  # < 3 neighbours: no normal anywhere
        ("strip", (), [3200, 750]),
        ("strip", ("--min-width", f"{STRIP_WIDTH + 0.001:.4f}"), [3200]),
    ],
)
def test_cli_segment_passes_its_options(tmp_path, capsys, scene, opts, sizes):
    xyz = {"parallel": _parallel, "roof": _bent_roof, "patch": _patch36, "strip": _wide_and_strip}[scene]()
    src = tmp_path / "scene.las"
    lidarfx.write(PointCloud(xyz + [E, N, H0]), src)  # LAS keeps millimetres: the same answers
    out = tmp_path / "seg.las"
    rc = main(["segment", str(src), str(out), "--json", "-q", *opts])
    if not sizes:  # no segment: the command stops with a hint (exit 2) and writes nothing
        err = capsys.readouterr().err
        assert rc == 2 and not out.exists() and err.startswith("lidarfx: error: no plane segment found")
        return
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert [r["size"] for r in summary["largest"]] == sizes
    assert summary["segmented_points"] == sum(sizes)
    for flag, value in zip(opts[::2], opts[1::2]):
        assert summary["parameters"][flag[2:].replace("-", "_")] == float(value)
    sid = lidarfx.read(out)["segment_id"]
    assert np.bincount(sid[sid >= 0]).tolist() == sizes
    table = json.loads((tmp_path / "seg.las.segments.json").read_text())
    assert [r["size"] for r in table["segments"]] == sizes
    if scene == "patch" and "--normal-radius" in opts:
        assert table["segmentation"]["no_normal_points"] == 36


def test_segments_table_of_a_bent_roof():
    """Dip 10° and dip directions 0° / 180° (docs/segmentation.md §4: atan2(n_x, n_y) mod 360,
    clockwise from North, normal flipped up), RMS 0, in-plane hull areas, world centroids."""
    from lidarfx.segment import segment_planes, segments_table

    xyz = _bent_roof() + [E, N, H0]
    rows = segments_table(segment_planes(PointCloud(xyz), max_distance=1.0))
    assert [r["size"] for r in rows] == [1640, 1600]
    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    # face a (y >= 0) rises towards +y: it dips towards −y (180°); face b dips towards +y (0°)
    for r, ddir, width in ((rows[0], 180.0, 40 * 0.05), (rows[1], 0.0, 39 * 0.05)):
        assert r["dip"] == pytest.approx(10.0, abs=1e-6)
        d = abs(r["dip_direction"] - ddir) % 360.0
        assert min(d, 360.0 - d) < 1e-6 and 0.0 <= r["dip_direction"] < 360.0
        assert r["rms"] == pytest.approx(0.0, abs=1e-6)
        assert r["area"] == pytest.approx(39 * 0.05 * width, rel=1e-9)
    # centroids: face a t = 0 … 2.0 m (mean 1.0), face b t = 0.05 … 2.0 m (mean 1.025)
    assert rows[0]["centroid_x"] == pytest.approx(E + 39 * 0.05 / 2, abs=1e-6)
    assert [rows[0]["centroid_y"], rows[0]["centroid_z"]] == pytest.approx([N + 1.0 * c, H0 + 1.0 * s], abs=1e-6)
    assert [rows[1]["centroid_y"], rows[1]["centroid_z"]] == pytest.approx([N - 1.025 * c, H0 + 1.025 * s], abs=1e-6)


def test_horizontal_plane_dip_direction_is_zero_for_either_normal_sign():
    from lidarfx.geometry import dip_from_normal

    assert dip_from_normal([0.0, 0.0, 1.0]) == (0.0, 0.0)
    assert dip_from_normal([0.0, 0.0, -1.0]) == (0.0, 0.0)


def test_dip_direction_of_a_north_dipping_plane_is_below_360():
    from lidarfx.geometry import dip_from_normal

    s, c = math.sin(math.radians(10)), math.cos(math.radians(10))
    dip, ddir = dip_from_normal([-1e-17, s, c])
    assert dip == pytest.approx(10.0) and 0.0 <= ddir < 360.0


# ---------------------------------------------------------------------------------------------
# Selection (docs/segmentation.md §5)
# ---------------------------------------------------------------------------------------------
def _sel_cloud() -> PointCloud:
    x = np.arange(-3.0, 3.0)  # -3 … 2
    return PointCloud(
        np.c_[x, 10.0 - x, 2.0 * x],
        {
            "segment_id": np.array([-1, -2, 0, 1, 2, 3], np.int32),
            "planarity": np.array([0.1, 0.6, np.nan, 0.9, 0.2, 0.7], np.float32),
            # an attribute named like a coordinate: x, y, z mean the coordinates
            "x": np.array([100.0, 100.0, 100.0, -100.0, -100.0, -100.0]),
        },
    )


@pytest.mark.parametrize(
    "expr, want",
    [
        # % is Python's modulo (sign of the divisor), like the rest of the grammar: -3 % 2 == 1
        ("x % 2 == 1", [x % 2 == 1 for x in range(-3, 3)]),
        ("segment_id % 3 == 1", [s % 3 == 1 for s in (-1, -2, 0, 1, 2, 3)]),
        ("x > 0", [False] * 4 + [True] * 2),  # the coordinate, not the attribute named "x"
        # float32 attributes meet constants rounded to float32 on either side (0.1f > 0.1,
        # 0.9f < 0.9, 0.6f > 0.6 in float64); NaN compares False
        ("0.1 == planarity", [True] + [False] * 5),
        ("0.9 <= planarity", [False, False, False, True, False, False]),
        ("0.6 >= planarity", [True, True, False, False, True, False]),
        ("0.6 != planarity", [True, False, False, True, True, True]),  # NaN on the right: False too
    ],
)
def test_select_python_semantics(expr, want):
    from lidarfx.select import evaluate

    assert evaluate(_sel_cloud(), expr).tolist() == want


# ---------------------------------------------------------------------------------------------
# I/O options (docs/io.md)
# ---------------------------------------------------------------------------------------------
def _io_cloud(n: int = 50) -> PointCloud:
    rng = np.random.default_rng(9)
    return PointCloud(
        rng.uniform(0, 100, (n, 3)) + [E, N, H0],
        {
            "zeta": np.arange(n, dtype=np.int32),  # not in sorted order: zeta, alpha, mid
            "alpha": rng.random(n).astype(np.float32),
            "mid": rng.random(n),
        },
    )


def test_text_writer_header_precision_and_digits(tmp_path):
    from lidarfx.io import write

    c = _io_cloud(20)
    write(c, tmp_path / "a.csv", precision=5, header=False)
    lines = (tmp_path / "a.csv").read_text().splitlines()
    assert len(lines) == 20  # no header line
    first = lines[0].split(",")
    assert first[:3] == [f"{v:.5f}" for v in c.xyz[0]]
    assert first[3] == "0"
    # float32 with 7 significant digits, float64 with 15: both read back to the stored value
    assert np.float32(float(first[4])) == c["alpha"][0] and first[4] == f"{float(c['alpha'][0]):.7g}"
    assert float(first[5]) == pytest.approx(c["mid"][0], rel=1e-14) and first[5] == f"{c['mid'][0]:.15g}"


def test_convert_precision_reaches_the_text_writer(tmp_path, capsys):
    src = tmp_path / "in.npz"
    lidarfx.write(_io_cloud(10), src)
    assert main(["convert", str(src), str(tmp_path / "out.xyz"), "--precision", "1"]) == 0
    capsys.readouterr()
    rows = (tmp_path / "out.xyz").read_text().splitlines()
    x, y, z = rows[1].split()[:3]
    assert all(len(v.split(".")[1]) == 1 for v in (x, y, z))
    c = lidarfx.read(src)
    assert float(x) == round(c.xyz[0, 0], 1)


def test_npy_table_in_attribute_order_and_npz_compression(tmp_path):
    import zipfile

    from lidarfx.io import write

    c = _io_cloud(200)
    write(c, tmp_path / "t.npy")
    table = np.load(tmp_path / "t.npy")
    assert table.shape == (200, 6)
    assert np.array_equal(table[:, :3], c.xyz)
    assert np.array_equal(table[:, 3], c["zeta"]) and np.array_equal(table[:, 4], c["alpha"])
    assert np.array_equal(table[:, 5], c["mid"])
    c["flat"] = np.zeros(200)  # compressible
    write(c, tmp_path / "s.npz")
    write(c, tmp_path / "d.npz", compressed=True)
    for name, kind in (("s.npz", zipfile.ZIP_STORED), ("d.npz", zipfile.ZIP_DEFLATED)):
        with zipfile.ZipFile(tmp_path / name) as zf:
            assert {i.compress_type for i in zf.infolist()} == {kind}, name
    assert (tmp_path / "d.npz").stat().st_size < (tmp_path / "s.npz").stat().st_size
    # written through a temporary file and renamed: nothing else is left in the folder
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.npz", "s.npz", "t.npy"]


def test_las_extra_dim_is_int64_only_when_int32_is_too_small(tmp_path):
    """docs/io.md rule 6: integer attributes become int32 extra bytes, int64 when the values need it."""
    import laspy

    c = PointCloud(np.zeros((3, 3)) + [E, N, H0], {"small": np.array([-5, 0, 2**31 - 1]),
                                                    "big": np.array([-(2**40), 0, 2**40 + 7])})
    lidarfx.write(c, tmp_path / "ids.las")
    ref = laspy.read(tmp_path / "ids.las")
    assert {d.name: d.dtype for d in ref.point_format.extra_dimensions} == {"small": np.int32, "big": np.int64}
    assert ref["big"].tolist() == [-(2**40), 0, 2**40 + 7] and ref["small"].tolist() == [-5, 0, 2**31 - 1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ids.las"]


def test_semicolon_wins_over_comma_as_delimiter(tmp_path):
    """docs/io.md: the delimiter of the first data line is ';' if present, else ','."""
    from lidarfx.io import read

    (tmp_path / "a.txt").write_text('x;y;z;"a,b"\n1;2;3;4\n5;6;7;8\n')
    c = read(tmp_path / "a.txt")
    assert c.names == ["a,b"] and c["a,b"].tolist() == [4, 8] and c.xyz.tolist() == [[1, 2, 3], [5, 6, 7]]
